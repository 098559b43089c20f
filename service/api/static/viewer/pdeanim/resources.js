// The GPU state of a clip in three.js. ClipResources: what does not depend on time (the vertex data texture,
// constant uniforms, the CPU evaluator), one per clip (and texture width) whatever the number of players,
// reference-counted and freed with its last player. FrameTables: the clip at one player's time (or, for an
// instanced crowd, at each distinct time offset). One player alone has a per-frame table (every curve's
// coefficients at its time, evaluated on the CPU); once players show distinct times (a second FrameTables,
// or an instanced crowd) and the crowd form takes at most twice the GPU bytes of a table per time (crowdForm), the
// clip turns into its crowd form: one shared knot table (gpu.js knotTables) and per time a row of a few
// texels (segment, time pairs: gpu.js crowdRow) in one shared texture, the atlas.

import { DataTexture, FloatType, NearestFilter, RGBAFormat } from 'three';
import { createEvaluator } from './clip.js';
import {
  TEXTURE_WIDTH,
  crowdRow,
  frameTexels,
  frameView,
  gpuLayout,
  knotTablePlan,
  knotTables,
  timeRow,
  timeUniforms,
} from './gpu.js';

function dataTexture(t) {
  const tex = new DataTexture(t.data, t.width, t.height, RGBAFormat, FloatType);
  tex.minFilter = NearestFilter;
  tex.magFilter = NearestFilter;
  tex.generateMipmaps = false;
  tex.needsUpdate = true;
  return tex;
}

