"""Read a triangle mesh (OBJ, PLY, STL, OFF, GLB/glTF) into a validated SurfaceMesh.

Parsing is done by trimesh with ``process=False`` (and ``maintain_order`` for OBJ), and by pdeanim's own glTF
reader for GLB/glTF (every primitive's vertices, in file order), so the vertex order of the file is kept;
every problem becomes a MeshInputError naming it, every configured limit a LimitError.
"""

from __future__ import annotations

import hashlib
import io
import logging
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import LimitError, MeshInputError
from ..gltf.document import GltfLimits

FORMATS = {".obj": "obj", ".ply": "ply", ".stl": "stl", ".off": "off", ".glb": "glb", ".gltf": "gltf"}
"""Known file extensions and the trimesh file type each is parsed as."""


@dataclass(frozen=True)
class MeshLimits:
    """Explicit limits on what an uploaded mesh may hold (checked before and after parsing); ``gltf`` holds
    the limits on what a glTF file may declare (None: the library's defaults)."""

    max_file_bytes: int = 100 * 1024 * 1024
    max_vertices: int = 2_000_000
    max_faces: int = 4_000_000
    gltf: GltfLimits | None = None


@dataclass
class SurfaceMesh:
    """A validated triangle mesh.

    vertices : (V, 3) float64 positions
    faces : (T, 3) int64 indices into vertices
    original_index : (V0,) int64, for each vertex of the file the index of its vertex here
        (identity unless seams were merged; ``vertices[original_index]`` is the file's vertex array)
    """

    vertices: np.ndarray
    faces: np.ndarray
    original_index: np.ndarray = field(default=None)  # type: ignore[assignment]
    source: str = ""

    def __post_init__(self) -> None:
        if self.original_index is None:
            self.original_index = np.arange(len(self.vertices), dtype=np.int64)

    @property
    def content_hash(self) -> str:
        """sha256 of the vertex and face arrays (canonical dtypes), a cache key independent of the file
        format."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.vertices, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(self.faces, dtype="<i8").tobytes())
        return h.hexdigest()

    def bbox(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounding box ((3,) min, (3,) max) of the vertices."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def diagonal(self) -> float:
        """Length of the bounding-box diagonal (the scale used for relative errors)."""
        lo, hi = self.bbox()
        return float(np.linalg.norm(hi - lo))

    def stats(self) -> dict:
        """Vertices, faces, connected components, watertightness and bounding box, as JSON-ready values."""
        lo, hi = self.bbox()
        return {
            "vertices": int(len(self.vertices)),
            "faces": int(len(self.faces)),
            "components": count_components(len(self.vertices), self.faces),
            "watertight": is_watertight(self.faces),
            "bbox": {"min": lo.tolist(), "max": hi.tolist()},
            "diagonal": self.diagonal(),
        }


def count_components(n_vertices: int, faces: np.ndarray) -> int:
    """Number of face-connected components (isolated vertices are not counted)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(faces) == 0:
        return 0
    a, b = faces.reshape(-1), np.roll(faces, 1, axis=1).reshape(-1)
    graph = coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(n_vertices, n_vertices))
    _, labels = connected_components(graph, directed=False)
    return int(len(np.unique(labels[np.unique(faces)])))


def is_watertight(faces: np.ndarray) -> bool:
    """True when every undirected edge is shared by exactly two faces, once in each direction."""
    if len(faces) == 0:
        return False
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2)
    undirected = np.sort(directed, axis=1)
    _, counts = np.unique(undirected, axis=0, return_counts=True)
    _, dcounts = np.unique(directed, axis=0, return_counts=True)
    return bool(np.all(counts == 2) and np.all(dcounts == 1))


