"""Write the skinned animation GLBs of two bone fixtures (format 1.1) into clients/js/test/gltf, for the JS
test that loads them with three.js's GLTFLoader and plays them with its own AnimationMixer
(test/bones-gltf.test.mjs). Run from the repository root after regenerating the fixtures:
``python clients/js/test/tools/bone_glbs.py``."""

from __future__ import annotations

import json
from pathlib import Path

from pdeanim.clip import load_clip_file
from pdeanim.gltf.clipexport import clip_animation_glb

HERE = Path(__file__).resolve().parent
FIXTURES = HERE.parent / "fixtures"
OUT = HERE.parent / "gltf"
CASES = ("bones-fit-k2-zero", "bones-fit-k4-residual")  # a pure skinned animation; skin + residual morphs
FPS = 12.0


def main() -> None:
    """Export each case at FPS keys per second and record the key count next to the GLBs."""
    OUT.mkdir(exist_ok=True)
    info = {}
    for name in CASES:
        clip = load_clip_file(FIXTURES / f"{name}.clip")
        glb = clip_animation_glb(clip, FPS)
        (OUT / f"{name}.glb").write_bytes(glb)
        info[name] = {"clip": f"../fixtures/{name}.clip", "glb": f"{name}.glb", "fps": FPS, "bytes": len(glb)}
    (OUT / "manifest.json").write_text(json.dumps(info, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