/** crowdForm: the most bytes of the crowd form per byte of per-frame tables (ClipResources.crowdPays). */
const CROWD_BYTES_RATIO = { auto: 2, bytes: 1, always: Infinity, never: 0 };
export const CROWD_FORMS = Object.freeze(Object.keys(CROWD_BYTES_RATIO));

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
      // the crowd form's (set by toCrowd)
      pdeKnotTex: { value: null },
      pdeKnotCurves: { value: 0 },
      pdeKnotTangents: { value: 0 },
      pdeMuTexel: { value: 0 },
      pdeTimeTexel: { value: 0 },
      pdeRigidTexel: { value: 0 },
      pdeRigidKnots: { value: 0 },
      pdeRigidMu: { value: 0 },
      pdeDirectTexel: { value: 0 },
    };
    this.users = 0;
    this._key = null;
    /** The per-time tables made on these resources (FrameTables register and unregister). */
    this.tables = new Set();
    /** The crowd form once players show distinct times: {table, texture, row, atlas}; null before. */
    this.crowd = null;
    this._crowdReason = undefined;
    /**
     * When players at distinct times take the crowd form (crowdPays): 'auto' (the default: unless the knot
     * table and a time row per time take more than twice the GPU bytes of a per-frame table per time; the
     * tables cost the CPU every curve's coefficients per player and frame, the rows a few numbers), 'bytes'
     * (only where it takes fewer bytes), 'always' (from the second time on) or 'never'. Set it before the
     * players are made (the form is kept once taken).
     */
    this.crowdForm = 'auto';
  }

  /** Why the clip cannot take its crowd form (null when it can): cyclic or streaming clips, no GPU, too large a table. */
  get crowdReason() {
    if (this._crowdReason !== undefined) return this._crowdReason;
    const L = this.layout;
    if (this.gpuReason) this._crowdReason = this.gpuReason;
    else if (L.kind === 'cyclic-spine') this._crowdReason = 'cyclic clips keep their per-player uniforms';
    else if (L.clip.windowed) this._crowdReason = 'a streaming clip keeps per-player tables (its knots come by window)';
    else {
      const plan = this.knotPlan;
      this._crowdReason =
        plan.height > this.limit ? `the clip's knot table needs ${plan.height} rows (limit ${this.limit})` : null;
    }
    return this._crowdReason;
  }

  /** The size of the crowd form's knot table (gpu.js knotTablePlan; made on first use, no values written). */
  get knotPlan() {
    this._knotPlan ??= knotTablePlan(this.layout, this.limit);
    return this._knotPlan;
  }

  /**
   * GPU bytes of the times registered (FrameTables, with `adding` more slots of a table being made) in each
   * form: {crowd: the knot table and an atlas with a row per slot, tables: a per-frame table (and evaluation
   * pass) per time}; null when the clip cannot take the crowd form.
   */
  formBytes(adding = 0) {
    if (this.crowdReason !== null) return null;
    const L = this.layout;
    const stride = frameTexels(L);
    const tableBytes = (k) => L.width * Math.max(1, Math.ceil((stride * k) / L.width)) * 16;
    let slots = adding;
    let tables = adding > 0 ? tableBytes(adding) : 0;
    for (const t of this.tables) {
      if (!t.crowdCapable || t.cyclic) continue;
      slots += t.offsets.length;
      tables += t.crowd ? tableBytes(t.offsets.length) : t.bytes;
    }
    const row = (this._row ??= crowdRow(L));
    let capacity = 4;
    while (capacity < slots) capacity *= 2;
    const atlas = L.width * Math.ceil((capacity * row.texels) / L.width) * 16;
    return { crowd: this.knotPlan.bytes + atlas, tables };
  }

  /** Whether the crowd form pays for the times registered (plus `adding` slots), by crowdForm. */
  crowdPays(adding = 0) {
    const ratio = CROWD_BYTES_RATIO[this.crowdForm];
    if (ratio === undefined) throw new RangeError(`crowdForm must be ${CROWD_FORMS.join(', ')}; got ${this.crowdForm}`);
    if (ratio === 0) return false;
    if (ratio === Infinity) return this.crowdReason === null;
    const b = this.formBytes(adding);
    return b !== null && b.crowd <= ratio * b.tables;
  }

  /**
   * Take the crowd form (once; the tables registered so far switch to it): the shared knot table and the
   * atlas of time rows. Returns whether the clip is in it.
   */
  toCrowd() {
    if (this.crowd) return true;
    if (this.crowdReason !== null) return false;
    const table = knotTables(this.layout, this.limit);
    const row = (this._row ??= crowdRow(this.layout));
    this.crowd = { table, texture: dataTexture(table), row, atlas: { slots: [], data: null, texture: null } };
    const u = this.uniforms;
    u.pdeKnotTex.value = this.crowd.texture;
    u.pdeKnotCurves.value = table.curves;
    u.pdeKnotTangents.value = table.tangentTexel;
    u.pdeMuTexel.value = table.muTexel;
    u.pdeTimeTexel.value = row.timeTexel;
    u.pdeRigidTexel.value = row.rigidTexel;
    u.pdeRigidKnots.value = table.rigidKnotTexel;
    u.pdeRigidMu.value = table.rigidMuTexel;
    u.pdeDirectTexel.value = table.directTexel;
    this._growAtlas(this.tables.size);
    for (const t of [...this.tables]) t._toCrowd();
    return true;
  }

  /** The atlas with room for `slots` time rows (doubling; rows of the layout's width); adding: the rows asked for. */
  _growAtlas(slots, adding = slots) {
    const { atlas, row } = this.crowd;
    const width = this.layout.width;
    let capacity = Math.max(4, atlas.slots.length);
    while (capacity < slots) capacity *= 2;
    // the last doubling may not fit where the rows needed do
    const rows = (n) => Math.ceil((n * row.texels) / width);
    if (rows(capacity) > this.limit) capacity = Math.max(slots, Math.floor((this.limit * width) / row.texels));
    const height = rows(capacity);
    if (height > this.limit) {
      throw new RangeError(
        `${adding} distinct time offsets need a ${rows(slots)}-row table with the clip's other players' ` +
          `${slots - adding} (limit ${this.limit})`,
      );
    }
    if (capacity === atlas.slots.length && atlas.texture) return;
    const data = new Float32Array(width * height * 4);
    if (atlas.data) data.set(atlas.data);
    const old = atlas.texture;
    atlas.data = data;
    atlas.texture = dataTexture({ data, width, height });
    while (atlas.slots.length < capacity) atlas.slots.push(null);
    for (const t of this.tables) if (t.crowd) t.uniforms.pdeFrameTex.value = atlas.texture;
    old?.dispose();
  }

  /** count consecutive free time rows of the atlas for owner; returns the first. */
  _allocate(owner, count) {
    const { atlas } = this.crowd;
    for (;;) {
      for (let i = 0, run = 0; i < atlas.slots.length; i++) {
        run = atlas.slots[i] === null ? run + 1 : 0;
        if (run === count) {
          const first = i - count + 1;
          atlas.slots.fill(owner, first, i + 1);
          return first;
        }
      }
      this._growAtlas(atlas.slots.filter((o) => o !== null).length + count, count);
    }
  }

  /** Free the time rows of owner. */
  _free(owner) {
    const { slots } = this.crowd.atlas;
    for (let i = 0; i < slots.length; i++) if (slots[i] === owner) slots[i] = null;
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

  /**
   * Bytes of the shared data textures (counted once per clip, whatever the players): the vertex records, the
   * normal rings and, in the crowd form, the knot table.
   */
  get sharedBytes() {
    const knots = this.crowd ? this.crowd.table.data.byteLength : 0;
    return this.layout.textures.vertex.data.byteLength + (this.layout.textures.ring?.data.byteLength ?? 0) + knots;
  }

  /** Bytes of the crowd form's atlas of time rows (all of it, free rows included; 0 before the crowd form). */
  get atlasBytes() {
    return this.crowd ? this.crowd.atlas.data.byteLength : 0;
  }

  /** Bytes of the clip's data textures for one player: the shared textures and one per-frame table (or time row). */
  get textureBytes() {
    if (this.crowd) return this.sharedBytes + this.crowd.row.texels * 16;
    return this.sharedBytes + (this.layout.textures.frame?.data.byteLength ?? 0);
  }

  dispose() {
    for (const tex of Object.values(this.textures)) tex.dispose();
    this.crowd?.texture.dispose();
    this.crowd?.atlas.texture?.dispose();
    this.crowd = null;
  }
}

