"""The bone layer's fit side: rigid bones that move many vertices with few numbers (a skinning decomposition
of unskinned sequences, a glTF skin's own joints), the residual left to the curves."""
