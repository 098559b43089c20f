// The GPU state of a clip in three.js. ClipResources: what does not depend on time (the vertex data texture,
// constant uniforms, the CPU evaluator), one per clip (and texture width) whatever the number of players,
// reference-counted and freed with its last player. FrameTables: the per-frame table at one player's time
// (or, for an instanced crowd, one table per distinct time offset in one texture).

import { DataTexture, FloatType, NearestFilter, RGBAFormat } from 'three';
import { createEvaluator } from './clip.js';
import { TEXTURE_WIDTH, frameTexels, frameView, gpuLayout, timeUniforms } from './gpu.js';

function dataTexture(t) {
  const tex = new DataTexture(t.data, t.width, t.height, RGBAFormat, FloatType);
  tex.minFilter = NearestFilter;
  tex.magFilter = NearestFilter;
  tex.generateMipmaps = false;
  tex.needsUpdate = true;
  return tex;
}

/** The shared resources of each clip object, by texture width and limit (freed with their last user). */
const CACHE = new WeakMap();

/**
 * Layout, vertex data texture, constant uniforms and CPU evaluator of a decoded clip. options: renderer (its
 * capabilities.maxTextureSize bounds the textures; else 4096), maxTextureSize, textureWidth (default
 * 4096), tables (gpuTables() made in a Web Worker; default: clip.gpuTables when a worker decoded the clip).
 * ClipResources.acquire(clip, options) returns the clip's shared instance; players retain() and release().
 */
export class ClipResources {
  constructor(clip, { renderer, maxTextureSize, textureWidth, tables } = {}) {
    // the renderer's limit when given (WebGL 2 guarantees only 2048), else 4096
    const limit = maxTextureSize ?? renderer?.capabilities?.maxTextureSize ?? 4096;
    const width = Math.min(textureWidth ?? TEXTURE_WIDTH, limit);
    let made = tables ?? clip.gpuTables ?? null;
    if (made && made.width > width) made = null; // made for wider textures than this renderer takes
    this.clip = clip;
    this.limit = limit;
    this.evaluator = createEvaluator(clip, made?.timeIndex ?? null); // the worker's index of time constants
    this.layout = gpuLayout(clip, { width, tables: made, evaluator: this.evaluator });
    /** Why the GPU cannot evaluate this clip (null when it can). */
    this.gpuReason =
      this.layout.maxHeight > limit
        ? `the clip needs a ${this.layout.maxHeight}-row data texture (limit ${limit})`
        : null;
    /** The shared data textures: vertex records and normal rings (the per-frame tables are the players', FrameTables). */
    this.textures = { vertex: dataTexture(this.layout.textures.vertex) };
    if (this.layout.textures.ring) this.textures.ring = dataTexture(this.layout.textures.ring);
    const L = this.layout;
    /** Uniforms shared by every material playing the clip (vertex texture, constants). */
    this.uniforms = {
      pdeVertices: { value: L.nVertices },
      pdeVertexTex: { value: this.textures.vertex },
      pdeRingTex: { value: this.textures.ring ?? null }, // the area-weighted normals' one-rings (shared)
      pdeDirect: { value: L.nDirect ?? 0 },
      // clips with bones: the per-frame table's first bone row, the first skin-only vertex and its texel
      pdeBones: { value: L.boneTexel ?? 0 },
      pdeSkinOnly: { value: L.skinOnly ?? 0 },
      pdeSkinTexel: { value: L.skinTexel ?? 0 },
      pdeAxis: { value: L.axis ? [...L.axis] : [1, 0, 0] },
      pdeBend: { value: L.bend ? [...L.bend] : [0, 1, 0] },
      pdeRotate: { value: Boolean(L.rotate) },
    };
    this.users = 0;
    this._key = null;
  }

  /** The clip's shared resources for these options (made on first use), retained for the caller. */
  static acquire(clip, options = {}) {
    const limit = options.maxTextureSize ?? options.renderer?.capabilities?.maxTextureSize ?? 4096;
    const key = `${Math.min(options.textureWidth ?? TEXTURE_WIDTH, limit)}:${limit}`;
    if (!CACHE.has(clip)) CACHE.set(clip, new Map());
    const byKey = CACHE.get(clip);
    let res = byKey.get(key);
    if (!res) {
      res = new ClipResources(clip, options);
      res._key = key;
      byKey.set(key, res);
    }
    return res.retain();
  }

  retain() {
    this.users++;
    return this;
  }