/**
 * A clip at a player's time, with its uniforms. offsets (optional): time offsets of the slots of an instanced
 * crowd (slot k shows t + offsets[k], wrapped for looping clips, clamped to [0, 1] for the others). Shared by
 * the meshes of a scene (retain/release). Two forms: a per-frame table of every curve's coefficients (one
 * player alone; the evaluation pass, when a player uses one, is made here, as it shows this time), or, in
 * the clip's crowd form (ClipResources.toCrowd: when a second FrameTables of the clip is made, or offsets are
 * given), a time row per slot in the clip's shared atlas. crowd: false keeps the per-frame table (a backend
 * whose shaders do not read the crowd form). onChange(fn): fn() runs when the form changes (the players
 * recompile their materials).
 */
export class FrameTables {
  constructor(resources, { offsets = null, crowd = true } = {}) {
    const L = resources.layout;
    this.resources = resources;
    this.offsets = offsets ? Float64Array.from(offsets) : Float64Array.of(0);
    this.slots = offsets !== null;
    this.stride = frameTexels(L);
    this.cyclic = L.kind === 'cyclic-spine';
    this.crowd = false;
    /** Whether the players' backend reads the crowd form (else this keeps its per-frame table). */
    this.crowdCapable = crowd;
    this._texture = null;
    this.views = [];
    this.uniforms = {
      pdeSeg: { value: 0 },
      pdeSinWt: { value: 0 },
      pdeCosWt: { value: 1 },
      pdeFrameTex: { value: null },
      pdeSlotTexels: { value: this.stride },
      pdeFrameOffset: { value: 0 },
      pdeBones: { value: L.boneTexel ?? 0 },
    };
    /** Bumped whenever the tables change (an evaluation pass reruns then). */
    this.version = 0;
    this.users = 0;
    this.pass = null;
    this._lastT = null;
    this._listeners = new Set();
    this.first = -1; // the crowd form's first atlas row
    try {
      const others = [...resources.tables].filter((x) => x.crowdCapable).length;
      // distinct times (an instanced crowd, or a second table) take the crowd form where it pays (crowdForm)
      const crowd =
        this.crowdCapable &&
        !this.cyclic &&
        (resources.crowd !== null || ((this.slots || others >= 1) && resources.crowdPays(this.offsets.length)));
      resources.tables.add(this);
      // (toCrowd switches every registered table, this one included)
      if (crowd && resources.toCrowd()) this._toCrowd();
      else this._ownTable();
    } catch (e) {
      resources.tables.delete(this);
      if (this.crowd) resources._free(this);
      throw e;
    }
  }

