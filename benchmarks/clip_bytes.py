"""Bytes a client downloads to play a clip (topology + coefficients, gzip as the service serves
them) against the animation GLB the service serves for the same frames, ``gltfpack -cc`` of those frames,
and the raw float32 frames: for the demo clip and sequences of ../shared/data/sequences (read from there,
never copied).

    .venv/bin/python benchmarks/clip_bytes.py [--sequences pcow horse-collapse] [--no-demo]

Everything goes through a real API server and worker (temporary data directory): the demo clip is the
``pdeanim demo`` job (spot simulated and fitted); a sequence is uploaded as a mesh (its first frame) and
poses, and fitted with the demo's fit options. "as served" is the body on the wire with ``Accept-Encoding:
gzip``. gltfpack (npm, ``tools/gltfpack``) packs a plain float32 morph-target GLB of exactly the frames the
animation GLB holds (the clip evaluated at the same times, with normals). Sizes are deterministic; the load
average is printed because the machine may be shared.
"""

from __future__ import annotations

import argparse
import gzip
import io
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np
import zstandard

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]

from service_frames import SPOT, check, wait_job  # noqa: E402

from pdeanim_service.demo import FIT, SCENE, DemoServices  # noqa: E402
from pdeanim_service.settings import Settings  # noqa: E402
from pdeanim_service.store.tenants import issue_key  # noqa: E402

SEQUENCES = next((p / "shared" / "data" / "sequences" for p in (ROOT.parent, ROOT.parent.parent)
                  if (p / "shared" / "data" / "sequences").is_dir()), Path("/work/shared/data/sequences"))
GLTFPACK = ROOT / "tools" / "gltfpack" / "node_modules" / ".bin" / "gltfpack"
FPS = 30.0  # the sequences' frame rate (their README); the demo simulates at 30 fps too


def wire(api: httpx.Client, path: str, accept: str = "gzip", **params) -> tuple[int, int]:
    """(bytes on the wire with ``accept`` as Accept-Encoding, bytes decoded) of a GET."""
    with api.stream("GET", path, params=params, headers={"Accept-Encoding": accept}) as r:
        if r.status_code != 200:
            r.read()
            raise RuntimeError(f"GET {path}: {r.status_code} {r.text[:300]}")
        raw = b"".join(r.iter_raw())
    coding = r.headers.get("content-encoding")
    decoded = {"gzip": gzip.decompress, "zstd": lambda b: zstandard.ZstdDecompressor().decompressobj()
               .decompress(b)}.get(coding, lambda b: b)(raw)
    return len(raw), len(decoded)


def animation(api: httpx.Client, clip_id: str, fps: float) -> tuple[int, int, int, str]:
    """The animation GLB's bytes as served to a client accepting gzip, one accepting zstd, and decoded: from
    the route, or from an export job when the route says it is too large."""
    r = api.get(f"/v1/clips/{clip_id}/animation", params={"fps": fps},
                headers={"Accept-Encoding": "identity"})
    if r.status_code == 200:
        path = f"/v1/clips/{clip_id}/animation"
        gz, glb = wire(api, path, fps=fps)
        return gz, wire(api, path, "zstd", fps=fps)[0], glb, "route"
    if r.status_code != 413:
        raise RuntimeError(f"animation: {r.status_code} {r.text[:300]}")
    job = api.post("/v1/jobs", json={"kind": "export", "clip_id": clip_id, "fps": fps}).json()
    while job["state"] not in ("succeeded", "failed"):
        time.sleep(0.3)
        job = api.get(f"/v1/jobs/{job['id']}").json()
    if job["state"] != "succeeded":
        raise RuntimeError(f"export job failed: {job['error']}")
    gz, glb = wire(api, f"/v1/exports/{job['id']}")
    return gz, wire(api, f"/v1/exports/{job['id']}", "zstd")[0], glb, "export job"


def gltfpack_cc(api: httpx.Client, clip_id: str, fps: float, tmp: Path) -> tuple[int, int]:
    """(bytes, gzip bytes) of ``gltfpack -cc`` on a float32 morph-target GLB of the animation's frames."""
    from pdeanim.clip import load_clip
    from pdeanim.gltf.clipexport import clip_animation_glb
    from pdeanim.gltf.compact import PackOptions

    clip = load_clip(api.get(f"/v1/clips/{clip_id}/topology").content,
                     api.get(f"/v1/clips/{clip_id}/coefficients").content)
    src, out = tmp / "in.glb", tmp / "out.glb"
    src.write_bytes(clip_animation_glb(clip, fps, options=PackOptions(quantize=False, compress=False)))
    subprocess.run([str(GLTFPACK), "-cc", "-i", str(src), "-o", str(out)], check=True, capture_output=True)
    data = out.read_bytes()
    return len(data), len(gzip.compress(data, 6))


