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
   * Whether some item is on the natural spline (docs/format.md §3.5): tangents then holds the spline's
   * tangents of every knot in the orthonormal bases (the CPU applies them; the shader is the same).
   */
  spline: boolean;
  /** Whether the clip has a bone layer: the shader skins the rest pose with the bone rows of the frame table. */
  bones?: boolean;
  /** false for a bone clip whose curves are all 0: no residual tables (no basis rows, curve texels, direct vertices). */
  residual?: boolean;
  /**
   * Bone clips: the GPU number of the first skin-only vertex (those of curves whose knots are all 0, numbered
   * last: 3 texels each, no residual tables); the clip's vertex count when every curve has a residual.
   */
  skinOnly?: number;
  /** Vertex-texture texel of the first skin-only vertex. */
  skinTexel?: number;
  /** Bones B (0 without bones). */
  nBones?: number;
  /** Texels per GPU vertex with a residual in the vertex texture: 4, + 2 bone texels with bones. */
  vertexTexels?: number;
  /** Frame-table texel of the first bone row (3 texels per bone: [R_b | c_b + T_b - R_b c_b]); uniform pdeBones. */
  boneTexel?: number;
  nCurves: number;
  nVertices: number;
  /** Segments S of a dynamic clip (0 for cyclic ones). */
  nSegments: number;
  /** Texture row length in texels (a power of two near the square root of the largest texture). */
  width: number;
  /** Vertices whose positions the CPU writes into the frame table (curves of at most curveTexels vertices). */
  nDirect?: number;
  /** Texels per GPU curve in the frame table: 3 coefficient texels, then 3 rows of the rigid motion. */
  curveTexels?: number;
  /** Coefficient texels per GPU curve (3) before its rigid rows. */
  coefficientTexels?: number;
  /** The GPU's number of each clip vertex (direct ones first): the pdeVertex attribute and the pass use it. */
  gpuIndex?: Int32Array;
  /** The GPU curve of each curve (-1 for direct ones). */
  gpuCurve?: Int32Array;
  textures: {
    /** Per GPU vertex (curve, base xyz) and its orthonormal basis row per coordinate (dynamic clips). */
    vertex: FloatTexture;
    /**
     * Per-frame table rewritten by timeUniforms(): the direct vertices' positions, then per GPU curve its
     * coefficients of the frame (and rigid rows).
     */
    frame?: FloatTexture;
    /** The normals' one-rings (ringTable): per GPU vertex (first, count), then closed fans or corner pairs. */
    ring: FloatTexture;
  };
  /** The clip's vertex rings for area-weighted normals (vertexRings), in clip vertex numbers (the CPU path's). */
  rings: VertexRings;
  /** Per item its R (C * 3 * 16, row-major upper triangular): knots to orthonormal-basis coefficients. */
  r?: Float64Array;
  /** Natural-spline tangents of every knot in the orthonormal bases (layout of clip.knots), or null. */
  tangents?: Float32Array | null;
  /** The direct vertices' basis rows, bases and curves, in GPU order (the CPU places them). */
  direct?: { q: Float32Array; base: Float32Array; curve: Int32Array; vertex: Int32Array };
  /** The CPU evaluator's index of time constants (dynamic clips; made with the tables, in a worker). */
  timeIndex?: object;
  /** The clip (gpuLayout; absent in gpuTables). */
  clip?: Clip;
  /** The CPU evaluator whose per-curve state fills the frame table (dynamic clips; gpuLayout). */
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

/** One-rings of vertices (geometry.js vertexRings): v's (a, b) pairs are pairs[2 offset[v] .. 2 offset[v + 1]). */
export interface VertexRings {
  offset: Int32Array;
  pairs: Int32Array;
  /** The first vertex at each vertex's rest position (seam duplicates share their ring). */
  group: Int32Array;
}

export interface MeshAttributes {
  /**
   * Per mesh vertex: its clip vertex, then -1, -1 for a smooth vertex (the area-weighted normal of its clip
   * vertex), else the clip vertices of two triangle neighbours (n * 3).
   */
  pdeVertex: Float32Array;
  /** Per mesh vertex: its normal in the rest frame of that triangle (n * 3). */
  pdeNormalFrame: Float32Array;
}

/** The data textures and constants of a clip as plain typed arrays (a Web Worker can make and transfer them). */
export declare function gpuTables(
  clip: Clip,
  /** directMax: the most vertices of a direct curve (default: as many as a curve's table texels; 0: none). */
  options?: { width?: number; directMax?: number | null },
): GpuLayout;
/** gpuTables (or the given tables) with the clip and its CPU evaluator: what timeUniforms() needs. */
export declare function gpuLayout(
  clip: Clip,
  options?: { width?: number; tables?: GpuLayout | null; evaluator?: Evaluator | null },
): GpuLayout;
/** Bytes of the data textures. */
export declare function textureBytes(tables: GpuLayout): number;
/**
 * A crowd's shared knot table: per knot and GPU curve the coordinates' knot coefficients in the orthonormal
 * bases (3 texels), spline tangents likewise from tangentTexel, per segment and GPU curve each coordinate's
 * time-pair index (-1: spline item) from muTexel (-1 when every item is on the spline: no indices).
 */
