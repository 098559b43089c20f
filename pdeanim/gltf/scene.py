"""The node hierarchy of a glTF scene and its animation: parents, traversal order, and node world matrices
and morph weights sampled at many times at once (per node, vectorised over times)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .document import GltfDocument
from .sampling import sample, trs_matrices

PATHS = ("translation", "rotation", "scale", "weights")


@dataclass
class Track:
    """One animation channel: keys (n,), values (n or 3n, w), interpolation."""

    keys: np.ndarray
    values: np.ndarray
    interpolation: str


def node_parents(gd: GltfDocument) -> np.ndarray:
    """(N,) parent index of every node, -1 for roots; rejects nodes with two parents."""
    nodes = gd.list("nodes")
    parent = np.full(len(nodes), -1, np.int64)
    for i, node in enumerate(nodes):
        for c in node.get("children", []):
            gd.item("nodes", c)
            if parent[c] != -1 or c == i:
                raise gd.error(f"glTF node {c} has more than one parent (the node graph must be a forest)")
            parent[c] = i
    return parent


def scene_order(gd: GltfDocument) -> list[int]:
    """Nodes of the default scene (all roots when there is none) in depth-first pre-order."""
    parent = node_parents(gd)
    scenes = gd.list("scenes")
    if scenes:
        roots = list(gd.item("scenes", gd.doc.get("scene", 0)).get("nodes", []))
    else:
        roots = [int(i) for i in np.flatnonzero(parent == -1)]
    order, stack, seen = [], list(reversed(roots)), set()
    while stack:
        n = stack.pop()
        gd.item("nodes", n)
        if n in seen:
            raise gd.error(f"glTF node {n} is reached twice (cycle or shared child)")
        seen.add(n)
        order.append(n)
        stack.extend(reversed(gd.list("nodes")[n].get("children", [])))
    return order


def pick_animation(gd: GltfDocument, animation: int | str | None) -> tuple[int, dict]:
    """The animation chosen by index or name (the first when None); raises when there is none."""
    anims = gd.list("animations")
    if not anims:
        raise gd.error("the glTF file has no animation (upload it as a mesh, or add a morph-target or "
                       "skinned animation)")
    if animation is None:
        return 0, anims[0]
    if isinstance(animation, str) and not animation.isdigit():
        for i, a in enumerate(anims):
            if a.get("name") == animation:
                return i, a
        raise gd.error(f"no animation named {animation!r} (have {[a.get('name') for a in anims]})")
    return int(animation), gd.item("animations", int(animation))


def animation_tracks(gd: GltfDocument, anim: dict) -> dict[tuple[int, str], Track]:
    """The TRS and weights channels of an animation, keyed by (node, path)."""
    tracks: dict[tuple[int, str], Track] = {}
    samplers = anim.get("samplers", [])
    for ch in anim.get("channels", []):
        target = ch.get("target", {})
        if target.get("path") not in PATHS or "node" not in target:
            continue  # channels of extensions (e.g. animation pointers) do not move vertices here
        s_index = ch.get("sampler")
        if not isinstance(s_index, int) or not 0 <= s_index < len(samplers):
            raise gd.error(f"animation channel refers to a missing sampler {s_index}")
        s = samplers[s_index]
        node = gd.item("nodes", target["node"])
        if "matrix" in node and target["path"] != "weights":
            raise gd.error(f"node {target['node']} is animated but has a matrix (the spec forbids it)")
        tracks[(target["node"], target["path"])] = Track(
            gd.accessor(s["input"])[:, 0], gd.accessor(s["output"]), s.get("interpolation", "LINEAR")
        )
    if not tracks:
        raise gd.error("the glTF animation has no channel that moves a node or morph weights")
    return tracks


def time_range(tracks: dict[tuple[int, str], Track]) -> tuple[float, float]:
    """First and last key time over all tracks."""
    return (
        float(min(t.keys.min() for t in tracks.values())),
        float(max(t.keys.max() for t in tracks.values())),
    )


def _local(gd: GltfDocument, n: int, tracks: dict, times: np.ndarray) -> np.ndarray:
    node = gd.list("nodes")[n]
    if "matrix" in node:
        m = np.asarray(node["matrix"], np.float64).reshape(4, 4).T
        return np.broadcast_to(m, (len(times), 4, 4))
    rest = {
        "translation": node.get("translation", [0.0, 0.0, 0.0]),
        "rotation": node.get("rotation", [0, 0, 0, 1]),
        "scale": node.get("scale", [1.0, 1.0, 1.0]),
    }
    trs = {}
    for path, default in rest.items():
        tr = tracks.get((n, path))
        if tr is None:
            trs[path] = np.asarray(default, np.float64)
        else:
            trs[path] = sample(
                tr.keys, tr.values, tr.interpolation, times, rotation=path == "rotation", error=gd.error
            )
    return np.broadcast_to(
        trs_matrices(trs["translation"], trs["rotation"], trs["scale"]), (len(times), 4, 4)
    )


def world_matrices(gd: GltfDocument, tracks: dict, times: np.ndarray) -> np.ndarray:
    """(K, N, 4, 4) world matrices of every node at times (K,); nodes outside the scene stay identity."""
    parent = node_parents(gd)
    world = np.broadcast_to(np.eye(4), (len(times), len(parent), 4, 4)).copy()
    for n in scene_order(gd):
        local = _local(gd, n, tracks, times)
        world[:, n] = local if parent[n] < 0 else world[:, parent[n]] @ local
    return world


def morph_weights(
    gd: GltfDocument, tracks: dict, node_index: int, n_targets: int, times: np.ndarray
) -> np.ndarray:
    """(K, n_targets) morph weights of a mesh node: animated, else the node's or mesh's default, else 0."""
    if n_targets == 0:
        return np.zeros((len(times), 0))
    tr = tracks.get((node_index, "weights"))
    if tr is not None:
        n = len(tr.keys)
        per_key = 3 * n if tr.interpolation == "CUBICSPLINE" else n
        values = tr.values.reshape(-1)
        if values.size != per_key * n_targets:
            raise gd.error(f"weights animation of node {node_index} has {values.size} values, expected "
                           f"{per_key * n_targets} ({n_targets} targets)")
        return sample(tr.keys, values.reshape(per_key, n_targets), tr.interpolation, times, error=gd.error)
    node = gd.list("nodes")[node_index]
    default = node.get("weights", gd.item("meshes", node["mesh"]).get("weights", [0.0] * n_targets))
    if len(default) != n_targets:
        raise gd.error(f"node {node_index} has {len(default)} default morph weights for {n_targets} targets")
    return np.broadcast_to(np.asarray(default, np.float64), (len(times), n_targets))
