// The pdeanim clip viewer: downloads a clip's topology and coefficients from this service (key from the URL
// fragment; decoded in a Web Worker), plays it with the JS package (GPU vertex shader or CPU) on the mesh's
// original glTF when the clip came from one (its materials, textures and hierarchy), else on a mesh of the
// clip's own topology, and compares the bytes it downloaded against raw float32 frames and the animation
// GLB (its size as the service reports it: a HEAD request). window.pdeanimViewer is the handle automated checks use.

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { createEvaluator } from 'pdeanim';
import { PDEClipLoader, attachClip, attachClipToScene } from 'pdeanim/three.js';

const ROOT = document.querySelector('meta[name="pdeanim-root"]')?.content ?? '';
const GLB_AUTO_LIMIT = 64 * 1024 * 1024; // ask for the animation GLB's size at once only below this raw size
const FRAME_WINDOW = 1200; // frames kept for the per-frame JavaScript time statistics

const $ = (id) => document.getElementById(id);
const fmtBytes = (n) => (n == null ? '—' : n < 1024 ? `${n} B` : n < 1048576 ? `${(n / 1024).toFixed(1)} KiB`
  : `${(n / 1048576).toFixed(2)} MiB`);
const ratio = (a, b) => (a && b ? `${(a / b * 100).toFixed(1)} %` : '');

function message(text, isError = false) {
  const el = $('message');
  el.textContent = text;
  el.classList.toggle('error', isError);
}

/** Bytes on the GPU for the clip: data textures plus the per-vertex attributes of its meshes. */
function gpuBytes(player) {
  if (player.gpuBytes !== undefined) return player.gpuBytes;
  return player.resources.textureBytes + player.attributeBytes;
}

function median(values) {
  if (!values.length) return null;
  const s = [...values].sort((a, b) => a - b);
  return s[Math.floor(s.length / 2)];
}

function percentile(values, q) {
  if (!values.length) return null;
  const s = [...values].sort((a, b) => a - b);
  return s[Math.min(s.length - 1, Math.floor(q * s.length))];
}

/** Bytes of a response as they came over the wire (Resource Timing), falling back to the decoded size. */
function wireBytes(url, decoded) {
  const entries = performance.getEntriesByName(new URL(url, location.href).href);
  const last = entries[entries.length - 1];
  return last && last.encodedBodySize > 0 ? last.encodedBodySize : decoded;
}

async function apiJson(path, key) {
  const headers = { Authorization: `Bearer ${key}`, Accept: 'application/json' };
  const res = await fetch(ROOT + path, { headers });
  const body = await res.json().catch(() => null);
  if (!res.ok) {
    throw new Error(body?.error?.message ? `${res.status}: ${body.error.message}` : `HTTP ${res.status}`);
  }
  return body;
}

/** The clip's source frame rate (frames per second of its frame times), 30 when unknown. */
function sourceFps(clip) {
  const times = clip.frameTimes;
  if (!times || times.length < 2) return 30;
  const span = times[times.length - 1] - times[0];
  return span > 0 ? (times.length - 1) / span : 30;
}

class Viewer {
  constructor({ antialias = true } = {}) {
    this.renderer = new THREE.WebGLRenderer({ canvas: $('canvas'), antialias,
      preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    this.renderer.outputColorSpace = THREE.SRGBColorSpace;
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x262b33);
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.01, 100);
    this.scene.add(new THREE.HemisphereLight(0xf2f4ff, 0x3a3026, 0.7));
    // a key light fixed to the camera (upper left of the view), so the shading reads from every angle
    this.sun = new THREE.DirectionalLight(0xffffff, 2.8);
    this.sun.position.set(-0.6, 0.9, 0.5);
    this.sun.target.position.set(0, 0, -1);
    this.camera.add(this.sun, this.sun.target);
    this.scene.add(this.camera);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener('change', () => { this.dirty = true; });
    this.playing = true;
    this.t = 0;
    this.frameJs = [];
    this.frameTimes = [];
    this.dirty = true;
    this.sizes = {};
    new ResizeObserver(() => this.resize()).observe($('stage'));
    this.resize();
  }

  resize() {
    const { clientWidth: w, clientHeight: h } = $('stage');
    if (!w || !h) return;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.dirty = true;
  }