  /** The per-frame table of one player alone (every curve's coefficients; cyclic: a slot's sine and cosine). */
  _ownTable() {
    const L = this.resources.layout;
    if (this.cyclic && !this.slots) return;
    const texels = this.stride * this.offsets.length;
    const height = Math.max(1, Math.ceil(texels / L.width));
    if (height > this.resources.limit) {
      throw new RangeError(
        `${this.offsets.length} distinct time offsets need a ${height}-row table (limit ${this.resources.limit})`,
      );
    }
    const data = new Float32Array(L.width * height * 4);
    this._texture = dataTexture({ data, width: L.width, height });
    this.uniforms.pdeFrameTex.value = this._texture;
    const n = this.stride * 4;
    if (!this.cyclic) this.views = [...this.offsets].map((_, k) => frameView(L, data.subarray(k * n, (k + 1) * n)));
  }

  /** Move to the clip's crowd form (ClipResources.toCrowd): time rows in the shared atlas. */
  _toCrowd() {
    if (this.crowd || !this.crowdCapable || this.cyclic) return;
    const res = this.resources;
    const L = res.layout;
    this.first = res._allocate(this, this.offsets.length);
    this.crowd = true;
    this._texture?.dispose();
    this._texture = null;
    this.pass?.dispose();
    this.pass = null;
    // a view per slot: its own record of the time written (the CPU evaluator and knot rows are shared)
    this.views = [...this.offsets].map(() => frameView(L));
    const { row, atlas } = res.crowd;
    Object.assign(this, { row });
    this.uniforms.pdeFrameTex.value = atlas.texture;
    this.uniforms.pdeSlotTexels.value = row.texels;
    this.uniforms.pdeFrameOffset.value = this.first * row.texels;
    this.uniforms.pdeBones.value = row.boneTexel;
    const t = this._lastT;
    this._lastT = null;
    if (t !== null) this.frame(t);
    this.version++;
    for (const fn of [...this._listeners]) fn();
  }

  /** The texture the shaders read: this table, or in the crowd form the clip's atlas (null: cyclic, one player). */
  get texture() {
    return this.crowd ? (this.resources.crowd?.atlas.texture ?? null) : this._texture;
  }

  /** Run fn() when the form changes (returns a function that stops it). */
  onChange(fn) {
    this._listeners.add(fn);
    return () => this._listeners.delete(fn);
  }

  retain() {
    this.users++;
    return this;
  }

  release() {
    if (--this.users === 0) this.dispose();
  }

  /**
   * Bytes this time costs on the GPU: the per-frame table and the evaluation pass's texture, or in the crowd
   * form this table's time rows in the atlas.
   */
  get bytes() {
    if (this.crowd) return this.offsets.length * this.row.texels * 16;
    return (this._texture?.image.data.byteLength ?? 0) + (this.pass?.bytes ?? 0);
  }

  /** Show normalised time t (slots: t + their offsets); a table is rewritten only when its state moved. */
  frame(t) {
    if (t === this._lastT) return;
    const L = this.resources.layout;
    const looping = L.clip.looping || this.cyclic;
    let changed = false;
    const atlas = this.crowd ? (this.resources.crowd?.atlas ?? null) : null;
    if (this.crowd && atlas === null) return; // the clip's resources were freed (its players detached)
    for (let k = 0; k < this.offsets.length; k++) {
      let tk = t + this.offsets[k];
      if (this.slots && !looping) tk = Math.min(Math.max(tk, 0), 1);
      if (atlas !== null) {
        changed = timeRow(this.views[k], tk, this.row, atlas.data, (this.first + k) * this.row.texels * 4) || changed;
        continue;
      }
      const u = timeUniforms(this.views[k] ?? L, tk);
      if (k === 0) {
        this.uniforms.pdeSeg.value = u.seg;
        this.uniforms.pdeSinWt.value = u.sw;
        this.uniforms.pdeCosWt.value = u.cw;
      }
      if (this.slots && this.cyclic) {
        this._texture.image.data[k * 4] = u.sw;
        this._texture.image.data[k * 4 + 1] = u.cw;
      }
      changed ||= u.changed;
    }
    this._lastT = t;
    if (changed) {
      this.version++;
      if (atlas !== null) atlas.texture.needsUpdate = true;
      else if (this._texture) this._texture.needsUpdate = true;
    }
  }

  /** Forget the time shown (the next frame() writes the tables again). */
  invalidate() {
    this._lastT = null;
    for (const v of this.views) v.tableAt[0] = -1;
  }

  dispose() {
    this._texture?.dispose();
    this._texture = null;
    this.pass?.dispose();
    this.pass = null;
    if (this.crowd && this.resources.crowd) this.resources._free(this);
    this.resources.tables.delete(this);
    this._listeners.clear();
  }
}
