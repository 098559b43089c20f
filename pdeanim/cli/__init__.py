"""The ``pdeanim`` console script. Each sub-command lives in its own module of this package and
exposes ``register(subparsers)``, which adds its parser and sets ``func`` (args -> exit code)."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys

from ..errors import InputError, PdeanimError

COMMANDS = ["simulate", "fit", "frame", "export", "cyclic", "serve", "worker", "keys", "demo"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command that is installed."""
    from .. import __version__

    parser = argparse.ArgumentParser(prog="pdeanim", description="Deforming 3D meshes to compact dynamic-PDE coefficient clips, and back to frames.")
    parser.add_argument("--version", action="version", version=f"pdeanim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        module = f"{__name__}.{name}"
        if importlib.util.find_spec(module) is not None:
            importlib.import_module(module).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point: parse, run the sub-command, and turn library errors into a message and exit code 2."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"pdeanim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except PdeanimError as exc:
        print(f"pdeanim {args.command}: failed: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
