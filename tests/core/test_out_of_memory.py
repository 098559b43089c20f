"""Running out of memory is a documented failure: under a real address-space limit (RLIMIT_AS set in the
child), ``pdeanim fit`` of poses larger than the limit exits with code 4 and says what it tried to allocate,
under which limit, and what would help, instead of a numpy traceback."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from numpy.lib import format as npformat

from pdeanim.cli import EXIT_OUT_OF_MEMORY
from pdeanim.errors import OutOfMemoryError
from pdeanim.outofmemory import cgroup_memory_limit, out_of_memory

ROOT = Path(__file__).resolve().parents[2]
LIMIT = 1 << 30  # the interpreter with numpy and scipy takes 0.4-0.6 GiB of address space of it


def zero_poses_npz(path: Path, frames: int, vertices: int) -> None:
    """A poses .npz of (frames, vertices, 3) float32 zeros, streamed (a tiny file that inflates to GBs)."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        with zf.open("vertices.npy", "w", force_zip64=True) as fh:
            npformat.write_array_header_1_0(fh, {"descr": "<f4", "fortran_order": False,
                                                 "shape": (frames, vertices, 3)})
            chunk, left = bytes(1 << 24), frames * vertices * 12
            while left:
                fh.write(chunk[:min(left, len(chunk))])
                left -= min(left, len(chunk))
        with zf.open("faces.npy", "w") as fh:
            npformat.write_array(fh, np.array([[0, 1, 2]], np.int32))


def limited(limit: int):  # noqa: ANN201 - a preexec function
    """A preexec_fn that puts the child under an address-space limit of ``limit`` bytes."""
    return lambda: resource.setrlimit(resource.RLIMIT_AS, (limit, limit))


def test_cli_fit_out_of_memory_exits_4_naming_the_allocation_the_limit_and_the_advice(tmp_path):
    poses = tmp_path / "big.npz"
    zero_poses_npz(poses, 1000, 100_000)  # 1.2 GB of float32 once inflated, more than the whole limit
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "PDEANIM_PROGRESS_EVERY": "60"}
    command = [sys.executable, "-m", "pdeanim_service.cli", "fit", str(poses), "--out",
               str(tmp_path / "out.clip"),
               "--segments", "1", "-q"]
    run = subprocess.run(command, capture_output=True, text=True, env=env, timeout=600,
                         preexec_fn=limited(LIMIT))
    assert run.returncode == EXIT_OUT_OF_MEMORY == 4, run.stderr[-3000:]
    err = run.stderr
    assert "Traceback" not in err and "out of memory" in err, err
    assert "1.12 GiB" in err  # the failed allocation: 1000 x 100000 x 3 float32
    assert "address-space limit (RLIMIT_AS, ulimit -v) of 1.00 GiB" in err, err
    assert "raise the limit" in err and ("fewer frames" in err or "coarser mesh" in err), err


def test_cli_fit_whose_estimate_is_over_the_limit_is_refused_before_fitting(tmp_path):
    poses = tmp_path / "long.npz"
    zero_poses_npz(poses, 2000, 1000)  # 24 MB inflated, loads under the limit; the fit's estimate: 1.39 GiB
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1",
           "PDEANIM_PROGRESS_EVERY": "0.01"}
    command = [sys.executable, "-m", "pdeanim_service.cli", "fit", str(poses), "--out",
               str(tmp_path / "out.clip")]
    run = subprocess.run(command, capture_output=True, text=True, env=env, timeout=600,
                         preexec_fn=limited(LIMIT))
    assert run.returncode == EXIT_OUT_OF_MEMORY == 4, run.stderr[-3000:]
    err = run.stderr
    assert "Traceback" not in err and "fit:" not in err.replace("pdeanim fit:", ""), err  # no progress line
    assert "out of memory: the estimated 1.39 GiB of the fit is over the address-space limit (RLIMIT_AS, " \
           "ulimit -v) of 1.00 GiB (refused before fitting)" in err, err
    assert "a fit of 2000 frames x 1000 vertices needs about 1.39 GiB" in err and "raise the limit" in err
    assert not (tmp_path / "out.clip").exists()


def test_out_of_memory_message_names_size_limit_and_advice():
    try:
        np.empty((1 << 20, 1 << 20, 1 << 10), np.float64)  # 8 PiB: refused by any machine at once
    except MemoryError as exc:
        err = out_of_memory(exc, "lower frames", (8 << 30, "job memory limit (PDEANIM_JOB_MEMORY_BYTES)"))
    assert isinstance(err, OutOfMemoryError) and err.code == "out_of_memory"
    assert err.needed == 8 << 50 and err.limit == 8 << 30
    text = str(err)
    assert "allocating 8388608.00 GiB (an array of shape (1048576, 1048576, 1024) float64)" in text
    assert "under the job memory limit (PDEANIM_JOB_MEMORY_BYTES) of 8.00 GiB; lower frames" in text
    plain = out_of_memory(MemoryError(), "lower frames", (1 << 30, "limit"))
    assert plain.needed is None and "an allocation failed under the limit of 1.00 GiB" in str(plain)


@pytest.mark.parametrize("text, limit", [("max\n", None), ("2147483648\n", 2 << 30),
                                         ("9223372036854771712\n", None)])
def test_cgroup_limit_reads_v2_and_v1_files(tmp_path, text, limit):
    path = tmp_path / "memory.max"
    path.write_text(text)
    assert cgroup_memory_limit((tmp_path / "missing", path)) == limit
