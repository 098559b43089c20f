"""Result records: JSON-safe values and the library versions (the one helper the API and the worker share)."""

from __future__ import annotations

import json

import numpy as np

from pdeanim.records import jsonable, library_versions


def test_jsonable_turns_numpy_into_json_and_non_finite_into_null():
    value = {"a": np.float32(1.5), 2: np.arange(3, dtype=np.int64), "n": [np.nan, np.inf, 1.0],
             "t": (np.bool_(True), None, "s"), "o": object}
    out = jsonable(value)
    assert out == {"a": 1.5, "2": [0, 1, 2], "n": [None, None, 1.0], "t": [True, None, "s"], "o": str(object)}
    assert json.loads(json.dumps(out, allow_nan=False)) == out


def test_library_versions_name_the_installed_distributions():
    versions = library_versions()
    assert versions["numpy"] == np.__version__ and versions["pdeanim"]
    assert set(versions) == {"pdeanim", "numpy", "scipy", "trimesh", "pytetwild", "numba", "meshoptimizer"}
