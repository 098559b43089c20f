"""The clip viewer in headless Chromium against a real service and worker: ``positions(t)`` matches the Python
evaluation, and screenshots show a lit mesh that moves between two t, the same on the GPU and the CPU path."""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests.service.harness import Services, client, make_key, wait_job

HERE = Path(__file__).resolve().parent
FRAMES = 12
CYCLIC = {"mode": "eel", "frames": 8, "n_curves": 12, "points": 16, "modes": 3}
TIMES = [0.0, 0.23, 0.5, 0.77, 1.0]
# float32 evaluation in JS against float64-accumulated numpy: observed about 1e-7 of the diagonal; the issue's
# bound (1e-6) leaves ten times that
TOLERANCE = 1e-6


def browser_tools_missing() -> str | None:
    """Why the browser test cannot run here (None when it can)."""
    if shutil.which("node") is None:
        return "node is not installed"
    if not (HERE / "node_modules" / "puppeteer-core").is_dir():
        return "puppeteer-core is not installed (npm ci in tests/browser, done by script/setup)"
    candidates = ("/usr/bin/chromium", "/usr/bin/chromium-browser", "/usr/bin/google-chrome",
                  os.environ.get("PDEANIM_CHROMIUM", "/none"), os.environ.get("CHROMIUM", "/none"))
    if not any(Path(p).exists() for p in candidates):
        return "chromium is not installed (apt-get install chromium, done by script/setup)"
    return None


@pytest.fixture(scope="module")
def browser_ready() -> None:
    reason = browser_tools_missing()
    if reason and os.environ.get("CI", "").lower() in ("1", "true", "yes"):
        pytest.fail(f"the browser test must run under CI: {reason}")
    if reason:
        pytest.skip(reason)


