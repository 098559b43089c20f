"""Fault injection for tests/service/test_window_tasks.py (on PYTHONPATH of the test's service processes
only): with PDEANIM_TEST_HOLD_DIR set, the encoding of window i waits while the file ``hold-encode-<i>``
exists there, after writing ``running-encode-<i>-<pid>``, so a test can kill or cancel a window mid-run.
The library module is patched when a process imports it (importing it here would slow every start)."""

import os
import sys

HOLD = os.environ.get("PDEANIM_TEST_HOLD_DIR")
TARGET = "pdeanim.fit.windowed"


def _patch(windowed) -> None:  # noqa: ANN001 - the module
    import time
    from pathlib import Path

    encode = windowed.encode_window

    def encode_window(model, frames, index, progress=None):  # noqa: ANN001, ANN202
        hold = Path(HOLD) / f"hold-encode-{index}"
        if hold.exists():
            (Path(HOLD) / f"running-encode-{index}-{os.getpid()}").touch()
            while hold.exists():
                time.sleep(0.05)
        return encode(model, frames, index, progress)

    windowed.encode_window = encode_window


class _Finder:
    """Finds the library module as the other finders do, and patches it once executed."""

    def find_spec(self, name, path, target=None):  # noqa: ANN001, ANN201
        if name != TARGET:
            return None
        for finder in sys.meta_path:
            find = getattr(finder, "find_spec", None)
            spec = None if finder is self or find is None else find(name, path, target)
            if spec is not None:
                spec.loader.exec_module = _patched(spec.loader.exec_module)
                return spec
        return None


def _patched(execute):  # noqa: ANN001, ANN202
    def exec_module(module) -> None:  # noqa: ANN001
        execute(module)
        _patch(module)

    return exec_module


if HOLD:
    sys.meta_path.insert(0, _Finder())
