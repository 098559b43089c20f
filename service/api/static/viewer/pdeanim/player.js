// ClipPlayer: a decoded clip played on one three.js mesh, keeping the mesh's materials. The clip is evaluated
// on the GPU (data textures + per-vertex attributes + per-frame uniforms) or, as a fallback, on the CPU into
// two extra attributes; either way the patched shader puts the clip's vertex in place of the mesh's after
// morphing and skinning, mixed by `influence` (1: the clip alone; 0: the mesh as without it).

import { BufferAttribute, InstancedBufferAttribute, Matrix3, Matrix4 } from 'three';
import { computeNormals } from './geometry.js';
import { clipNormals, frameNormals, gpuAttributes, meshAttributes, smoothVertices } from './gpu.js';
import { CROWD_FORMS, ClipResources, FrameTables } from './resources.js';
import { webglBackend } from './webgl.js';

export const MAP_ATTRIBUTES = ['_pdeanim_vertex', '_PDEANIM_VERTEX'];

/** The options attachClip and ClipPlayer take. */
export const PLAYER_OPTIONS = Object.freeze([
  'gpu',
  'renderer',
  'pass',
  'vertexMap',
  'clipToLocal',
  'normals',
  'textureWidth',
  'maxTextureSize',
  'tables',
  'shadows',
  'frustumCulled',
  'resources',
  'frames',
  'influence',
  'timeOffsets',
  'crowdForm',
]);

/** The per-vertex attributes a player adds to a geometry. */
const PLAYER_ATTRIBUTES = ['pdeVertex', 'pdeNormalFrame', 'pdeSlot', 'pdeCpuPosition', 'pdeCpuNormal'];

/** Who uses the pdeanim attributes of each geometry: {key, users} (geometries shared by cloned meshes). */
const GEOMETRY_USERS = new WeakMap();

/** Whether two geometry users' attributes are the same (same clip resources, vertex map, placement, slots). */
function sameUse(a, b) {
  const eq = (x, y) => x === y || (x !== null && y !== null && x.length === y.length && x.every((v, i) => v === y[i]));
  return a.resources === b.resources && eq(a.vertexMap, b.vertexMap) && eq(a.placement, b.placement) && eq(a.slots, b.slots);
}

/** Throw a TypeError naming any option not in allowed (an ignored option would fail silently). */
export function checkOptions(options, allowed, what) {
  const unknown = Object.keys(options ?? {}).filter((k) => !allowed.includes(k));
  if (unknown.length) {
    throw new TypeError(`${what}: unknown option(s) ${unknown.join(', ')} (known: ${allowed.join(', ')})`);
  }
}

/** The clip vertex of every mesh vertex: options.vertexMap, a _pdeanim_vertex attribute, or the identity. */
function resolveVertexMap(geometry, clip, vertexMap) {
  const count = geometry.attributes.position.count;
  let map = vertexMap;
  if (!map) {
    const attr = MAP_ATTRIBUTES.map((n) => geometry.getAttribute(n)).find(Boolean);
    if (attr) map = Int32Array.from({ length: count }, (_, i) => Math.round(attr.getX(i)));
  }
  if (!map) {
    if (count !== clip.nVertices) {
      throw new Error(
        `the mesh has ${count} vertices and the clip ${clip.nVertices}: pass options.vertexMap ` +
          '(the clip vertex of each mesh vertex) or a _pdeanim_vertex attribute',
      );
    }
    map = Int32Array.from({ length: count }, (_, i) => i);
  }
  if (map.length !== count || map.some((v) => !(v >= 0 && v < clip.nVertices))) {
    throw new Error('vertexMap must give a clip vertex (0 .. nVertices - 1) for every mesh vertex');
  }
  return Int32Array.from(map);
}

/** A float copy (n * 3) of a 3-component attribute (dequantised, de-interleaved). */
function floatCopy(attr) {
  const out = new Float32Array(attr.count * 3);
  for (let i = 0; i < attr.count; i++) {
    out[i * 3] = attr.getX(i);
    out[i * 3 + 1] = attr.getY(i);
    out[i * 3 + 2] = attr.getZ(i);
  }
  return out;
}

function toMatrix4(m) {
  if (!m) return new Matrix4();
  if (m.isMatrix4) return m.clone();
  return new Matrix4().fromArray(m);
}