  async open(clipId, key) {
    this.clipId = clipId;
    this.key = key;
    message(`loading clip ${clipId}…`);
    this.meta = await apiJson(`/v1/clips/${encodeURIComponent(clipId)}`, key);
    const base = `${ROOT}/v1/clips/${encodeURIComponent(clipId)}`;
    const urls = { topology: `${base}/topology`, coefficients: `${base}/coefficients` };
    const source = this.meta.mesh_id ? this.sourceGltf(this.meta.mesh_id) : Promise.resolve(null);
    const timings = { start: performance.now() };
    const limit = this.renderer.capabilities.maxTextureSize;
    const loader = new PDEClipLoader().setRequestHeader({ Authorization: `Bearer ${key}` })
      .setTextureWidth(Math.min(4096, limit));
    // the download ends when both parts are in: the loader then decodes them off the main thread
    const clip = await loader.loadAsync(base, (e) => {
      if (e.lengthComputable && e.loaded === e.total) timings.downloaded ??= performance.now();
    });
    timings.decoded = performance.now();
    timings.downloaded ??= timings.decoded;
    this.evaluator = createEvaluator(clip);
    const entries = (u) => performance.getEntriesByName(new URL(u, location.href).href).at(-1);
    const decoded = (u) => entries(u)?.decodedBodySize || 0;
    // the loader asks for the streamable layout (?layout=stream) and reads the plain part where there is none
    const coefficients = [`${urls.coefficients}?layout=stream`, urls.coefficients].find((u) => entries(u))
      ?? urls.coefficients;
    this.sizes = {
      topologyWire: wireBytes(urls.topology, decoded(urls.topology)),
      coefficientsWire: wireBytes(coefficients, decoded(coefficients)),
      topology: decoded(urls.topology),
      coefficients: decoded(coefficients),
      raw: this.meta.sizes?.raw_float32_bytes
        ?? (this.meta.frames ?? clip.frameTimes.length) * clip.nVertices * 12,
      glb: null,
      glbNote: 'not measured',
    };
    const gltf = await source.catch((err) => {
      this.sourceNote = `the mesh's glTF could not be used (${err.message})`;
      return null;
    });
    this.buildModel(clip, gltf);
    this.attachPlayer(clip);
    this.duration = clip.frameTimes.length > 1
      ? clip.frameTimes[clip.frameTimes.length - 1] - clip.frameTimes[0] : 1;
    if (!(this.duration > 0)) this.duration = 1;
    this.clip = clip; // from here on the animation loop plays it
    this.enableControls();
    this.renderer.render(this.scene, this.camera);
    this.renderer.getContext().finish();
    timings.firstFrame = performance.now();
    this.timings = timings;
    this.renderStats();
    message(this.sourceNote ?? '');
    if (this.sizes.raw <= GLB_AUTO_LIMIT) this.measureGlb();
  }

  /** The mesh's uploaded file as a glTF scene when it is one (GLB), else null. */
  async sourceGltf(meshId) {
    const mesh = await apiJson(`/v1/meshes/${encodeURIComponent(meshId)}`, this.key);
    if (!/\.(glb|gltf)$/i.test(mesh.filename ?? '')) return null;
    const res = await fetch(`${ROOT}/v1/meshes/${encodeURIComponent(meshId)}/file`,
      { headers: { Authorization: `Bearer ${this.key}` } });
    if (!res.ok) throw new Error(`HTTP ${res.status}`);
    return new GLTFLoader().parseAsync(await res.arrayBuffer(), '');
  }

