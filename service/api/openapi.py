"""Write the app's OpenAPI document to ``openapi/openapi.json`` (``python -m pdeanim_service.api.openapi``);
a test fails when the checked-in file drifts from the app."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..settings import Settings
from .app import create_app

DEFAULT_PATH = Path(__file__).resolve().parents[2] / "openapi" / "openapi.json"


def openapi_text() -> str:
    """The OpenAPI document as stable, indented JSON (independent of the settings)."""
    doc = create_app(Settings(data_dir=Path("unused"))).openapi()
    return json.dumps(doc, indent=2, sort_keys=True) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write (or with ``--check``, compare) the OpenAPI file; returns the exit code."""
    args = sys.argv[1:] if argv is None else argv
    check = "--check" in args
    paths = [a for a in args if not a.startswith("--")]
    path = Path(paths[0]) if paths else DEFAULT_PATH
    text = openapi_text()
    if check:
        same = path.exists() and path.read_text() == text
        print(f"{path}: {'up to date' if same else 'DRIFTED: run python -m pdeanim_service.api.openapi'}")
        return 0 if same else 1
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