@pytest.fixture(scope="module")
def browser_env(browser_ready):
    """The environment of the check scripts: one Chromium for the whole module (chromium_serve.mjs), which
    each script connects to instead of launching its own."""
    proc = subprocess.Popen(["node", str(HERE / "chromium_serve.mjs")], cwd=HERE, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        endpoint = proc.stdout.readline().strip()
        assert endpoint.startswith("ws://"), f"chromium_serve.mjs printed {endpoint!r}"
        yield {**os.environ, "PDEANIM_BROWSER_WS": endpoint}
    finally:
        proc.stdin.close()
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.fixture(scope="module")
def services(browser_ready, tmp_path_factory):
    from tests.service.conftest import open_backend

    with open_backend("sqlite", tmp_path_factory.mktemp("data"), None) as backend:
        svc = Services(backend, tmp_path_factory.mktemp("svc"))
        try:
            svc.start_server()
            svc.start_worker()
            yield svc
        finally:
            svc.stop()


def wave(verts: np.ndarray, frames: int) -> np.ndarray:
    """Poses (F, V, 3) float32: a sideways wave travelling along the longest axis, 5% of its length."""
    axis = int(np.argmax(np.ptp(verts, axis=0)))
    side = (axis + 1) % 3
    u = (verts[:, axis] - verts[:, axis].min()) / np.ptp(verts[:, axis])
    phase = np.linspace(0, 2 * np.pi, frames)[:, None]
    out = np.repeat(verts[None].astype(np.float32), frames, axis=0)
    out[:, :, side] += 0.05 * np.ptp(verts[:, axis]) * u * np.sin(2 * np.pi * u - phase)
    return out


@pytest.fixture(scope="module")
def clips(services, data_dir) -> dict:
    """A key and two clips of the fish mesh: a dynamic-PDE fit of a travelling wave, and a cyclic swim."""
    key = make_key(services.backend, "viewer")
    api = client(services, key)
    obj = (data_dir / "fish_eel.obj").read_bytes()
    mesh = api.post("/v1/meshes", files={"file": ("fish.obj", obj, "application/octet-stream")})
    assert mesh.status_code == 201, mesh.text
    verts = np.array([ln.split()[1:4] for ln in obj.decode().splitlines() if ln.startswith("v ")],
                     dtype=np.float32)
    buf = io.BytesIO()
    np.savez(buf, vertices=wave(verts, FRAMES))
    mid = mesh.json()["id"]
    poses = api.post(f"/v1/meshes/{mid}/poses",
                     files={"file": ("p.npz", buf.getvalue(), "application/octet-stream")})
    assert poses.status_code == 201, poses.text
    out = {"key": key}
    fit = {"kind": "fit", "poses_id": poses.json()["id"], "params": {"segments": 2}}
    cyclic = {"kind": "cyclic", "mesh_id": mid, "params": CYCLIC}
    for kind, body in (("dynamic-pde", fit), ("cyclic-spine", cyclic)):
        r = api.post("/v1/jobs", json=body)
        assert r.status_code == 202, r.text
        job = wait_job(api, r.json()["id"], timeout=300)
        assert job["state"] == "succeeded", (job, services.logs())
        out[kind] = job["result"]["clip_id"]
    return out


def run_viewer(services: Services, env: dict, tmp_path: Path, job: dict, timeout: float = 300) -> dict:
    """Run viewer_check.mjs on ``job`` in the module's browser (``env``); its JSON result (with the page's
    console on failure)."""
    job = {**job, "out": str(tmp_path / "result.json")}
    proc = subprocess.run(["node", str(HERE / "viewer_check.mjs"), json.dumps(job)], cwd=HERE, env=env,
                          capture_output=True, text=True, timeout=timeout)
    result = json.loads(Path(job["out"]).read_text()) if Path(job["out"]).exists() else {}
    assert proc.returncode == 0 and "error" not in result, (proc.stdout, proc.stderr, result, services.logs())
    return result


def load_png(path: str) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"), dtype=np.int16)


def canvas_part(img: np.ndarray) -> np.ndarray:
    """The 3D view (left of the side panel, which is 22rem = 308 px wide)."""
    return img[:, : img.shape[1] - 320]


@pytest.mark.parametrize("kind", ["dynamic-pde", "cyclic-spine"])
def test_viewer_plays_the_clip_as_python_evaluates_it(services, browser_env, clips, kind, tmp_path):
    from pdeanim.clip import load_clip

    cid, key = clips[kind], clips["key"]
    api = client(services, key)
    clip = load_clip(api.get(f"/v1/clips/{cid}/topology").content,
                     api.get(f"/v1/clips/{cid}/coefficients").content)
    shots = [{"t": 0.1, "mode": "gpu", "path": str(tmp_path / "gpu_a.png")},
             {"t": 0.6, "mode": "gpu", "path": str(tmp_path / "gpu_b.png")},
             {"t": 0.6, "mode": "cpu", "path": str(tmp_path / "cpu_b.png")}]
    job = {"url": f"{services.url}/viewer#clip={cid}&key={key}", "times": TIMES, "shots": shots,
           "measureGlb": kind == "dynamic-pde"}
    result = run_viewer(services, browser_env, tmp_path, job)
    info = result["info"]
    assert info["kind"] == kind and info["nVertices"] == clip.n_vertices
    assert info["mode"] == "gpu", info["gpuUnavailableReason"]

    diag = float(np.linalg.norm(np.ptp(clip.evaluate(0.0), axis=0)))
    for t, got in zip(TIMES, result["positions"], strict=True):
        js = np.asarray(got, dtype=np.float64).reshape(-1, 3)
        err = float(np.abs(js - clip.evaluate(t)).max())
        assert err <= TOLERANCE * diag, (t, err / diag)

    # bytes: what the page downloaded (gzip as served) next to raw frames and the animation GLB
    sizes = info["sizes"]
    assert 0 < sizes["topologyWire"] <= sizes["topology"]
    assert 0 < sizes["coefficientsWire"] <= sizes["coefficients"]
    assert sizes["raw"] > 0 and "raw float32 frames" in info["stats"]
    if kind == "dynamic-pde":
        assert result["glb"] and result["glb"] > 0 and "animation GLB" in info["statsAfter"]
        # the size comes from the service (HEAD): the GLB is never downloaded to count it
        assert set(result["animationRequests"]) == {"HEAD"}, result["animationRequests"]

    gpu_a, gpu_b, cpu_b = (canvas_part(load_png(s["path"])) for s in shots)
    background = gpu_a[2, 2]
    mesh = np.abs(gpu_a - background).sum(axis=2) > 30
    # the long thin fish, framed by the bounding sphere of its motion, covers about 2.5% of the view
    assert mesh.mean() > 0.01, f"the mesh covers only {mesh.mean():.1%} of the view"
    lum = gpu_a[mesh].mean(axis=1)
    assert lum.std() > 8 and np.ptp(lum) > 60, "the mesh looks flat: is it lit?"
    moved = np.abs(gpu_a - gpu_b).sum(axis=2) > 30
    assert moved.mean() > 0.002, f"only {moved.mean():.2%} of pixels change between t=0.1 and t=0.6"
    # the shader and the CPU path draw the same frame (antialiasing and float rounding aside)
    same = np.abs(gpu_b - cpu_b).sum(axis=2) > 60
    assert same.mean() < 0.005, f"GPU and CPU frames differ on {same.mean():.2%} of pixels"
    for shot in shots:  # keep them for a person to look at
        shutil.copy(shot["path"], services.log_dir / f"{kind}-{Path(shot['path']).name}")


# the clip's frames on the source glTF in the viewer against three.js drawing that glTF (its own skinning, at
# the same times) in another page, without the viewer's CSP; the bound is 1% of the model's pixels off by more
# than 40 levels (docs/gltf.md, "How close the look is"):
# - "bones" (bones auto at the default target, rel. RMS 3e-3: what `pdeanim fit` does with a skinned glTF, the
#   file's two joints and weights): the file's own skeleton bounds the largest error by the target
#   (FitTolerances.skin_max_ratio) and the bone layer is the rate-distortion slope rule's (skin_rd_slope):
#   0.28/0.27/0.29% flat, 0.40/0.36/0.37% smooth (2026-12-08, t = 0, 0.5, 1). Before those two rules
#   (2026-12-07): 1.14/1.09/2.71% flat, 1.34/1.43/3.17% smooth (the tail joint's track in one segment, 4-bit
#   weights: the tail moved rigidly by 2-3.6e-3 of the diagonal).
# - "curve" (bones 0, the HTTP default): does NOT meet 1% at the default target: 0.13/1.50/1.77% flat,
#   -/1.84/1.78% smooth, following the stored clip's largest error in each frame (1.9e-4, 8.7e-3, 8.9e-3 of
#   the diagonal: the knots' rounding, which the rate control grows to fill the target). Fitted at 2e-4:
#   0.01-0.31%.
LOOK_TIMES = [0.0, 0.5, 1.0]
LOOK_DIFFER = 0.01
LOOK_FIT_RMS = 2e-4
LOOK_FITS = {"bones": {"bones": "auto"},  # the default target
             "curve": {"target_rel_rms": LOOK_FIT_RMS}}


@pytest.mark.parametrize(("flat", "fit"), [(True, "bones"), (False, "bones"), (False, "curve")],
                         ids=["flat-bones", "smooth-bones", "smooth-curve"])
def test_viewer_plays_on_the_source_gltf_with_its_look(services, browser_env, flat, fit, tmp_path):
    """The mesh was uploaded as a textured, skinned GLB (flat: no normals, unwelded): the viewer plays the
    clip on that glTF (texture, flat or smooth shading kept) and its frames look like three.js's own rendering
    of the source at the same times, drawn in a page without the viewer's Content-Security-Policy."""
    from tests.browser.models import creature_glb

    key = make_key(services.backend, "look")
    api = client(services, key)
    glb = creature_glb(flat)
    mesh = api.post("/v1/meshes", files={"file": ("creature.glb", glb, "model/gltf-binary")})
    assert mesh.status_code == 201, mesh.text
    mid = mesh.json()["id"]
    got = api.get(f"/v1/meshes/{mid}/file")
    assert got.status_code == 200 and got.content == glb
    assert got.headers["content-type"] == "model/gltf-binary"
    poses = api.post(f"/v1/meshes/{mid}/poses", params={"fps": 10},
                     files={"file": ("creature.glb", glb, "model/gltf-binary")})
    assert poses.status_code == 201, poses.text
    r = api.post("/v1/jobs", json={"kind": "fit", "poses_id": poses.json()["id"], "params": LOOK_FITS[fit]})
    assert r.status_code == 202, r.text
    job = wait_job(api, r.json()["id"], timeout=300)
    assert job["state"] == "succeeded", (job, services.logs())
    cid = job["result"]["clip_id"]
    shots = [{"t": 0.0, "mode": "cpu", "path": str(tmp_path / "cpu.png")},
             {"t": 0.0, "mode": "gpu", "path": str(tmp_path / "gpu.png")}]
    reference = {"times": LOOK_TIMES, "fileUrl": f"{services.url}/v1/meshes/{mid}/file", "key": key,
                 "dir": str(tmp_path)}
    job = {"url": f"{services.url}/viewer#clip={cid}&key={key}&aa=0", "shots": shots, "reference": reference}
    result = run_viewer(services, browser_env, tmp_path, job)
    assert result["info"]["model"] == "gltf", result["info"]
    # bones auto keeps the file's two joints (a bone clip, played with its bone layer); the curve fit has none
    bones = (result["info"].get("bones") or {}).get("nBones")
    assert bones == (2 if fit == "bones" else None), result["info"]
    name = f"{'flat' if flat else 'smooth'}-{fit}"
    ref = result["reference"]
    assert ref["flat"] is flat  # GLTFLoader shades a glTF without normals flat
    # the texture shows in both pages: the viewer's CSP lets GLTFLoader read the GLB's embedded image
    assert ref["textured"] and ref["viewerTextured"], result["logs"]
    refused = [line for line in result["logs"] if "Content Security Policy" in line]
    assert not refused, refused
    differs = []  # every time is measured and printed before the bound is checked
    for t, clip_path, ref_path in zip(LOOK_TIMES, ref["clipPaths"], ref["referencePaths"], strict=True):
        clip_img, ref_img = load_png(clip_path), load_png(ref_path)
        assert clip_img.shape == ref_img.shape
        background = ref_img[2, 2]
        model = np.abs(ref_img - background).sum(axis=2) > 30
        assert model.mean() > 0.02, f"the model covers {model.mean():.1%} of the view"
        colours = ref_img[model].std(axis=0).max()
        assert colours > 20, "the reference model shows no texture"
        differ = (np.abs(clip_img - ref_img).max(axis=2) > 40).sum() / model.sum()
        print(f"look ({name}, t={t}): {differ:.3%} of the model's pixels differ by more than 40 levels, "
              f"model {model.mean():.1%} of the view")
        differs.append(differ)
        shutil.copy(clip_path, services.log_dir / f"look-{name}-clip-{t}.png")
        shutil.copy(ref_path, services.log_dir / f"look-{name}-reference-{t}.png")
    worst = int(np.argmax(differs))
    assert differs[worst] < LOOK_DIFFER, \
        f"t={LOOK_TIMES[worst]}: {differs[worst]:.2%} of the model's pixels differ from three.js's own"
    gpu, cpu = (canvas_part(load_png(s["path"])) for s in shots)
    assert (np.abs(gpu - cpu).max(axis=2) > 40).mean() < 0.005  # no facets on the GPU path


CESIUM_MAN = HERE.parent / "gltf" / "data" / "CesiumMan.glb"


def test_viewer_plays_a_service_made_bone_clip_of_a_skinned_gltf(services, browser_env, tmp_path):
    """A skinned glTF (CesiumMan) uploaded as mesh and poses, fitted by the service with bones: the fit keeps
    the file's skeleton and the viewer plays the clip with its bone layer, drawing frames that change, with
    no error on the page's console, on the GPU path as on the CPU one."""
    from pdeanim.clip import load_clip

    key = make_key(services.backend, "bones")
    api = client(services, key)
    glb = CESIUM_MAN.read_bytes()
    mesh = api.post("/v1/meshes", files={"file": ("CesiumMan.glb", glb, "model/gltf-binary")})
    assert mesh.status_code == 201, mesh.text
    poses = api.post(f"/v1/meshes/{mesh.json()['id']}/poses", params={"fps": 10},
                     files={"file": ("CesiumMan.glb", glb, "model/gltf-binary")})
    assert poses.status_code == 201, poses.text
    r = api.post("/v1/jobs", json={"kind": "fit", "poses_id": poses.json()["id"],
                                   "params": {"target_rel_rms": 3e-3, "bones": "auto"}})
    assert r.status_code == 202, r.text
    job = wait_job(api, r.json()["id"], timeout=600)
    assert job["state"] == "succeeded", (job, services.logs())
    cid = job["result"]["clip_id"]
    clip = load_clip(api.get(f"/v1/clips/{cid}/topology").content,
                     api.get(f"/v1/clips/{cid}/coefficients").content)
    assert clip.bones is not None and clip.bones.enc.n_bones == 19  # the file's 19 joints, no decomposition
    shots = [{"t": 0.1, "mode": "gpu", "path": str(tmp_path / "gpu_a.png")},
             {"t": 0.6, "mode": "gpu", "path": str(tmp_path / "gpu_b.png")},
             {"t": 0.6, "mode": "cpu", "path": str(tmp_path / "cpu_b.png")}]
    run = {"url": f"{services.url}/viewer#clip={cid}&key={key}", "times": [0.0, 0.5], "shots": shots,
           "playFrames": 20}
    result = run_viewer(services, browser_env, tmp_path, run)
    info = result["info"]
    assert info["bones"] == {"nBones": 19, "residual": info["bones"]["residual"]}, info
    assert info["mode"] == "gpu", info["gpuUnavailableReason"]
    played = result["played"]
    assert played["frames"] >= 20 and played["end"] != played["start"], played
    # console errors, uncaught exceptions and failed requests; a request the page itself aborts (the size of
    # the animation GLB is asked for with HEAD and dropped when the page moves on) is not a failure
    errors = [line for line in result["logs"] if line.startswith(("error", "pageerror"))
              or (line.startswith("requestfailed") and "ERR_ABORTED" not in line)]
    assert not errors, errors
    diag = float(np.linalg.norm(np.ptp(clip.evaluate(0.0), axis=0)))
    for t, got in zip([0.0, 0.5], result["positions"], strict=True):
        js = np.asarray(got, dtype=np.float64).reshape(-1, 3)
        assert float(np.abs(js - clip.evaluate(t)).max()) <= TOLERANCE * diag, t
    gpu_a, gpu_b, cpu_b = (canvas_part(load_png(s["path"])) for s in shots)
    background = gpu_a[2, 2]
    assert (np.abs(gpu_a - background).sum(axis=2) > 30).mean() > 0.01, "the model is not drawn"
    moved = np.abs(gpu_a - gpu_b).sum(axis=2) > 30
    assert moved.mean() > 0.002, f"only {moved.mean():.2%} of pixels change between t=0.1 and t=0.6"
    same = np.abs(gpu_b - cpu_b).sum(axis=2) > 60
    assert same.mean() < 0.005, f"GPU and CPU frames differ on {same.mean():.2%} of pixels"
    for shot in shots:
        shutil.copy(shot["path"], services.log_dir / f"bones-{Path(shot['path']).name}")


def test_viewer_without_a_valid_key_says_why(services, browser_env, clips, tmp_path):
    job = {"url": f"{services.url}/viewer#clip={clips['dynamic-pde']}&key=pda_wrong",
           "out": str(tmp_path / "r.json")}
    proc = subprocess.run(["node", str(HERE / "viewer_check.mjs"), json.dumps(job)], cwd=HERE,
                          env=browser_env, capture_output=True, text=True, timeout=300)
    result = json.loads(Path(job["out"]).read_text())
    assert proc.returncode == 1 and "invalid API key" in result["error"], result


def test_viewer_page_needs_no_key_and_sends_none(services):
    r = client(services, None).get("/viewer")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    assert r.headers["referrer-policy"] == "no-referrer" and "importmap" in r.text
    csp = r.headers["content-security-policy"]
    assert "default-src 'self'" in csp and "worker-src 'self';" in csp
    assert "connect-src 'self' blob: data:" in csp  # GLTFLoader fetches a GLB's images through blob: URLs
    for path in ("/static/viewer/viewer.js", "/static/viewer/pdeanim/index.js",
                 "/static/vendor/three/three.module.js", "/static/vendor/fzstd/fzstd.js"):
        got = client(services, None).get(path)
        assert got.status_code == 200, path
        assert "javascript" in got.headers["content-type"], path  # module scripts need a JavaScript type


def test_docs_render_with_no_other_host_reachable(services, browser_env):
    """/docs and /redoc render the API's title in Chromium while every request to another host is refused."""
    proc = subprocess.run(["node", str(HERE / "docs_check.mjs"), services.url], cwd=HERE, env=browser_env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    for page in ("/docs", "/redoc"):
        assert "pdeanim" in result[page]["title"], result
        assert result[page]["outside"] == [], result