  /** The model to play on: the source glTF's scene (when its vertices are the clip's), else the clip's mesh. */
  buildModel(clip, gltf) {
    let count = 0;
    gltf?.scene.traverse((o) => { if (o.isMesh) count += o.geometry.getAttribute('position').count; });
    if (gltf && count === clip.nVertices) {
      this.model = gltf.scene;
      this.sourceKind = 'gltf';
    } else {
      if (gltf) this.sourceNote = `the mesh's glTF has ${count} vertices, the clip ${clip.nVertices}: not used`;
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.BufferAttribute(Float32Array.from(clip.rest), 3));
      geometry.setIndex(new THREE.BufferAttribute(Uint32Array.from(clip.faces), 1));
      geometry.computeVertexNormals(); // unwelded (flat) meshes come out flat, welded ones smooth
      const material = new THREE.MeshStandardMaterial({ color: 0xd9a066, roughness: 0.55, metalness: 0.05,
        side: THREE.DoubleSide });
      this.model = new THREE.Mesh(geometry, material);
      this.mesh = this.model;
      this.sourceKind = 'clip';
    }
    this.scene.add(this.model);
    this.frame(clip);
  }

  /** Frame the whole motion: the bounding box over a few times, not only the rest pose. */
  frame(clip) {
    const box = new THREE.Box3();
    const pos = new Float32Array(clip.nVertices * 3);
    // a clip still downloading (the streamable layout) is framed on the times it has decoded so far
    const times = (clip.looping ? [0, 0.25, 0.5, 0.75] : [0, 0.25, 0.5, 0.75, 1]).filter((t) => clip.ready?.(t) ?? true);
    this.model.updateMatrixWorld(true);
    const toWorld = this.model.matrixWorld;
    for (const t of times) {
      this.evaluator.evaluate(t, pos);
      for (let i = 0; i < pos.length; i += 3) {
        box.expandByPoint(new THREE.Vector3(pos[i], pos[i + 1], pos[i + 2]).applyMatrix4(toWorld));
      }
    }
    const center = box.getCenter(new THREE.Vector3());
    const radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1e-6);
    const vfov = THREE.MathUtils.degToRad(this.camera.fov);
    const hfov = 2 * Math.atan(Math.tan(vfov / 2) * this.camera.aspect);
    const dist = radius / Math.sin(Math.min(vfov, hfov) / 2) * 1.05;
    this.camera.near = dist / 100;
    this.camera.far = dist * 10;
    this.camera.position.copy(center).add(new THREE.Vector3(0.55, 0.35, 1).normalize().multiplyScalar(dist));
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(center);
    this.controls.update();
  }

  attachPlayer(clip) {
    const options = { gpu: true, renderer: this.renderer };
    this.player = this.sourceKind === 'gltf' ? attachClipToScene(this.model, clip, options)
      : attachClip(this.mesh, clip, options);
    this.gpuReason = this.player.gpuUnavailableReason ?? null;
  }

  get mode() { return this.player?.gpu ? 'gpu' : 'cpu'; }

  setMode(mode) {
    const gpu = mode === 'gpu';
    if (this.player) this.player.useGPU(gpu);
    if (gpu && (!this.player || !this.player.gpu)) {
      message(`GPU evaluation unavailable: ${this.gpuReason}`, true);
    }
    for (const input of document.querySelectorAll('input[name=mode]')) {
      input.checked = input.value === this.mode;
    }
    this.apply(this.t);
    this.renderStats();
    return this.mode;
  }

  /** Move the mesh to normalised time t (GPU: uniforms; CPU: positions and normals rewritten). */
  apply(t) {
    this.t = t;
    this.player.setTime(t);
    $('scrub').value = String(t);
    $('t-value').textContent = t.toFixed(3);
    this.dirty = true;
  }

  enableControls() {
    for (const el of document.querySelectorAll('#controls button, #controls input')) el.disabled = false;
    if (!this.player?.gpu && this.gpuReason) {
      document.querySelector('input[name=mode][value=gpu]').disabled = true;
    }
    $('play').onclick = () => (this.playing ? this.pause() : this.play());
    $('scrub').oninput = (e) => { this.pause(); this.apply(Number(e.target.value)); };
    for (const input of document.querySelectorAll('input[name=mode]')) {
      input.onchange = () => this.setMode(input.value);
    }
    this.setMode(this.player?.gpu ? 'gpu' : 'cpu');
  }

  play() { this.playing = true; $('play').textContent = 'pause'; this.last = undefined; }

  pause() { this.playing = false; $('play').textContent = 'play'; }

  /** One animation frame: advance t when playing, update, render; records the JavaScript time it took. */
  tick(now) {
    const start = performance.now();
    if (this.clip) {
      if (this.playing) {
        const dt = this.last === undefined ? 0 : Math.min((now - this.last) / 1000, 0.1);
        let t = this.t + dt / this.duration;
        t -= Math.floor(t); // clips that do not loop take t in [0, 1] only: replay from 0
        this.apply(t);
      }
      this.last = now;
    }
    if (this.dirty || this.renderAlways) {
      this.renderer.render(this.scene, this.camera);
      this.dirty = false;
    }
    if (this.clip && (this.playing || this.renderAlways)) {
      this.frameJs.push(performance.now() - start);
      this.frameTimes.push(now);
      if (this.frameJs.length > FRAME_WINDOW) { this.frameJs.shift(); this.frameTimes.shift(); }
    }
    requestAnimationFrame((n) => this.tick(n));
  }

  /** Frame statistics over the last frames while playing: rate and JavaScript milliseconds per frame. */
  frameStats() {
    const n = this.frameTimes.length;
    const fps = n > 1 ? (n - 1) / ((this.frameTimes[n - 1] - this.frameTimes[0]) / 1000) : null;
    return { frames: n, fps, jsMsMedian: median(this.frameJs), jsMsP95: percentile(this.frameJs, 0.95) };
  }

  resetFrameStats() { this.frameJs = []; this.frameTimes = []; }

  /** Ask the service for the size of the animation GLB of the same frames, as served (HEAD: no download). */
  async measureGlb() {
    const fps = Math.round(sourceFps(this.clip) * 1000) / 1000;
    const url = `${ROOT}/v1/clips/${encodeURIComponent(this.clipId)}/animation?fps=${fps}`;
    this.sizes.glbNote = 'measuring…';
    this.renderStats();
    try {
      const res = await fetch(url, { method: 'HEAD', headers: { Authorization: `Bearer ${this.key}` } });
      const length = Number(res.headers.get('content-length'));
      if (res.status === 413) this.sizes.glbNote = 'larger than a request builds (an export job makes it)';
      else if (!res.ok) this.sizes.glbNote = `not available (HTTP ${res.status})`;
      else if (!(length > 0)) this.sizes.glbNote = 'not available (no Content-Length)';
      else {
        this.sizes.glb = length;
        const coding = res.headers.get('content-encoding');
        this.sizes.glbNote = coding ? `fps ${fps}, ${coding}` : `fps ${fps}`;
      }
    } catch (err) {
      this.sizes.glbNote = `not available (${err.message})`;
    }
    this.renderStats();
    return this.sizes.glb;
  }

  renderStats() {
    const s = this.sizes;
    const m = this.meta ?? {};
    const downloaded = (s.topologyWire ?? 0) + (s.coefficientsWire ?? 0);
    const rows = [
      ['clip', `${m.kind ?? ''}${this.clip?.looping ? ', looping' : ''}`],
      ['vertices / faces', this.clip ? `${this.clip.nVertices} / ${this.clip.faces.length / 3}` : ''],
      ['source frames', m.frames ?? ''],
      ['evaluation', this.clip ? this.mode.toUpperCase() : ''],
      ['model', this.sourceKind === 'gltf' ? "the mesh's glTF (its materials)" : "the clip's mesh"],
      ['GPU data (textures, attributes)', this.player ? fmtBytes(gpuBytes(this.player)) : ''],
      ['first frame', this.timings ? `${(this.timings.firstFrame - this.timings.downloaded).toFixed(0)} ms after the download` : ''],
      ['downloaded (as served)', `${fmtBytes(downloaded)}`],
      ['  topology', `${fmtBytes(s.topologyWire)} (${fmtBytes(s.topology)} decoded)`],
      ['  coefficients', `${fmtBytes(s.coefficientsWire)} (${fmtBytes(s.coefficients)} decoded)`],
      ['raw float32 frames', `${fmtBytes(s.raw)}  → ${ratio(downloaded, s.raw)}`],
      ['animation GLB (as served)', s.glb ? `${fmtBytes(s.glb)}  → ${ratio(downloaded, s.glb)}` : s.glbNote],
    ];
    $('stats').tBodies[0].replaceChildren(...rows.map(([k, v]) => {
      const tr = document.createElement('tr');
      for (const text of [k, v]) {
        tr.appendChild(Object.assign(document.createElement('td'), { textContent: text }));
      }
      return tr;
    }));
  }
}