/** Apply the affine matrix (elements, column-major) to positions (n * 3) into out. */
function transformPoints(e, src, out) {
  for (let i = 0; i < src.length; i += 3) {
    const x = src[i];
    const y = src[i + 1];
    const z = src[i + 2];
    out[i] = e[0] * x + e[4] * y + e[8] * z + e[12];
    out[i + 1] = e[1] * x + e[5] * y + e[9] * z + e[13];
    out[i + 2] = e[2] * x + e[6] * y + e[10] * z + e[14];
  }
  return out;
}

/** Apply the 3x3 normal matrix (elements, column-major) to normals (n * 3) and normalise, in place. */
function transformNormals(e, n) {
  for (let i = 0; i < n.length; i += 3) {
    const x = e[0] * n[i] + e[3] * n[i + 1] + e[6] * n[i + 2];
    const y = e[1] * n[i] + e[4] * n[i + 1] + e[7] * n[i + 2];
    const z = e[2] * n[i] + e[5] * n[i + 1] + e[8] * n[i + 2];
    const l = Math.hypot(x, y, z) || 1;
    n[i] = x / l;
    n[i + 1] = y / l;
    n[i + 2] = z / l;
  }
  return n;
}

/**
 * Play a decoded clip on mesh (a THREE.Mesh, SkinnedMesh or InstancedMesh whose vertices are the clip's, or
 * mapped to them by options.vertexMap / a _pdeanim_vertex attribute). options: gpu (default true), renderer
 * (bounds the data textures; with float render targets the clip is evaluated in a pass before drawing),
 * pass (force that either way), vertexMap, clipToLocal (Matrix4 or 16 numbers, column-major: clip
 * coordinates to the mesh's local frame; default identity), normals ('frame', the default: each frame's
 * area-weighted vertex normals, as three.js computes them, hard-edge vertices turned with a triangle;
 * 'rest': one evaluation per vertex, normals kept), textureWidth, maxTextureSize,
 * tables (from a Web Worker), shadows (default true), frustumCulled (default false), resources (a
 * ClipResources; default: the clip's shared one, ClipResources.acquire), frames (a FrameTables shared by
 * meshes showing the same time), influence (default 1), timeOffsets (InstancedMesh only: each instance's
 * time offset, an instanced attribute; GPU only, no evaluation pass), crowdForm (when players of the clip at
 * distinct times take its crowd form: 'auto', the default, unless it takes more than twice the GPU bytes of
 * per-frame tables; 'bytes', where it takes fewer; 'always'; 'never': ClipResources.crowdForm, for all the
 * clip's players). Players of one clip share its data
 * texture; each has its own time (per-frame table and uniforms) and its own patched materials.
 */
export class ClipPlayer {
  constructor(mesh, clip, options = {}, backend = webglBackend) {
    checkOptions(options, PLAYER_OPTIONS, 'ClipPlayer');
    const { gpu = true, shadows = true, frustumCulled = false, normals = 'frame', influence = 1 } = options;
    if (normals !== 'frame' && normals !== 'rest') throw new RangeError(`normals must be 'frame' or 'rest'`);
    backend.check(options.renderer);
    this.clip = clip;
    this.mesh = mesh;
    this.normals = normals;
    this.backend = backend;
    const offsets = instanceSlots(mesh, options.timeOffsets);
    if (offsets && !gpu) throw new Error('timeOffsets play on the GPU only (gpu: false was given)');
    this._options = { ...options };
    this.vertexMap = resolveVertexMap(mesh.geometry, clip, options.vertexMap);
    this.resources = options.resources ? options.resources.retain() : ClipResources.acquire(clip, options);
    try {
      // when the clip's players at distinct times take the crowd form (ClipResources.crowdForm)
      if (options.crowdForm !== undefined) {
        if (!CROWD_FORMS.includes(options.crowdForm)) {
          throw new RangeError(`crowdForm must be ${CROWD_FORMS.join(', ')}; got ${options.crowdForm}`);
        }
        this.resources.crowdForm = options.crowdForm;
      }
      if (offsets && this.resources.gpuReason) throw new Error(`timeOffsets play on the GPU only: ${this.resources.gpuReason}`);
      const crowd = backend.crowd === true; // whether the backend's shaders read the crowd form
      this.frames = (options.frames ?? new FrameTables(this.resources, { offsets: offsets?.offsets ?? null, crowd })).retain();
    } catch (e) {
      this.resources.release();
      throw e;
    }
    const { evaluator, gpuReason } = this.resources;
    this.evaluator = evaluator;
    /** Why the GPU path is unavailable (null when it is available). */
    this.gpuUnavailableReason = gpuReason;
    this.slots = offsets !== null;
    this.clipToLocal = toMatrix4(options.clipToLocal);
    this.normalToLocal = new Matrix3().getNormalMatrix(this.clipToLocal);
    this._originalGeometry = mesh.geometry;
    this._use = { resources: this.resources, vertexMap: this.vertexMap, placement: this.clipToLocal.elements, slots: offsets?.slot ?? null };
    this.attributes = this._frameAttributes(offsets);
    this._pass = !this.slots && backend.usePass(options, normals);
    this.uniforms = {
      ...this.resources.uniforms,
      ...this.frames.uniforms,
      pdeEnabled: { value: false },
      pdeInfluence: { value: influence },
      pdeClipToLocal: { value: this.clipToLocal },
      pdeNormalToLocal: { value: this.normalToLocal },
      pdePosTex: { value: null },
    };
    this._onGPU = gpu && !gpuReason;
    this._time = 0;
    this._attached = true;
    this._cpu = null; // CPU path buffers, made on first use
    this._originalCulled = mesh.frustumCulled;
    mesh.frustumCulled = frustumCulled;
    this._installed = backend.install(this, { shadows });
    // the clip's crowd form (another player at another time): the materials recompile
    this._unlisten = this.frames.onChange(() => this._installed.refresh());
    this.useGPU(this._onGPU);
  }

