"""Issue 26, in the library: every decoder that inflates checks what it declares before allocating, with the
figures in the error: glTF JSON size and depth, declared counts, meshopt views (each no larger than its
accessors read, all within the decode budget), and zstd containers (their declared total, shapes that would
overflow int64)."""

from __future__ import annotations

import json
import time
import tracemalloc

import numpy as np
import pytest

from pdeanim import container
from pdeanim.errors import ClipFormatError, InputError, LimitError, MeshInputError
from pdeanim.gltf.document import GltfLimits, json_depth, load_document
from pdeanim.gltf.glb import pack_glb
from pdeanim.gltf.read import read_static_mesh
from pdeanim.mesh.io import MeshLimits, load_mesh

from . import bombs


def refused_quickly(call, error: type[Exception], match: str, seconds: float = 3.0,
                    peak_mb: float = 50.0) -> str:
    """Run ``call``; it must raise ``error`` matching ``match`` within ``seconds`` and ``peak_mb`` of
    Python allocations; returns the message."""
    tracemalloc.start()
    started = time.monotonic()
    try:
        with pytest.raises(error, match=match) as info:
            call()
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert time.monotonic() - started < seconds
    assert peak < peak_mb * 2**20, f"peak {peak / 2**20:.0f} MB"
    return str(info.value)


def test_views_sharing_one_stream_are_capped_in_total() -> None:
    """Three compressed views whose accessors read all of them (sparse morph-target values), 256 MiB each
    from one 4 MiB stream: each alone is fine, together they are over a 512 MiB decode budget."""
    size = 1 << 28
    doc_glb = bombs.meshopt_bomb(size, views=3)
    from pdeanim.gltf.glb import unpack_glb

    doc, binary = unpack_glb(doc_glb)
    for acc in doc["accessors"][2:]:
        acc["count"] = size // bombs.STRIDE  # the accessors now read every byte of their views
    limits = GltfLimits(max_decoded_bytes=512 * 2**20)
    message = refused_quickly(lambda: read_static_mesh(pack_glb(doc, binary), limits), LimitError,
                              "PDEANIM_MAX_DECODED_BYTES")
    assert f"{3 * size} in EXT_meshopt_compression views" in message, message


def test_single_view_bomb_is_refused_with_the_figures() -> None:
    message = refused_quickly(lambda: load_mesh(bombs.meshopt_bomb(1 << 30), filename="b.glb"),
                              MeshInputError, "decompression bomb", peak_mb=60)  # the 16 MB file itself
    assert "declares 1073741824 decoded bytes but its accessors read 60" in message


def test_accessor_outputs_count_against_the_budget() -> None:
    """A view-less accessor (all zeros by the spec) of 48M values is 384 MB of float64: over a 64 MiB budget
    from the JSON alone."""
    doc, raw = bombs._tetra_doc()
    doc["accessors"].append({"componentType": 5126, "count": 16_000_000, "type": "VEC3"})
    doc["meshes"][0]["primitives"][0]["targets"] = [{"POSITION": 2}]
    refused_quickly(lambda: read_static_mesh(pack_glb(doc, raw), GltfLimits(max_decoded_bytes=64 * 2**20)),
                    LimitError, "384000192 in accessors")


@pytest.mark.parametrize(("raw", "depth"), [(b'{"a":[1,{"b":"x[y"}]}', 3), (b'{"a":"\\"[[[","b":[[]]}', 3),
                                            (b'{"a":"\\\\","b":[[[]]]}', 4), (b"[]", 1), (b'"[["', 0)])
def test_json_depth_ignores_brackets_in_strings(raw: bytes, depth: int) -> None:
    assert json_depth(raw) == depth
    if raw.startswith((b"{", b"[")):
        assert json_depth(json.dumps(json.loads(raw)).encode()) == depth


def test_json_size_and_depth_limits_name_their_settings() -> None:
    deep = bombs.deep_json(5_000)
    refused_quickly(lambda: load_document(deep), LimitError, "depth is 5001.*PDEANIM_MAX_GLTF_JSON_DEPTH")
    big = bombs.node_flood(30_000)
    refused_quickly(lambda: load_document(big, limits=GltfLimits(max_json_bytes=100_000)), LimitError,
                    "PDEANIM_MAX_GLTF_JSON_BYTES")


def test_mesh_limits_carry_the_gltf_limits() -> None:
    limits = MeshLimits(gltf=GltfLimits(max_nodes=10))
    refused_quickly(lambda: load_mesh(bombs.node_flood(11), filename="n.glb", limits=limits), LimitError,
                    "glTF nodes count is 11, over the limit of 10")


def _container_declaring(shape: list[int]) -> bytes:
    """A container whose one zstd array's header is rewritten to declare ``shape``."""
    blob = container.pack({}, {"a": np.zeros(1024, np.float32)}, encodings={"a": "zstd"})
    prefix = container._PREFIX
    _, _, hlen = prefix.unpack_from(blob, 0)
    header = json.loads(blob[prefix.size:prefix.size + hlen])
    header["arrays"]["a"]["shape"] = shape
    meta = json.dumps(header).encode()
    meta += b" " * (-len(meta) % 8)
    return prefix.pack(container.MAGIC, container.VERSION, len(meta)) + meta + blob[prefix.size + hlen:]


@pytest.mark.parametrize("shape", [[2**40], [2**32, 2**32], [2**62, 4]])
def test_container_declaring_huge_arrays_is_refused_before_decompressing(shape: list[int]) -> None:
    """Declared sizes past the cap (and shapes whose product wraps around int64) are refused from the
    header."""
    refused_quickly(lambda: container.unpack(_container_declaring(shape)), ClipFormatError,
                    "declare .* bytes once decoded, more than")


@pytest.mark.parametrize("kind", ["nodes", "primitives"])
def test_floods_are_refused_within_a_second_of_cpu(kind: str) -> None:
    """200k nodes or primitives (3 and 8 MB of JSON): refused from the declared counts in under a second of
    CPU time (0.21 s and 0.55 s measured; the bound is 2.5 s for a loaded machine), not after walking the
    scene (32.7 s and 12.4 s before)."""
    data = bombs.node_flood(200_000) if kind == "nodes" else bombs.primitive_flood(200_000)
    started = time.process_time()
    with pytest.raises(LimitError, match=f"glTF {'nodes count' if kind == 'nodes' else 'mesh primitives'}"):
        load_mesh(data, filename="flood.glb")
    assert time.process_time() - started < 2.5


def test_inputs_within_the_limits_still_load() -> None:
    vertices, faces = read_static_mesh(pack_glb(*bombs._tetra_doc()))
    assert vertices.shape == (4, 3) and faces.shape == (4, 3)
    _, arrays = container.unpack(container.pack({}, {"a": np.arange(9.0)}, encodings={"a": "zstd"}))
    assert arrays["a"].tolist() == list(np.arange(9.0))
    assert issubclass(LimitError, InputError)
