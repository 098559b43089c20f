// ScenePlayer: one clip played on every mesh under a root (e.g. the user's own glTF scene from GLTFLoader, or
// a GLB that pdeanim wrote), keeping materials, textures, UVs and the node hierarchy.

import { ClipPlayer, MAP_ATTRIBUTES, PLAYER_OPTIONS, checkOptions } from './player.js';
import { ClipResources, FrameTables } from './resources.js';
import { webglBackend } from './webgl.js';

const SCENE_OPTIONS = Object.freeze([
  ...PLAYER_OPTIONS.filter((k) => !['vertexMap', 'clipToLocal', 'resources', 'frames', 'timeOffsets'].includes(k)),
  'filter',
]);

/**
 * Play a clip on every mesh under root: meshes in depth-first order take consecutive ranges of the clip's
 * vertices (the order pdeanim reads a glTF's primitives in, and writes unwelded GLBs in) or, where every mesh
 * carries one, the clip vertices of their _pdeanim_vertex attributes (pdeanim's welded GLBs); each is placed
 * with its transform relative to root, so that the clip's coordinates are root's. Skinned meshes play the clip in
 * place of their skinning (mixed by influence); meshes sharing one geometry get their own copy of it.
 * options: as ClipPlayer's (without vertexMap, clipToLocal, resources, frames, timeOffsets), plus
 * filter(mesh) to skip meshes. Scene players of one clip share its data texture (ClipResources.acquire);
 * each has its own time for its meshes (one per-frame table, or in the clip's crowd form one time row).
 */
export class ScenePlayer {
  constructor(root, clip, options = {}, backend = webglBackend) {
    checkOptions(options, SCENE_OPTIONS, 'ScenePlayer');
    const { filter, ...rest } = options;
    root.updateMatrixWorld(true);
    const rootInverse = root.matrixWorld.clone().invert();
    const meshes = [];
    root.traverse((o) => {
      if (o.isMesh && o.geometry?.getAttribute('position') && (!filter || filter(o))) meshes.push(o);
    });
    const mapped = meshes.filter((m) => MAP_ATTRIBUTES.some((n) => m.geometry.getAttribute(n)));
    if (mapped.length && mapped.length !== meshes.length) {
      throw new Error(
        `${mapped.length} of the ${meshes.length} meshes under root carry a _pdeanim_vertex map: all or none must`,
      );
    }
    const total = meshes.reduce((n, m) => n + m.geometry.getAttribute('position').count, 0);
    if (!mapped.length && total !== clip.nVertices) {
      throw new Error(`the meshes under root have ${total} vertices in all and the clip ${clip.nVertices}`);
    }
    this.root = root;
    this.clip = clip;
    this._options = { ...options };
    this.resources = ClipResources.acquire(clip, rest);
    this.frames = new FrameTables(this.resources, { crowd: backend.crowd === true }).retain();
    const shared = { resources: this.resources, frames: this.frames };
    const seen = new Set();
    let offset = 0;
    this.players = meshes.map((mesh) => {
      if (seen.has(mesh.geometry)) mesh.geometry = mesh.geometry.clone(); // its attributes are per mesh
      seen.add(mesh.geometry);
      const n = mesh.geometry.getAttribute('position').count;
      // a welded GLB maps its vertices to the clip's (_pdeanim_vertex); else meshes take consecutive ranges
      const vertexMap = mapped.length ? undefined : Int32Array.from({ length: n }, (_, i) => offset + i);
      offset += n;
      const clipToLocal = rootInverse.clone().multiply(mesh.matrixWorld).invert();
      return new ClipPlayer(mesh, clip, { ...rest, vertexMap, clipToLocal, ...shared }, backend);
    });
    this.backend = backend;
    this._positions = new Float32Array(clip.nVertices * 3);
    this._time = 0;
  }

  get evaluator() {
    return this.resources.evaluator;
  }

  /** Why the GPU path is unavailable (null when it is available). */
  get gpuUnavailableReason() {
    return this.resources.gpuReason;
  }

  get gpu() {
    return this.players.every((p) => p.gpu);
  }

  get time() {
    return this._time;
  }

  get influence() {
    return this.players[0]?.influence ?? 1;
  }

  set influence(w) {
    for (const p of this.players) p.influence = w;
  }

  /** Show normalised time t on every mesh (one CPU evaluation shared by all on the CPU path). */
  setTime(t) {
    if (this.clip.windowed && !this.clip.setPlayhead(t)) return this; // window not decoded yet (stream.js)
    const cpu = this.players.some((p) => !p.gpu);
    if (cpu) this.resources.evaluator.evaluate(t, this._positions);
    for (const p of this.players) p.setTime(t, cpu ? this._positions : null);
    this._time = t;
    return this;
  }

  useGPU(on) {
    for (const p of this.players) p.useGPU(on);
    this.setTime(this._time);
    return this.gpu;
  }

  positions(t, out = new Float32Array(this.clip.nVertices * 3)) {
    return this.resources.evaluator.evaluate(t, out);
  }

  /**
   * Bytes on the GPU for the clip: its shared data texture, this player's per-frame table and evaluation
   * pass, and every mesh's attributes (counted here even where a clone's player shares them).
   */
  get gpuBytes() {
    const attributes = this.players.reduce((n, p) => n + p.attributeBytes, 0);
    return this.resources.sharedBytes + this.frames.bytes + attributes;
  }

  /**
   * A new player on a clone of root (root.clone(), with the meshes' own materials) with this player's
   * options: its own time, uniforms and patched materials, sharing the clip's data texture and, while both
   * play, the meshes' attributes. Add its root to a scene.
   */
  clone() {
    const root = this.root.clone();
    const copies = [];
    root.traverse((o) => copies.push(o));
    const originals = [];
    this.root.traverse((o) => originals.push(o));
    for (const p of this.players) {
      const copy = copies[originals.indexOf(p.mesh)];
      p._installed.restoreOn(copy);
      copy.frustumCulled = p._originalCulled;
    }
    const player = new ScenePlayer(root, this.clip, { ...this._options, influence: this.influence }, this.backend);
    player.setTime(this._time);
    return player;
  }

  detach() {
    if (!this.frames) return;
    for (const p of this.players) p.detach();
    this.frames.release();
    this.resources.release();
    this.frames = null;
  }
}

/** Play a clip on every mesh under root (see ScenePlayer); returns the player. */
export function attachClipToScene(root, clip, options = {}) {
  return new ScenePlayer(root, clip, options);
}