  /**
   * The data textures the shaders read: the clip's vertex records (shared) and the per-frame table (this
   * player's, or in the clip's crowd form the shared atlas of time rows).
   */
  get textures() {
    return { vertex: this.resources.textures.vertex, frame: this.frames.texture ?? undefined };
  }

  /**
   * The clip's GPU layout as this player shows it (a view whose per-frame table is this player's, or slot 0's
   * of an instanced crowd; in the clip's crowd form a view with its own record of the time written).
   */
  get layout() {
    return this.frames.views[0] ?? this.resources.layout;
  }

  /** Whether the evaluation pass runs (not in the clip's crowd form: the vertex shader evaluates then). */
  get pass() {
    return this._pass && !this.frames.crowd;
  }

  /** Whether the clip is in its crowd form (players at distinct times: shared knot table, a time row each). */
  get crowd() {
    return this.frames.crowd;
  }

  /**
   * pdeVertex and pdeNormalFrame (meshAttributes) from the mesh's rest positions and normals, and pdeSlot for
   * an instanced crowd: set on the mesh's geometry, or shared with the players of its clones (same clip, map
   * and placement); a geometry that another player uses otherwise is copied for this mesh.
   */
  _frameAttributes(offsets) {
    let geometry = this.mesh.geometry;
    const user = GEOMETRY_USERS.get(geometry);
    if (user && user.users > 0 && !sameUse(user.key, this._use)) {
      geometry = this.mesh.geometry = geometry.clone();
    }
    const shared = GEOMETRY_USERS.get(geometry);
    if (shared && shared.users > 0) {
      shared.users++;
      this._restNormalsClip = shared.restNormalsClip;
      return shared.attrs;
    }
    const attrs = this._makeAttributes(geometry);
    if (offsets) geometry.setAttribute('pdeSlot', new InstancedBufferAttribute(offsets.slot, 1));
    GEOMETRY_USERS.set(geometry, { key: this._use, users: 1, attrs, restNormalsClip: this._restNormalsClip });
    return attrs;
  }

  _makeAttributes(geometry) {
    const localToClip = this.clipToLocal.clone().invert();
    const restLocal = floatCopy(geometry.getAttribute('position'));
    const restClip = transformPoints(localToClip.elements, restLocal, new Float32Array(restLocal.length));
    // a geometry without normals (e.g. a flat-shaded glTF) gets its own for the frames only: the mesh's
    // geometry is not changed
    const index = geometry.index ? geometry.index.array : null;
    const normalAttr = geometry.getAttribute('normal');
    let normalsClip;
    if (normalAttr) {
      normalsClip = transformNormals(new Matrix3().getNormalMatrix(localToClip).elements, floatCopy(normalAttr));
    } else {
      const faces = index ?? Uint32Array.from({ length: restClip.length / 3 }, (_, i) => i);
      normalsClip = computeNormals(restClip, faces);
    }
    this._restNormalsClip = normalsClip;
    // smooth vertices take their clip vertex's area-weighted normal (the clip's rings, as three.js computes it)
    const restRing = clipNormals(this.layout, this.clip.rest);
    const attrs = meshAttributes({
      vertexMap: this.vertexMap,
      positions: restClip,
      normals: normalsClip,
      index,
      clipNormals: restRing,
    });
    // the shader's copy: the GPU's vertex numbers, the frame normals as normalised int16
    const gpu = gpuAttributes(attrs, this.layout.gpuIndex ?? null);
    geometry.setAttribute('pdeVertex', new BufferAttribute(gpu.pdeVertex, 3));
    geometry.setAttribute('pdeNormalFrame', new BufferAttribute(gpu.pdeNormalFrame, 3, true));
    return attrs;
  }