export interface KnotTables {
  data: Float32Array;
  width: number;
  height: number;
  curves: number;
  tangentTexel: number;
  muTexel: number;
  /** Rigid clips: per rigid knot and GPU curve (rotation vector, centroid), per rigid segment their constants. */
  rigidKnotTexel: number;
  rigidMuTexel: number;
  /** The direct vertices' records (as the vertex texture's): a crowd evaluates them like the others. */
  directTexel: number;
  texels: number;
}
/** The per-player time row of a crowd: rigid segment and time, bone rows, then segment, cubic weights, time pairs. */
export interface CrowdRow {
  rigidTexel: number;
  boneTexel: number;
  timeTexel: number;
  texels: number;
}
/** The crowd's shared knot table of a dynamic layout (rows of at most maxWidth texels). */
export declare function knotTables(layout: GpuLayout, maxWidth?: number): KnotTables;
/** The knot table's layout without its values (muTexel -1: every item on the spline, no time-pair indices). */
export type KnotTablePlan = Omit<KnotTables, 'data'> & { bytes: number };
/** The size of knotTables(layout, maxWidth) without writing it. */
export declare function knotTablePlan(layout: GpuLayout, maxWidth?: number): KnotTablePlan;
/** The texels of a dynamic layout's per-player time row. */
export declare function crowdRow(layout: GpuLayout): CrowdRow;
/** Write layout's time row at t into data from value offset; returns whether it was rewritten. */
export declare function timeRow(layout: GpuLayout, t: number, row: CrowdRow, data: Float32Array, offset: number): boolean;
/** The uniforms at t; also rewrites layout.textures.frame.data when it changes (upload it then). */
export declare function timeUniforms(layout: GpuLayout, t: number): TimeUniforms;
export declare function meshAttributes(mesh: {
  vertexMap: ArrayLike<number>;
  positions: ArrayLike<number>;
  normals?: ArrayLike<number> | null;
  index?: ArrayLike<number> | null;
  /** Unit area-weighted rest normals of the clip vertices (clipNormals of clip.rest); null: no smooth vertex. */
  clipNormals?: ArrayLike<number> | null;
}): MeshAttributes;
/** The ring texture's values (first, count per GPU vertex, then closed fans or corner pairs) of vertex rings. */
export declare function ringTable(rings: VertexRings, gpuIndex?: Int32Array | null): Float32Array;
/** Unit area-weighted normals (V * 3) of the clip at positions over the tables' rings (only of vertices when given). */
export declare function clipNormals(
  tables: GpuLayout,
  positions: ArrayLike<number>,
  out?: Float32Array,
  vertices?: ArrayLike<number> | null,
): Float32Array;
/** The clip vertices of the smooth mesh vertices (those frameNormals reads from clipNormals). */
export declare function smoothVertices(attributes: MeshAttributes): Int32Array;
/** The attributes the shader reads: pdeVertex in the GPU's numbering, pdeNormalFrame as normalised int16. */
export declare function gpuAttributes(
  attributes: MeshAttributes,
  gpuIndex?: Int32Array | null,
): { pdeVertex: Float32Array; pdeNormalFrame: Int16Array };
/** The row length for a clip's largest texture of nTexels: a power of two near its square root, at most width. */
export declare function fittedWidth(nTexels: number, width?: number): number;
/** Bytes of the evaluation pass's position texture. */
export declare function passBytes(layout: GpuLayout): number;
/** Bytes per mesh vertex of the shader's attributes (18). */
export declare const ATTRIBUTE_BYTES_PER_VERTEX: number;
/** GPU bytes of the clip on a mesh: data textures, evaluation pass (default on) and attributes. */
export declare function gpuBytes(layout: GpuLayout, options?: { meshVertices?: number; pass?: boolean }): number;
export declare function frameNormals(
  clipPositions: ArrayLike<number>,
  attributes: MeshAttributes,
  restNormals: ArrayLike<number> | null,
  out: Float32Array,
  clipNormals?: ArrayLike<number> | null,
): Float32Array;
/** GLSL ES 3.00 declarations and functions (pdeCompute() sets pdePosition and pdeNormal). */
export declare function glslHeader(
  layout: GpuLayout,
  options?: {
    normals?: 'frame' | 'rest';
    stage?: 'vertex' | 'fragment';
    pass?: boolean;
    cpu?: boolean;
    slots?: boolean;
    /** The crowd variant: the knot table's row length (0: a per-frame table). */
    knotWidth?: number;
  },
): string;
/** A built-in material's vertex shader with the clip evaluation patched in (mixed by pdeInfluence). */
export declare function patchVertexShader(vertexShader: string, header: string): string;
export declare function glslPassMain(): string;