def load_mesh(source: str | Path | bytes, *, filename: str | None = None, limits: MeshLimits | None = None,
              merge_seams: bool = False) -> SurfaceMesh:
    """Read and validate a mesh from a path, or from bytes plus ``filename`` (for its extension)."""
    limits = limits or MeshLimits()
    folder = None  # external glTF buffers resolve next to a file on disk, never for uploaded bytes
    if isinstance(source, bytes | bytearray | memoryview):
        data = bytes(source)
        name = filename or ""
    else:
        path = Path(source)
        name = filename or path.name
        if not path.is_file():
            raise MeshInputError(f"mesh file {str(path)!r} does not exist")
        size = path.stat().st_size
        if size > limits.max_file_bytes:
            raise LimitError("mesh file size in bytes", size, limits.max_file_bytes, "PDEANIM_MAX_MESH_BYTES")
        data = path.read_bytes()
        folder = path.parent
    if len(data) > limits.max_file_bytes:
        raise LimitError(
            "mesh file size in bytes", len(data), limits.max_file_bytes, "PDEANIM_MAX_MESH_BYTES"
        )
    file_type = file_type_of(name)
    if len(data) == 0:
        raise MeshInputError(f"mesh file {name!r} is empty")
    vertices, faces = parse_mesh(data, file_type, name, folder, limits)
    validate_arrays(vertices, faces, name, limits)
    mesh = SurfaceMesh(vertices, faces, source=name)
    return merge_duplicate_vertices(mesh) if merge_seams else mesh


def file_type_of(name: str) -> str:
    """The trimesh file type for a file name, or MeshInputError for an unknown extension."""
    suffix = Path(name).suffix.lower()
    if suffix not in FORMATS:
        raise MeshInputError(
            f"unsupported mesh file type {suffix or name!r}: use one of {', '.join(FORMATS)}"
        )
    return FORMATS[suffix]


