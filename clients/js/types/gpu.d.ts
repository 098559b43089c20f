// Type declarations of pdeanim/gpu: data for evaluating a clip in a vertex shader (no three.js needed).

import type { Clip, Evaluator } from './index.js';

export declare const TEXTURE_WIDTH: number;

export interface FloatTexture {
  /** RGBA float32 texels, width * height * 4 values. */
  data: Float32Array;
  width: number;
  height: number;
}

export interface GpuLayout {
  kind: Clip['kind'];
  rigid: boolean;
  /**
   * Whether some item is on the natural spline (docs/format.md §3.5): the curve table then holds four weight
   * texels per curve instead of the pair, on T_s, P_s, P_s+1, T_s+1, and textures.tangent holds the tangents
   * T (the pdeTangentTex uniform).
   */
  spline: boolean;
  nCurves: number;
  nVertices: number;
  /** Segments S of a dynamic clip (0 for cyclic ones). */
  nSegments: number;
  /** Texture row length in texels (a power of two). */
  width: number;
  /**
   * Texels per curve in the per-frame curve table: the weights (2: phi0, phi1; 4 with spline items), then 3
   * rows of the rigid motion (so 2, 5, 4 or 7).
   */
  curveTexels?: number;
  /** Weight texels per curve at the start of its table entry (2, or 4 with spline items). */
  weightTexels?: number;
  textures: {
    /** Per vertex (curve, base xyz) and its orthonormal basis row per coordinate (dynamic clips). */
    vertex: FloatTexture;
    /** Per (knot, curve, coordinate) the knots in the curve's orthonormal basis. */
    knot?: FloatTexture;
    /** Natural-spline tangents of every knot's coefficients (clips with spline items), in the layout of knot. */
    tangent?: FloatTexture;
    /** Per-frame table rewritten by timeUniforms(). */
    curve?: FloatTexture;
  };
  /** The clip (gpuLayout; absent in gpuTables). */
  clip?: Clip;
  /** The CPU evaluator whose per-curve state fills the curve table (dynamic clips; gpuLayout). */
  evaluator?: Evaluator;
  /** Largest texture height (compare with the renderer's MAX_TEXTURE_SIZE). */
  maxHeight: number;
  axis?: number[];
  bend?: number[];
  rotate?: boolean;
}

export interface TimeUniforms {
  /** Segment of the dynamic clip at t. */
  seg: number;
  /** sin and cos of the swim phase (cyclic clips). */
  sw: number;
  cw: number;
  /** Whether the curve table was rewritten (false when t maps to the same segment and local time as the
   * previous call): upload it only then. */
  changed: boolean;
}

export interface MeshAttributes {
  /** Per mesh vertex: clip vertex of itself and of two triangle neighbours (n * 3). */
  pdeVertex: Float32Array;
  /** Per mesh vertex: its normal in the rest frame of that triangle (n * 3). */
  pdeNormalFrame: Float32Array;
}

/** The data textures and constants of a clip as plain typed arrays (a Web Worker can make and transfer them). */
export declare function gpuTables(clip: Clip, options?: { width?: number }): GpuLayout;
/** gpuTables (or the given tables) with the clip and its CPU evaluator: what timeUniforms() needs. */
export declare function gpuLayout(
  clip: Clip,
  options?: { width?: number; tables?: GpuLayout | null; evaluator?: Evaluator | null },
): GpuLayout;
/** Bytes of the data textures. */
export declare function textureBytes(tables: GpuLayout): number;
/** The uniforms at t; also rewrites layout.textures.curve.data when it changes (upload it then). */
export declare function timeUniforms(layout: GpuLayout, t: number): TimeUniforms;
export declare function meshAttributes(mesh: {
  vertexMap: ArrayLike<number>;
  positions: ArrayLike<number>;
  normals?: ArrayLike<number> | null;
  index?: ArrayLike<number> | null;
}): MeshAttributes;
export declare function frameNormals(
  clipPositions: ArrayLike<number>,
  attributes: MeshAttributes,
  restNormals: ArrayLike<number> | null,
  out: Float32Array,
): Float32Array;
/** GLSL ES 3.00 declarations and functions (pdeCompute() sets pdePosition and pdeNormal). */
export declare function glslHeader(
  layout: GpuLayout,
  options?: { normals?: 'frame' | 'rest'; stage?: 'vertex' | 'fragment'; pass?: boolean; cpu?: boolean },
): string;
/** A built-in material's vertex shader with the clip evaluation patched in (mixed by pdeInfluence). */
export declare function patchVertexShader(vertexShader: string, header: string): string;
export declare function glslPassMain(): string;