  /** Drop a user; the last one frees the textures (and the cache entry). */
  release() {
    if (--this.users > 0) return;
    this.dispose();
    if (this._key !== null && CACHE.get(this.clip)?.get(this._key) === this) CACHE.get(this.clip).delete(this._key);
  }

  /** Bytes of the shared data textures (counted once per clip, whatever the players). */
  get sharedBytes() {
    return this.layout.textures.vertex.data.byteLength + (this.layout.textures.ring?.data.byteLength ?? 0);
  }

  /** Bytes of the clip's data textures for one player: the shared texture and one per-frame table. */
  get textureBytes() {
    return this.sharedBytes + (this.layout.textures.frame?.data.byteLength ?? 0);
  }

  dispose() {
    for (const tex of Object.values(this.textures)) tex.dispose();
  }
}

/**
 * The per-frame table(s) of a clip at a player's time, with their uniforms. offsets (optional): time offsets
 * of the slots of an instanced crowd (one table per distinct offset, in one texture: slot k shows t +
 * offsets[k], wrapped for looping clips, clamped to [0, 1] for the others). Shared by the meshes of a scene
 * (retain/release); the evaluation pass, when a player uses one, is made here (pass) as it shows this time.
 */
export class FrameTables {
  constructor(resources, { offsets = null } = {}) {
    const L = resources.layout;
    this.resources = resources;
    this.offsets = offsets ? Float64Array.from(offsets) : Float64Array.of(0);
    this.slots = offsets !== null;
    this.stride = frameTexels(L);
    const cyclic = L.kind === 'cyclic-spine';
    this.texture = null;
    this.views = [];
    if (!cyclic || this.slots) {
      const texels = this.stride * this.offsets.length;
      const height = Math.max(1, Math.ceil(texels / L.width));
      if (height > resources.limit) {
        throw new RangeError(
          `${this.offsets.length} distinct time offsets need a ${height}-row table (limit ${resources.limit})`,
        );
      }
      const data = new Float32Array(L.width * height * 4);
      this.texture = dataTexture({ data, width: L.width, height });
      const n = this.stride * 4;
      if (!cyclic) this.views = [...this.offsets].map((_, k) => frameView(L, data.subarray(k * n, (k + 1) * n)));
    }
    this.uniforms = {
      pdeSeg: { value: 0 },
      pdeSinWt: { value: 0 },
      pdeCosWt: { value: 1 },
      pdeFrameTex: { value: this.texture },
      pdeSlotTexels: { value: this.stride },
    };
    /** Bumped whenever the tables change (an evaluation pass reruns then). */
    this.version = 0;
    this.users = 0;
    this.pass = null;
    this._lastT = null;
  }

  retain() {
    this.users++;
    return this;
  }

  release() {
    if (--this.users === 0) this.dispose();
  }

  /** Bytes of the table texture and of the evaluation pass's texture (what this time costs on the GPU). */
  get bytes() {
    return (this.texture?.image.data.byteLength ?? 0) + (this.pass?.bytes ?? 0);
  }

  /** Show normalised time t (slots: t + their offsets); a table is rewritten only when its state moved. */
  frame(t) {
    if (t === this._lastT) return;
    const L = this.resources.layout;
    const looping = L.clip.looping || L.kind === 'cyclic-spine';
    let changed = false;
    for (let k = 0; k < this.offsets.length; k++) {
      let tk = t + this.offsets[k];
      if (this.slots && !looping) tk = Math.min(Math.max(tk, 0), 1);
      const u = timeUniforms(this.views[k] ?? L, tk);
      if (k === 0) {
        this.uniforms.pdeSeg.value = u.seg;
        this.uniforms.pdeSinWt.value = u.sw;
        this.uniforms.pdeCosWt.value = u.cw;
      }
      if (this.slots && L.kind === 'cyclic-spine') {
        this.texture.image.data[k * 4] = u.sw;
        this.texture.image.data[k * 4 + 1] = u.cw;
      }
      changed ||= u.changed;
    }
    this._lastT = t;
    if (changed) {
      this.version++;
      if (this.texture) this.texture.needsUpdate = true;
    }
  }

  /** Forget the time shown (the next frame() writes the tables again). */
  invalidate() {
    this._lastT = null;
    for (const v of this.views) v.tableAt[0] = -1;
  }

  dispose() {
    this.texture?.dispose();
    this.pass?.dispose();
    this.pass = null;
  }
}