// #aa=0 turns multisampling off (cheaper on software WebGL)
const viewer = new Viewer({ antialias: new URLSearchParams(location.hash.slice(1)).get('aa') !== '0' });
requestAnimationFrame((n) => viewer.tick(n));

function fragment() {
  const p = new URLSearchParams(location.hash.slice(1));
  return { clip: p.get('clip'), key: p.get('key'), t: p.get('t'), mode: p.get('mode'), play: p.get('play') };
}

async function start() {
  const f = fragment();
  $('clip-id').value = f.clip ?? '';
  $('api-key').value = f.key ?? '';
  if (!f.clip || !f.key) {
    message('open a clip: /viewer#clip=CLIP_ID&key=API_KEY (or fill in the form)');
    return new Promise(() => {}); // resolves once a clip is opened through the form (page reload)
  }
  await viewer.open(f.clip, f.key);
  if (f.mode) viewer.setMode(f.mode);
  if (f.t !== null) viewer.apply(Number(f.t));
  if (f.play === '0' || f.t !== null) viewer.pause();
  return viewer;
}

$('open').onsubmit = (e) => {
  e.preventDefault();
  const p = new URLSearchParams({ clip: $('clip-id').value.trim(), key: $('api-key').value.trim() });
  location.hash = p.toString();
  location.reload();
};

