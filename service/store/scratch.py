"""Scratch files and directories in DATA_DIR/tmp are named after the process that owns them
(``upload-HOST-PID-*``, ``work-HOST-PID-*``), so a process starting later can remove what dead processes on
this host left behind (a SIGKILLed upload, a killed worker) without touching the scratch of live ones, even
when several API and worker processes, or containers with their own host names, share the directory. Also
the process liveness checks this needs, and :func:`die_with_parent` for child processes that must not
outlive the process that started them (job processes, HTTP processes, workers started by ``serve``)."""

from __future__ import annotations

import ctypes
import hashlib
import logging
import os
import re
import shutil
import signal
import socket
from pathlib import Path

log = logging.getLogger("pdeanim.scratch")
HOST = hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]
_OWNED = re.compile(r"^(upload|work)-([0-9a-f]{8})-(\d+)-")


def prefix(kind: str) -> str:
    """Name prefix of this process's scratch of ``kind`` ("upload" or "work")."""
    return f"{kind}-{HOST}-{os.getpid()}-"


def alive(pid: int) -> bool:
    """Whether process ``pid`` exists and has not exited (one owned by another user counts as alive; a zombie,
    killed but not yet reaped by its parent, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return not zombie(pid)


def zombie(pid: int) -> bool:
    """Whether process ``pid`` has exited and waits to be reaped (state Z in /proc; False if unreadable)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[-1].split()[:1] == ["Z"]


PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent(parent_pid: int | None = None, sig: int = signal.SIGKILL) -> bool:
    """Have Linux send ``sig`` to this process when its parent exits, however it ends (prctl
    PR_SET_PDEATHSIG; SIGKILL included), so a killed supervisor or worker leaves no child running. With
    ``parent_pid``, the process that should be the parent: if it is already gone (it died before the call),
    this process exits at once. Returns False where prctl is unavailable (not Linux)."""
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):  # pragma: no cover - not Linux
        return False
    if prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:  # pragma: no cover - refused by a sandbox
        return False
    if parent_pid is not None and (os.getppid() != parent_pid or not alive(parent_pid)):
        os._exit(3)  # orphaned before the signal was armed: nobody is left to take our work
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