def sequence_upload(api: httpx.Client, name: str) -> dict:
    """Upload a sequence's first frame as an OBJ mesh and the frames as poses; run a fit job."""
    with np.load(SEQUENCES / f"{name}.npz") as d:
        frames, faces = d["vertices"].astype(np.float32), d["faces"].astype(np.int64)
    used = np.unique(faces)  # the service keeps only referenced vertices: upload exactly those
    remap = np.full(frames.shape[1], -1)
    remap[used] = np.arange(len(used))
    frames, faces = frames[:, used], remap[faces]
    obj = io.StringIO()
    np.savetxt(obj, frames[0], fmt="v %.7g %.7g %.7g")
    np.savetxt(obj, faces + 1, fmt="f %d %d %d")
    mesh = api.post("/v1/meshes", files={"file": (f"{name}.obj", obj.getvalue().encode())}).json()
    buf = io.BytesIO()
    np.savez(buf, vertices=frames, times=np.arange(len(frames)) / FPS)
    poses = api.post(f"/v1/meshes/{mesh['id']}/poses", files={"file": (f"{name}.npz", buf.getvalue())})
    if poses.status_code != 201:
        raise RuntimeError(f"poses upload: {poses.status_code} {poses.text[:300]}")
    job = api.post("/v1/jobs", json={"kind": "fit", "poses_id": poses.json()["id"], "params": FIT}).json()
    while job["state"] not in ("succeeded", "failed"):
        time.sleep(0.3)
        job = api.get(f"/v1/jobs/{job['id']}").json()
    if job["state"] != "succeeded":
        raise RuntimeError(f"fit of {name} failed: {job['error']}")
    return job


def kib(n: int) -> str:
    return f"{n / 1024:,.1f}"


def main() -> int:
    """Print one row per case."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequences", nargs="*", default=["pcow", "horse-collapse"])
    ap.add_argument("--no-demo", action="store_true")
    args = ap.parse_args()
    if not GLTFPACK.exists():
        print(f"gltfpack not found at {GLTFPACK}: run script/setup (npm ci in tools/gltfpack)")
        return 2
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    os.environ["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    print(f"fit options {FIT}; animation GLB and gltfpack at {FPS:g} fps; sizes in KiB; "
          "'gz' = gzip as served (level 6; animation GLBs level 1), 'zstd' = the animation GLB as served "
          "to a client that accepts zstd")
    head = (f"{'case':<18} {'frames x verts':>14} {'raw f32':>9} {'clip gz':>8} {'(topo+coef)':>15} "
            f"{'clip raw':>8} "
            f"{'anim GLB gz':>11} {'GLB zstd':>8} {'GLB raw':>8} {'gltfpack':>8} {'gp gz':>7} "
            f"{'clip/GLB':>8} {'clip/gp':>7} "
            f"{'clip/raw':>8}")
    print(head)
    with tempfile.TemporaryDirectory(prefix="pdeanim-bench-") as tmp:
        services = DemoServices(Path(tmp))
        try:
            key, url = issue_key(Settings(data_dir=Path(tmp)), "bench"), services.start()
            with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {key}"}, timeout=900) as api:
                def demo() -> dict:  # what `pdeanim demo` submits: spot simulated, then fitted
                    mesh = check(api.post("/v1/meshes", files={"file": ("spot.obj", SPOT.read_bytes())}))
                    job = check(api.post("/v1/jobs", json={"kind": "simulate", "mesh_id": mesh["id"],
                                                           "params": SCENE, "then_fit": True, "fit": FIT}))
                    return wait_job(api, job["id"], 900)

                cases = [] if args.no_demo else [("demo (spot)", demo)]
                cases += [(name, lambda n=name: sequence_upload(api, n)) for name in args.sequences]
                for label, make in cases:
                    job = make()
                    cid = job["result"]["clip_id"]
                    meta = api.get(f"/v1/clips/{cid}").json()
                    topo_gz, topo = wire(api, f"/v1/clips/{cid}/topology")
                    coef_gz, coef = wire(api, f"/v1/clips/{cid}/coefficients")
                    glb_gz, glb_zstd, glb, how = animation(api, cid, FPS)
                    gp, gp_gz = gltfpack_cc(api, cid, FPS, Path(tmp))
                    raw = meta["sizes"]["raw_float32_bytes"]
                    clip_gz = topo_gz + coef_gz
                    verts = meta["info"].get("n_vertices", 0)
                    print(f"{label:<18} {meta['frames']:>5} x {verts:>6} {kib(raw):>9} "
                          f"{kib(clip_gz):>8} {kib(topo_gz) + '+' + kib(coef_gz):>15} {kib(topo + coef):>8} "
                          f"{kib(glb_gz):>11} {kib(glb_zstd):>8} {kib(glb):>8} {kib(gp):>8} {kib(gp_gz):>7} "
                          f"{clip_gz / glb_gz:>8.2f} {clip_gz / gp_gz:>7.2f} {clip_gz / raw:>8.3f}"
                          + ("" if how == "route" else f"  (GLB from an {how})"), flush=True)
        finally:
            services.stop()
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