  /** Whether the GPU evaluates the clip (else the CPU). */
  get gpu() {
    return this._onGPU;
  }

  /** The normalised clip time last shown. */
  get time() {
    return this._time;
  }

  /** How much of the clip is shown: 1 the clip alone, 0 the mesh as without it, between: a linear mix. */
  get influence() {
    return this.uniforms.pdeInfluence.value;
  }

  set influence(w) {
    if (!(w >= 0 && w <= 1)) throw new RangeError(`influence must lie in [0, 1], got ${w}`);
    this.uniforms.pdeInfluence.value = w;
    this.uniforms.pdeEnabled.value = this._attached && w > 0;
  }

  /** The shader variant of this player (materials' program cache key). */
  get programKey() {
    const L = this.layout;
    const mode = this._onGPU ? (this.pass ? 'pass' : 'gpu') : 'cpu';
    const bones = L.bones ? ':bones' : '';
    const slots = this.slots ? ':slots' : '';
    const crowd = this.frames.crowd ? `:crowd${this.resources.crowd?.table.width ?? 0}` : '';
    return `pdeanim:${L.kind}:${L.rigid}:${L.spline}${bones}${slots}${crowd}:${this.normals}:${L.width}:${mode}`;
  }

  /**
   * Show the clip at normalised time t (GPU: a few uniforms; CPU: positions and normals evaluated). t in
   * [0, 1] for clips that do not loop (else RangeError), any t for looping ones (period 1). evaluated: the
   * clip's CPU positions at t when the caller already has them (shared between meshes).
   */
  setTime(t, evaluated = null) {
    // a streaming clip (stream.js): the play head moves there; a window not decoded yet keeps the last frame
    if (this.clip.windowed && !this.clip.setPlayhead(t)) return this;
    if (this._onGPU) this.frames.frame(t);
    else this._writeCPU(evaluated ?? this.evaluator.evaluate(t, this._cpuBuffers().clip));
    this._time = t;
    return this;
  }

  /** Switch between GPU evaluation and the CPU fallback; returns whether the GPU is used. */
  useGPU(on) {
    const gpu = Boolean(on) && !this.gpuUnavailableReason;
    if (!gpu && this.slots) throw new Error('timeOffsets play on the GPU only');
    const changed = gpu !== this._onGPU;
    this._onGPU = gpu;
    if (!gpu) this._cpuBuffers();
    this.uniforms.pdeEnabled.value = this._attached && this.influence > 0;
    if (changed) this._installed.refresh();
    this.frames.invalidate(); // the time state is set again below
    this.setTime(this._time);
    return gpu;
  }

  /** The CPU path's buffers: clip positions, and the attributes the shader reads (made on first use). */
  _cpuBuffers() {
    if (this._cpu) return this._cpu;
    const n = this.vertexMap.length;
    const geometry = this._privateGeometry();
    const position = new BufferAttribute(new Float32Array(n * 3), 3);
    const normal = new BufferAttribute(new Float32Array(n * 3), 3);
    geometry.setAttribute('pdeCpuPosition', position);
    geometry.setAttribute('pdeCpuNormal', normal);
    const V3 = this.clip.nVertices * 3;
    this._cpu = {
      clip: new Float32Array(V3),
      clipNormals: new Float32Array(V3), // the area-weighted normals of the smooth vertices' clip vertices
      smooth: smoothVertices(this.attributes),
      position,
      normal,
      scratch: new Float32Array(n * 3),
    };
    return this._cpu;
  }

  /** The mesh's geometry, copied first when the players of other meshes use it too (CPU attributes are per time). */
  _privateGeometry() {
    const old = this.mesh.geometry;
    const user = GEOMETRY_USERS.get(old);
    if (!user || user.users === 1) return old; // (no user: the caller replaced the geometry)
    user.users--;
    const geometry = (this.mesh.geometry = old.clone());
    GEOMETRY_USERS.set(geometry, { ...user, users: 1 });
    return geometry;
  }

