// The mesh-independent state of a clip in three.js: its data textures, the uniforms every mesh playing it
// shares, and its CPU evaluator. One per clip, shared by the meshes of a scene.

import { DataTexture, FloatType, NearestFilter, RGBAFormat } from 'three';
import { createEvaluator } from './clip.js';
import { TEXTURE_WIDTH, gpuLayout, textureBytes, timeUniforms } from './gpu.js';

function dataTexture(t) {
  const tex = new DataTexture(t.data, t.width, t.height, RGBAFormat, FloatType);
  tex.minFilter = NearestFilter;
  tex.magFilter = NearestFilter;
  tex.generateMipmaps = false;
  tex.needsUpdate = true;
  return tex;
}

/**
 * Layout, data textures, shared uniforms and CPU evaluator of a decoded clip. options: renderer (its
 * capabilities.maxTextureSize bounds the textures; else 4096), maxTextureSize, textureWidth (default
 * 4096), tables (gpuTables() made in a Web Worker; default: clip.gpuTables when a worker decoded the clip).
 */
export class ClipResources {
  constructor(clip, { renderer, maxTextureSize, textureWidth, tables } = {}) {
    // the renderer's limit when given (WebGL 2 guarantees only 2048), else 4096
    const limit = maxTextureSize ?? renderer?.capabilities?.maxTextureSize ?? 4096;
    const width = Math.min(textureWidth ?? TEXTURE_WIDTH, limit);
    let made = tables ?? clip.gpuTables ?? null;
    if (made && made.width > width) made = null; // made for wider textures than this renderer takes
    this.clip = clip;
    this.evaluator = createEvaluator(clip, made?.timeIndex ?? null); // the worker's index of time constants
    this.layout = gpuLayout(clip, { width, tables: made, evaluator: this.evaluator });
    /** Why the GPU cannot evaluate this clip (null when it can). */
    this.gpuReason =
      this.layout.maxHeight > limit
        ? `the clip needs a ${this.layout.maxHeight}-row data texture (limit ${limit})`
        : null;
    this.textures = Object.fromEntries(
      Object.entries(this.layout.textures).map(([k, t]) => [k, dataTexture(t)]),
    );
    const L = this.layout;
    /** Uniforms shared by every material playing the clip (time state, textures, constants). */
    this.uniforms = {
      pdeSeg: { value: 0 },
      pdeSinWt: { value: 0 },
      pdeCosWt: { value: 1 },
      pdeVertices: { value: L.nVertices },
      pdeVertexTex: { value: this.textures.vertex },
      pdeFrameTex: { value: this.textures.frame ?? null },
      pdeRingTex: { value: this.textures.ring ?? null }, // the area-weighted normals' one-rings
      pdeDirect: { value: L.nDirect ?? 0 },
      // clips with bones: the per-frame table's first bone row, the first skin-only vertex and its texel
      pdeBones: { value: L.boneTexel ?? 0 },
      pdeSkinOnly: { value: L.skinOnly ?? 0 },
      pdeSkinTexel: { value: L.skinTexel ?? 0 },
      pdeAxis: { value: L.axis ? [...L.axis] : [1, 0, 0] },
      pdeBend: { value: L.bend ? [...L.bend] : [0, 1, 0] },
      pdeRotate: { value: Boolean(L.rotate) },
    };
    /** Bumped whenever the clip's state on the GPU changes (an evaluation pass reruns then). */
    this.version = 0;
    this.users = 0;
    /** Backend extras (the WebGL evaluation pass), created on first use. */
    this.extras = {};
    this._lastT = null;
  }

  /** Bytes of the data textures (GPU memory of the clip, whatever the meshes). */
  get textureBytes() {
    return textureBytes(this.layout);
  }

  /**
   * Move the shared GPU state to t: uniforms, and the per-curve table rewritten and marked for upload only
   * when t moved to another segment or local time (once per distinct t for all meshes).
   */
  frame(t) {
    if (t === this._lastT) return;
    const u = timeUniforms(this.layout, t);
    this._lastT = t;
    this.uniforms.pdeSeg.value = u.seg;
    this.uniforms.pdeSinWt.value = u.sw;
    this.uniforms.pdeCosWt.value = u.cw;
    if (u.changed) {
      this.version++;
      if (this.textures.frame) this.textures.frame.needsUpdate = true;
    }
  }

  dispose() {
    for (const tex of Object.values(this.textures)) tex.dispose();
    for (const extra of Object.values(this.extras)) extra.dispose();
    this.extras = {};
  }
}