def parse_mesh(
    data: bytes, file_type: str, name: str, folder: Path | None = None, limits: MeshLimits | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Parse bytes with trimesh into raw (V, 3) float64 vertices and (T, 3) int64 faces (not yet validated).

    ``folder`` lets a .gltf on disk load its external buffers; bytes from an upload get no resolver. glTF
    files are checked against ``limits`` from their declared counts before their scene is read.
    """
    if file_type in ("glb", "gltf"):
        return gltf_arrays(data, name, folder, limits)
    import trimesh

    kwargs: dict = {"process": False}
    if folder is not None:
        kwargs["resolver"] = trimesh.resolvers.FilePathResolver(str(folder))
    if file_type == "obj":
        kwargs["maintain_order"] = True
        check_obj_indices(data, name)
    logger = logging.getLogger("trimesh")
    level = logger.level
    logger.setLevel(logging.CRITICAL)  # trimesh logs parse failures before raising; the error says enough
    try:
        loaded = trimesh.load(io.BytesIO(data), file_type=file_type, **kwargs)
    except MeshInputError:
        raise
    except IndexError as exc:
        raise MeshInputError(f"{name!r} has face indices out of range ({exc})") from exc
    except (
        Exception
    ) as exc:  # trimesh raises many types (ValueError, KeyError, struct.error, ...) on bad files
        raise MeshInputError(
            f"cannot parse {name!r} as {file_type.upper()}: the file is truncated, corrupt or "
            f"not in that format ({type(exc).__name__}: {exc})"
        ) from exc
    finally:
        logger.setLevel(level)
    return geometry_arrays(loaded, name)


def gltf_arrays(data: bytes, name: str, folder: Path | None = None,
                limits: MeshLimits | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a glTF/GLB scene at rest, in file order (scene nodes depth-first, each mesh's
    primitives in order, every vertex of every primitive kept) with node transforms and skins applied: the
    order the animated-poses reader and the look-keeping GLB writer (``pdeanim.gltf.layout``) use."""
    from ..gltf.read import read_static_mesh

    path = folder / Path(name).name if folder is not None else None
    source: Path | bytes = path if path is not None and path.is_file() else data
    try:
        vertices, faces = read_static_mesh(source, limits.gltf if limits else None,
                                           limits.max_vertices if limits else None)
    except LimitError:
        raise
    except MeshInputError as exc:
        kind = Path(name).suffix[1:].upper() or "glTF"
        raise MeshInputError(f"cannot parse {name!r} as {kind}: {exc}") from exc
    return np.asarray(vertices, np.float64), np.asarray(faces, np.int64).reshape(-1, 3)


OBJ_ZERO_INDEX = re.compile(rb"^[ \t]*f(?=[ \t])[^\n]*?(?<=[ \t])0(?:/\S*)?(?=\s|$)", re.MULTILINE)
"""A face line of an OBJ file with a vertex index 0 (OBJ indices start at 1; trimesh would wrap 0 to -1)."""


def check_obj_indices(data: bytes, name: str) -> None:
    """MeshInputError for an OBJ face using vertex index 0, which trimesh silently maps to the last vertex."""
    match = OBJ_ZERO_INDEX.search(data)
    if match is not None:
        line = data.count(b"\n", 0, match.start()) + 1
        raise MeshInputError(
            f"{name!r} line {line}: face vertex index 0 (OBJ indices start at 1, or -1 from the end)"
        )


def geometry_arrays(loaded: object, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a trimesh result; a Scene is flattened with its node transforms applied."""
    import trimesh

    if isinstance(loaded, trimesh.Scene):
        meshes = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh) and len(g.faces)]
        if not meshes:
            raise MeshInputError(
                f"{name!r} contains no triangle mesh (empty, truncated or not in that format)"
            )
        offsets = np.cumsum([0] + [len(m.vertices) for m in meshes])
        vertices = np.concatenate([np.asarray(m.vertices, np.float64) for m in meshes])
        faces = np.concatenate(
            [np.asarray(m.faces, np.int64) + o for m, o in zip(meshes, offsets, strict=False)]
        )
        return vertices, faces
    if not isinstance(loaded, trimesh.Trimesh):
        raise MeshInputError(f"{name!r} contains no triangle mesh (found {type(loaded).__name__})")
    return np.asarray(loaded.vertices, np.float64), np.asarray(loaded.faces, np.int64).reshape(-1, 3)


MAX_ABS_COORDINATE = 1e15
"""Larger coordinates overflow float32 poses once squared (areas, norms) or cubed (volumes)."""


def validate_arrays(vertices: np.ndarray, faces: np.ndarray, name: str, limits: MeshLimits) -> None:
    """Raise MeshInputError naming the first problem, or LimitError for a configured limit."""
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) == 0:
        raise MeshInputError(f"{name!r} has no vertices")
    if len(vertices) > limits.max_vertices:
        raise LimitError("vertex count", len(vertices), limits.max_vertices, "PDEANIM_MAX_VERTICES")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise MeshInputError(f"{name!r} has no triangle (vertices only or empty faces)")
    if len(faces) > limits.max_faces:
        raise LimitError("face count", len(faces), limits.max_faces, "PDEANIM_MAX_FACES")
    if not np.all(np.isfinite(vertices)):
        first = int(np.argwhere(~np.isfinite(vertices))[0, 0])
        raise MeshInputError(f"{name!r} has NaN or infinite coordinates (first at vertex {first})")
    biggest = float(np.abs(vertices).max())
    if biggest > MAX_ABS_COORDINATE:
        raise MeshInputError(f"{name!r} has coordinates up to {biggest:.3g}, over {MAX_ABS_COORDINATE:.0e}: "
                             "sizes, areas and float32 poses would overflow (non-finite); rescale the mesh")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshInputError(f"{name!r} has face indices out of range: {faces.min()}..{faces.max()} "
                             f"for {len(vertices)} vertices")


def merge_duplicate_vertices(mesh: SurfaceMesh) -> SurfaceMesh:
    """Merge vertices at identical positions (UV/normal seams); keeps the map back to the file's order."""
    unique, first, inverse = np.unique(mesh.vertices, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    # renumber merged vertices in order of first appearance so the result follows the file's order
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    original_index = rank[inverse].astype(np.int64)
    faces = original_index[mesh.faces]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    return SurfaceMesh(unique[order], faces[keep], original_index=original_index, source=mesh.source)
