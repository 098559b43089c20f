"""The API process limits numpy's and scipy's OpenBLAS to one thread (concurrent frame requests otherwise
fight OpenBLAS's own threads); checked in a fresh interpreter, so this test process keeps its settings."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from tests.ci import missing

CHECK = r"""
import ctypes, json
from pdeanim_service.api.threads import _loaded_openblas, single_threaded_blas

limited = single_threaded_blas()
counts = {}
for path in _loaded_openblas():
    lib = ctypes.CDLL(path)
    for name in ("openblas_get_num_threads", "openblas_get_num_threads64_",
                 "scipy_openblas_get_num_threads", "scipy_openblas_get_num_threads64_"):
        getter = getattr(lib, name, None)
        if getter is not None:
            getter.restype = ctypes.c_int
            counts[path] = getter()
            break
print(json.dumps({"limited": limited, "threads": counts}))
"""


def test_api_process_runs_openblas_single_threaded():
    # as a user starts it: no thread limit in the environment
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", CHECK], capture_output=True, text=True, env=env, check=True)
    report = json.loads(out.stdout.strip().splitlines()[-1])
    if not report["threads"]:
        missing("numpy/scipy are not linked against OpenBLAS here (the wheels from the lock file are)")
    assert report["limited"] == len(report["threads"]), report
    assert set(report["threads"].values()) == {1}, report
