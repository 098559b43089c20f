"""pdeanim: deforming 3D models to compact dynamic-PDE coefficient clips, and back to frames."""

__version__ = "0.1.0"
