"""The domain library never imports the service or the worker (the map in docs/architecture.md)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# Import every pdeanim module in a fresh interpreter where importing `service` or `worker` raises.
PROBE = """
import importlib, importlib.abc, pkgutil, sys

class Refuse(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("service", "worker"):
            raise ImportError("pdeanim imported " + name)
        return None

sys.meta_path.insert(0, Refuse())
import pdeanim
names = [m.name for m in pkgutil.walk_packages(pdeanim.__path__, "pdeanim.")]
for name in names:
    importlib.import_module(name)
print(len(names))
"""


def test_pdeanim_imports_without_service_or_worker() -> None:
    out = subprocess.run([sys.executable, "-c", PROBE], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout.strip()) > 40  # every module was imported, not just the package


def test_library_cli_has_no_service_commands() -> None:
    from pdeanim.cli import build_parser
    from pdeanim_service.cli import service_commands

    library = build_parser()._subparsers._group_actions[0].choices  # noqa: SLF001
    full = build_parser(service_commands())._subparsers._group_actions[0].choices  # noqa: SLF001
    assert {"serve", "worker", "keys", "demo"}.isdisjoint(library)
    assert {"serve", "worker", "keys", "demo", "fit", "simulate"} <= set(full)
