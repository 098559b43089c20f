"""The library's commands of the ``pdeanim`` console script. Each sub-command lives in its own module and
exposes ``register(subparsers)``, which adds its parser and sets ``func`` (args -> exit code). The
service-side commands (serve, worker, keys, demo) live with the service and are added by
:func:`pdeanim_service.cli.main`, the installed console script; this package never imports them."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

from ..errors import InputError, OutOfMemoryError, ParameterError, PdeanimError
from . import cyclic, export, fit, frame, simulate, stream


class Command(Protocol):
    """A sub-command: a module (or object) whose ``register(subparsers)`` adds its parser."""

    def register(self, subparsers: Any) -> None: ...


COMMANDS: tuple[Command, ...] = (simulate, fit, frame, export, cyclic, stream)
LIBRARY_COMMANDS = frozenset({"simulate", "fit", "frame", "export", "cyclic", "stream"})
"""Names of the library's sub-commands (their ``--out`` is checked before any work starts)."""
EXIT_OUT_OF_MEMORY = 4
"""Exit code of a command that ran out of memory (an allocation failed under the process's limit)."""
RAISE_LIMIT = "or raise the limit (ulimit -v, or the container's memory)"
MEMORY_ADVICE = {
    "simulate": f"lower --frames or --tets, {RAISE_LIMIT}",
    "fit": "fit fewer frames (a part of the poses) or a coarser mesh: a fit needs about 480 bytes per frame "
           f"x vertex plus 0.5 GiB (pdeanim.fit.budget), {RAISE_LIMIT}",
    "frame": f"ask for fewer times at once (--t), {RAISE_LIMIT}",
    "export": f"export at a lower --fps, {RAISE_LIMIT}",
    "cyclic": f"lower --frames, --curves or --points, {RAISE_LIMIT}",
    "stream": f"lower --window-seconds, {RAISE_LIMIT}",
}
"""What would help, per command, when it runs out of memory."""


def build_parser(extra_commands: Sequence[Command] = ()) -> argparse.ArgumentParser:
    """The argument parser with the library's sub-commands plus ``extra_commands``."""
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="pdeanim",
        description="Deforming 3D meshes to compact dynamic-PDE coefficient clips, and back to frames.",
    )
    parser.add_argument("--version", action="version", version=f"pdeanim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for command in (*COMMANDS, *extra_commands):
        command.register(sub)
    return parser


def check_writable(path: str) -> None:
    """Raise ParameterError unless the file ``path`` can be created or overwritten: it is tried by opening it
    for appending (a new file is removed again), which also catches read-only file systems and root."""
    target = Path(path)
    if target.is_dir():
        raise ParameterError(f"--out {path} is a directory, not a file")
    existed = target.exists()
    try:
        with open(target, "ab"):
            pass
    except OSError as exc:
        raise ParameterError(f"--out {path} cannot be written: {exc.strerror or exc}") from exc
    if not existed:
        target.unlink()


def main(argv: list[str] | None = None, extra_commands: Sequence[Command] = ()) -> int:
    """Entry point: parse, run the sub-command, and turn library errors into a message and an exit code: 2 bad
    input, 4 out of memory (EXIT_OUT_OF_MEMORY), 1 other failures."""
    parser = build_parser(extra_commands)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        if args.command in LIBRARY_COMMANDS and getattr(args, "out", None):
            check_writable(args.out)  # before any work: a long fit must not end in an unwritable path
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"pdeanim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except (MemoryError, OutOfMemoryError) as exc:
        return _out_of_memory(args.command, exc)
    except PdeanimError as exc:
        print(f"pdeanim {args.command}: failed: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


def _out_of_memory(command: str, exc: BaseException) -> int:
    """Say what ran out of memory, under which limit and what would help; EXIT_OUT_OF_MEMORY."""
    from ..outofmemory import out_of_memory

    if not isinstance(exc, OutOfMemoryError):
        exc = out_of_memory(exc, MEMORY_ADVICE.get(command, RAISE_LIMIT))
    print(f"pdeanim {command}: failed: {exc}", file=sys.stderr)
    return EXIT_OUT_OF_MEMORY


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
