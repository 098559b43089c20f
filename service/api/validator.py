"""Uploads are validated in a child process, so the API process's memory stays the same whatever the file:
decoding a legal upload can take gigabytes (a 1 GiB poses .npz, a morph-target GLB) and glibc keeps the API's
freed heap (:mod:`pdeanim_service.api.memory`). The child forks from a forkserver that preloaded the readers
(a few
milliseconds per upload), runs under an address-space limit (``PDEANIM_UPLOAD_MEMORY_BYTES`` over what the
preloaded libraries map) and a time limit, and sends back only small results. At most
``PDEANIM_MAX_CONCURRENT_UPLOADS`` uploads are received and validated at once per API process
(:mod:`pdeanim_service.api.uploadslots`)."""

from __future__ import annotations

import logging
import multiprocessing
import os
import resource
import signal
import threading
from typing import Any

from ..settings import Settings
from .errors import ApiError

log = logging.getLogger("pdeanim.api")

PRELOAD = ["numpy", "scipy.sparse", "trimesh", "pdeanim.mesh.io", "pdeanim.gltf.read", "pdeanim.poses",
           "pdeanim_service.api.ingest"]
RETRY_AFTER_SECONDS = 2
_context: multiprocessing.context.BaseContext | None = None
_lock = threading.Lock()


def context() -> multiprocessing.context.BaseContext:
    """The forkserver context of the validator children (its server preloads the readers once)."""
    global _context
    with _lock:
        if _context is None:
            ctx = multiprocessing.get_context("forkserver")
            ctx.set_forkserver_preload(PRELOAD)
            _context = ctx
        return _context


def warm() -> None:
    """Start the forkserver now (it imports the readers: about a second), not on the first upload."""
    from multiprocessing import forkserver

    context()
    try:
        forkserver.ensure_running()
    except (OSError, ImportError, RuntimeError) as exc:  # the first upload will try again and answer
        log.warning("could not start the upload validators' forkserver: %s", exc)


def _address_space() -> int:
    """Bytes of address space this process maps now (VmSize), 0 when /proc is not there."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmSize:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def _child(conn, target: str, args: tuple, budget: int) -> None:  # noqa: ANN001 - a Connection
    """Entry of the child: limit memory, run ``pdeanim_service.api.ingest.<target>(*args)``, send one
    message."""
    from pdeanim.errors import InputError

    from . import ingest
    from .threads import single_threaded_blas

    try:
        single_threaded_blas()  # before the limit: OpenBLAS threads reserve address space when they start
        if budget:
            limit = _address_space() + budget
            resource.setrlimit(resource.RLIMIT_AS, (limit, resource.RLIM_INFINITY))
        conn.send(("ok", getattr(ingest, target)(*args)))
    except InputError as exc:
        if isinstance(exc.__cause__, MemoryError):  # a reader's "does not fit in memory": the budget's
            conn.send(("memory",))
        else:
            conn.send(("input", int(getattr(exc, "status", 422)), exc.code, str(exc)))
    except MemoryError:
        conn.send(("memory",))
    except BaseException as exc:  # noqa: BLE001 - a reader failing on a hostile file is the file's fault
        conn.send(("failed", f"{type(exc).__name__}: {exc}"))
    finally:
        conn.close()
        os._exit(0)  # no interpreter teardown (it can hang under RLIMIT_AS)


def _over_memory(budget: int) -> ApiError:
    return ApiError(413, "limit_exceeded", f"validating this upload needs more memory than the "
                    f"{budget} bytes ({budget / 2**30:.2f} GiB) one upload may use (setting "
                    "PDEANIM_UPLOAD_MEMORY_BYTES)")


def _answer(message: tuple, settings: Settings) -> Any:
    """The result a child sent, or the ApiError it stands for."""
    kind = message[0]
    if kind == "ok":
        return message[1]
    if kind == "input":
        raise ApiError(message[1], message[2], message[3])
    if kind == "memory":
        raise _over_memory(settings.upload_memory_bytes)
    log.warning("upload validation failed: %s", message[1])
    raise ApiError(422, "invalid_upload", f"the file cannot be read ({message[1]})")


def _died(proc: multiprocessing.process.BaseProcess, settings: Settings) -> ApiError:
    """The error for a child that exited without an answer (killed, crashed in native code)."""
    code = proc.exitcode
    if code is not None and code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        if -code == signal.SIGKILL and settings.upload_memory_bytes:
            return _over_memory(settings.upload_memory_bytes)
        return ApiError(422, "invalid_upload", f"the file cannot be read: its reader died ({name})")
    return ApiError(422, "invalid_upload", f"the file cannot be read: its reader exited with code {code}")


def run_checked(target: str, args: tuple, settings: Settings) -> Any:
    """``pdeanim_service.api.ingest.<target>(*args)`` in a fresh child under the memory and time limits
    (blocking: call it from a thread). Its InputErrors come back as ApiErrors with their status and
    message."""
    ctx = context()
    receiver, sender = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(sender, target, args, settings.upload_memory_bytes), daemon=True)
    try:
        proc.start()
    except OSError as exc:  # no process could be started (fork or memory limits of the host)
        receiver.close()
        sender.close()
        raise ApiError(503, "unavailable", f"cannot start an upload validator now ({exc}); retry later",
                       headers={"Retry-After": str(RETRY_AFTER_SECONDS)}) from exc
    try:
        sender.close()
        if not receiver.poll(settings.upload_timeout_seconds):
            proc.kill()
            raise ApiError(413, "limit_exceeded", f"validating this upload took longer than "
                           f"{settings.upload_timeout_seconds:g} s (setting PDEANIM_UPLOAD_TIMEOUT_SECONDS)")
        try:
            message = receiver.recv()
        except EOFError:
            proc.join(10)
            raise _died(proc, settings) from None
        return _answer(message, settings)
    finally:
        receiver.close()
        if proc.is_alive():
            proc.join(5)
        if proc.is_alive():
            proc.kill()
        proc.join(5)