  /** Write the clip positions (V * 3, clip order) and their frame normals for this mesh. */
  _writeCPU(positions) {
    const { position, normal, scratch, clipNormals: ring, smooth } = this._cpuBuffers();
    const map = this.vertexMap;
    for (let i = 0; i < map.length; i++) {
      const v = map[i] * 3;
      scratch[i * 3] = positions[v];
      scratch[i * 3 + 1] = positions[v + 1];
      scratch[i * 3 + 2] = positions[v + 2];
    }
    transformPoints(this.clipToLocal.elements, scratch, position.array);
    position.needsUpdate = true;
    if (this.normals === 'rest') normal.array.set(this._restNormalsClip);
    else {
      clipNormals(this.layout, positions, ring, smooth);
      frameNormals(positions, this.attributes, this._restNormalsClip, normal.array, ring);
    }
    transformNormals(this.normalToLocal.elements, normal.array);
    normal.needsUpdate = true;
  }

  /** The CPU-evaluated positions (V, 3) in clip vertex order at t (for checks; does not touch the mesh). */
  positions(t, out = new Float32Array(this.clip.nVertices * 3)) {
    return this.evaluator.evaluate(t, out);
  }

  /** Bytes this player adds on the GPU for its mesh (per-vertex attributes), besides the shared textures. */
  get attributeBytes() {
    return PLAYER_ATTRIBUTES.reduce((n, k) => n + (this.mesh.geometry.getAttribute(k)?.array.byteLength ?? 0), 0);
  }

  /**
   * Bytes on the GPU for the clip on this mesh: the clip's shared data texture, this player's per-frame
   * table(s) and evaluation pass's texture (when the pass runs), and this mesh's attributes.
   */
  get gpuBytes() {
    return this.resources.sharedBytes + this.frames.bytes + this.attributeBytes;
  }

  /**
   * A new player on a clone of the mesh (mesh.clone(), with the mesh's own materials), with this player's
   * options: its own time, uniforms and patched materials, sharing the clip's data texture (and, while both
   * play, the geometry's attributes). Add its mesh to a scene; player.setTime drives it alone.
   */
  clone() {
    const mesh = this.mesh.clone();
    this._installed.restoreOn(mesh);
    mesh.frustumCulled = this._originalCulled;
    const options = { ...this._options, influence: this.influence, resources: this.resources };
    delete options.frames; // a per-frame table of its own
    const player = new ClipPlayer(mesh, this.clip, options, this.backend);
    player.setTime(this._time);
    return player;
  }

  /** Restore the mesh's materials and geometry; the textures are freed with their last player. */
  detach() {
    if (!this._attached) return;
    this._attached = false;
    this.uniforms.pdeEnabled.value = false;
    this._installed.uninstall();
    this._unlisten();
    this.mesh.frustumCulled = this._originalCulled;
    const geometry = this.mesh.geometry;
    const use = GEOMETRY_USERS.get(geometry); // none when the caller replaced the geometry meanwhile
    if (!use || --use.users === 0) {
      for (const name of PLAYER_ATTRIBUTES) geometry.deleteAttribute(name);
      GEOMETRY_USERS.delete(geometry);
      if (geometry !== this._originalGeometry) {
        geometry.dispose(); // the copy made for this mesh
        this.mesh.geometry = this._originalGeometry;
      }
    } else if (geometry !== this._originalGeometry) {
      this.mesh.geometry = this._originalGeometry;
    }
    this.frames.release();
    this.resources.release();
  }
}

/**
 * For an InstancedMesh with timeOffsets (one number per instance): {offsets (the distinct ones), slot
 * (Float32Array: each instance's index into offsets)}; null without timeOffsets.
 */
function instanceSlots(mesh, timeOffsets) {
  if (timeOffsets === undefined || timeOffsets === null) return null;
  if (!mesh.isInstancedMesh) throw new TypeError('timeOffsets needs an InstancedMesh (one offset per instance)');
  if (timeOffsets.length !== mesh.count || ![...timeOffsets].every(Number.isFinite)) {
    throw new RangeError(`timeOffsets must hold ${mesh.count} finite numbers (one per instance)`);
  }
  const index = new Map();
  const slot = new Float32Array(timeOffsets.length);
  for (let i = 0; i < timeOffsets.length; i++) {
    const o = timeOffsets[i];
    if (!index.has(o)) index.set(o, index.size);
    slot[i] = index.get(o);
  }
  return { offsets: [...index.keys()], slot };
}

/** Play a decoded clip on mesh (see ClipPlayer for the options); returns the player. */
export function attachClip(mesh, clip, options = {}) {
  return new ClipPlayer(mesh, clip, options);
}
