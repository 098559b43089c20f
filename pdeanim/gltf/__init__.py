"""glTF 2.0 for pdeanim: writing frames and morph-target animations as GLB (:mod:`.write`), reading animated
poses and skinned meshes (:mod:`.read`, :mod:`.skin`), and the Khronos validator harness
(:mod:`.validate`)."""