const ready = start().catch((err) => {
  message(`could not open the clip: ${err.message}`, true);
  throw err;
});

/** Wait until a frame with the current state has been rendered and presented. */
function nextFrame() {
  viewer.dirty = true;
  return new Promise((resolve) => requestAnimationFrame(() => requestAnimationFrame(resolve)));
}

window.pdeanimViewer = {
  ready,
  /** The CPU-evaluated positions (V * 3, clip vertex order) at normalised time t. */
  async positions(t) {
    await viewer.clip.whenReady?.(Number(t)); // a streaming clip: t's window fetched and decoded first
    const out = new Float32Array(viewer.clip.nVertices * 3);
    return viewer.evaluator.evaluate(Number(t), out) ?? out;
  },
  /** Pause and show time t; resolves after it has been rendered. */
  async show(t) {
    viewer.pause();
    await viewer.clip.whenReady?.(Number(t));
    viewer.apply(Number(t));
    await nextFrame();
    return viewer.t;
  },
  setMode: (mode) => viewer.setMode(mode),
  get mode() { return viewer.mode; },
  get gpuUnavailableReason() { return viewer.gpuReason; },
  /** What the clip plays on: 'gltf' (the mesh's own glTF) or 'clip' (the clip's topology). */
  get model() { return viewer.sourceKind; },
  /** Whether a mesh of the model shows a texture (its image loaded). */
  get textured() {
    let on = false;
    viewer.model?.traverse((o) => { if (o.isMesh && o.material?.map?.image) on = true; });
    return on;
  },
  /** ms: start, downloaded (both parts in), decoded (worker done), firstFrame (drawn, gl.finish). */
  get timings() { return { ...viewer.timings }; },
  get gpuBytes() { return gpuBytes(viewer.player); },
  play: () => viewer.play(),
  pause: () => viewer.pause(),
  get t() { return viewer.t; },
  get clip() { return viewer.clip; },
  sizes: () => ({ ...viewer.sizes }),
  /**
   * Draw another object in place of the clip's model (null: the clip's model again), with the same camera
   * and lights; resolves after it has been rendered (screenshot comparisons against the source model).
   */
  async swapModel(other) {
    if (viewer.other) viewer.scene.remove(viewer.other);
    viewer.other = other ?? null;
    viewer.model.visible = !other;
    if (other) viewer.scene.add(other);
    await nextFrame();
  },
  /**
   * The view in plain numbers (world space): canvas size, background, camera and lights, so that another
   * page can draw the same view with three.js alone.
   */
  stage() {
    const { camera, renderer, scene } = viewer;
    scene.updateMatrixWorld(true);
    const lights = [];
    scene.traverse((o) => {
      if (!o.isLight) return;
      const light = { type: o.type, color: o.color.getHex(), intensity: o.intensity,
        position: o.getWorldPosition(new THREE.Vector3()).toArray() };
      if (o.groundColor) light.groundColor = o.groundColor.getHex();
      if (o.target) light.target = o.target.getWorldPosition(new THREE.Vector3()).toArray();
      lights.push(light);
    });
    const size = renderer.getSize(new THREE.Vector2());
    return { width: size.x, height: size.y, pixelRatio: renderer.getPixelRatio(),
      background: scene.background.getHex(), lights,
      camera: { fov: camera.fov, aspect: camera.aspect, near: camera.near, far: camera.far,
        matrixWorld: camera.matrixWorld.toArray() } };
  },
  measureGlb: () => viewer.measureGlb(),
  frameStats: () => viewer.frameStats(),
  resetFrameStats: () => viewer.resetFrameStats(),
  /** Render (and count) every frame even when nothing changed: the drawing cost alone, for benchmarks. */
  set renderAlways(on) { viewer.renderAlways = Boolean(on); },
};
