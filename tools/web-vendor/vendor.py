"""Copy the browser files the service ships into service/api/static: three.js, fzstd (the zstd decoder the JS
client imports), Swagger UI and ReDoc from this folder's node_modules (npm ci), and the JS client's browser
modules from clients/js/src.

``python tools/web-vendor/vendor.py`` copies; ``--check`` only compares and exits 1 on drift (a test runs it).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
STATIC = ROOT / "service" / "api" / "static"
MODULES = HERE / "node_modules"
CLIENT_SRC = ROOT / "clients" / "js" / "src"
CLIENT_DEST = STATIC / "viewer" / "pdeanim"
VERSIONS = STATIC / "vendor" / "versions.json"

# npm package -> [(file in the package, destination under static/vendor)]
NPM_FILES: dict[str, list[tuple[str, str]]] = {
    "three": [("build/three.module.js", "three/three.module.js"),
              ("build/three.core.js", "three/three.core.js"),
              ("examples/jsm/controls/OrbitControls.js", "three/addons/controls/OrbitControls.js"),
              # the viewer plays clips on the mesh's original glTF (GLTFLoader and what it imports)
              ("examples/jsm/loaders/GLTFLoader.js", "three/addons/loaders/GLTFLoader.js"),
              ("examples/jsm/utils/BufferGeometryUtils.js", "three/addons/utils/BufferGeometryUtils.js"),
              ("examples/jsm/utils/SkeletonUtils.js", "three/addons/utils/SkeletonUtils.js"),
              ("LICENSE", "three/LICENSE")],
    # ESM build, mapped to the bare specifier "fzstd" by the viewer's import map (.js: served as JavaScript)
    "fzstd": [("esm/index.mjs", "fzstd/fzstd.js"), ("LICENSE", "fzstd/LICENSE")],
    "swagger-ui-dist": [("swagger-ui-bundle.js", "swagger-ui/swagger-ui-bundle.js"),
                        ("swagger-ui.css", "swagger-ui/swagger-ui.css"),
                        ("favicon-32x32.png", "swagger-ui/favicon-32x32.png"),
                        ("LICENSE", "swagger-ui/LICENSE"), ("NOTICE", "swagger-ui/NOTICE")],
    "redoc": [("bundles/redoc.standalone.js", "redoc/redoc.standalone.js"),
              ("bundles/redoc.standalone.js.LICENSE.txt", "redoc/redoc.standalone.js.LICENSE.txt"),
              ("LICENSE", "redoc/LICENSE")],
}


def locked_versions() -> dict[str, str]:
    """The versions package-lock.json pins for the vendored packages."""
    lock = json.loads((HERE / "package-lock.json").read_text())
    return {name: lock["packages"][f"node_modules/{name}"]["version"] for name in NPM_FILES}


def planned() -> dict[Path, bytes | None]:
    """Destination -> expected bytes (None where node_modules is absent and only versions can be checked)."""
    plan: dict[Path, bytes | None] = {}
    for name, files in NPM_FILES.items():
        for src, dest in files:
            path = MODULES / name / src
            plan[STATIC / "vendor" / dest] = path.read_bytes() if MODULES.is_dir() else None
    plan[VERSIONS] = (json.dumps(locked_versions(), indent=2, sort_keys=True) + "\n").encode()
    if CLIENT_SRC.is_dir():
        for path in sorted(CLIENT_SRC.rglob("*")):
            if path.is_file() and path.suffix in (".js", ".mjs"):
                plan[CLIENT_DEST / path.relative_to(CLIENT_SRC)] = path.read_bytes()
    return plan


def stale_client_files(plan: dict[Path, bytes | None]) -> list[Path]:
    """Copied client modules whose source is gone."""
    if not CLIENT_DEST.is_dir():
        return []
    return [p for p in sorted(CLIENT_DEST.rglob("*")) if p.is_file() and p not in plan]


def drift() -> list[str]:
    """Human-readable differences between the static folder and its sources (empty when in sync)."""
    plan = planned()
    out = [f"{p.relative_to(ROOT)}: missing" for p in plan if not p.exists()]
    out += [f"{p.relative_to(ROOT)}: differs from its source" for p, data in plan.items()
            if p.exists() and data is not None and p.read_bytes() != data]
    out += [f"{p.relative_to(ROOT)}: its source is gone" for p in stale_client_files(plan)]
    return out


def main(argv: list[str]) -> int:
    """Copy (default) or check (``--check``); returns the exit code."""
    if "--check" in argv:
        problems = drift()
        for line in problems:
            print(line)
        print("static files drifted: run python tools/web-vendor/vendor.py" if problems
              else "static files in sync")
        return 1 if problems else 0
    if not MODULES.is_dir():
        print("run `npm ci` in tools/web-vendor first", file=sys.stderr)
        return 2
    plan = planned()
    for path in stale_client_files(plan):
        path.unlink()
    for path, data in plan.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        if data is not None and (not path.exists() or path.read_bytes() != data):
            path.write_bytes(data)
            print(f"wrote {path.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
