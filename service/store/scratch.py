"""Scratch files and directories in DATA_DIR/tmp are named after the process that owns them
(``upload-HOST-PID-*``, ``work-HOST-PID-*``), so a process starting later can remove what dead processes on
this host left behind (a SIGKILLed upload, a killed worker) without touching the scratch of live ones, even
when several API and worker processes, or containers with their own host names, share the directory."""

from __future__ import annotations

import hashlib
import logging
import os
import re
import shutil
import socket
from pathlib import Path

log = logging.getLogger("pdeanim.scratch")
HOST = hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]
_OWNED = re.compile(r"^(upload|work)-([0-9a-f]{8})-(\d+)-")


def prefix(kind: str) -> str:
    """Name prefix of this process's scratch of ``kind`` ("upload" or "work")."""
    return f"{kind}-{HOST}-{os.getpid()}-"


def alive(pid: int) -> bool:
    """Whether process ``pid`` exists (one owned by another user counts as alive)."""
    try:
        os.kill(pid, 0)
        return True
    except ProcessLookupError:
        return False
    except PermissionError:
        return True


def remove(path: Path) -> None:
    """Delete a scratch file or directory (missing is fine)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def clean_stale(tmp_dir: Path) -> int:
    """Remove the scratch of processes of this host that are gone; returns how many entries were removed."""
    removed = 0
    try:
        entries = list(Path(tmp_dir).iterdir())
    except FileNotFoundError:
        return 0
    for entry in entries:
        match = _OWNED.match(entry.name)
        if match is None or match[2] != HOST or alive(int(match[3])):
            continue
        remove(entry)
        removed += 1
    if removed:
        log.warning("removed %d scratch entries left by dead processes in %s", removed, tmp_dir)
    return removed
