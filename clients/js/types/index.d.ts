// Type declarations of the pdeanim package (hand-written; the sources are plain ES modules).

export type BytesLike = ArrayBuffer | ArrayBufferView;
export type TypedArray =
  Float32Array | Float64Array | Int32Array | Uint32Array | Int16Array | Uint16Array | Uint8Array | Int8Array;

/** The container version read (the uint32 at byte 8). */
export declare const CONTAINER_VERSION: 1;
/** Array encodings a container may use (decoded with the fzstd package). */
export declare const ENCODINGS: readonly ['zstd', 'shuffle-zstd'];
/** The clip format written and read (docs/format.md): readers accept any "1.<minor>". */
export declare const FORMAT_VERSION: '1.0';
/** The format features this reader implements (a part's `required` list may name only these). */
export declare const SUPPORTED_FEATURES: readonly ['bones', 'stream'];
/**
 * Throws ClipFormatError unless header.format_version is "1.<minor>" and every feature its `required` names
 * is supported (checkRequired).
 */
export declare function checkFormatVersion(header: { format_version?: unknown; required?: unknown }, part: string): void;
/**
 * The features a part requires (`required`, absent = []); throws ClipFormatError naming any this reader lacks
 * and the supported set, or when `required` is not a list of strings.
 */
export declare function checkRequired(header: { required?: unknown }, part: string): string[];
/** Time models of an item (`time_model`): the paper's time pairs (0), the natural cubic spline (1). */
export declare const TIME_PDE: 0;
export declare const TIME_SPLINE: 1;

/** Thrown for anything that is not a valid pdeanim container, part, clip or CLIP file. */
export declare class ClipFormatError extends Error {
  constructor(message: string);
}

export interface ContainerArray {
  dtype: '<f4' | '<f8' | '<i4' | '<u4' | '<i2' | '<u2' | '<u1' | '<i1';
  shape: number[];
  /** The decoded values (C order); a view on the input for raw arrays, a fresh array for encoded ones. */
  data: TypedArray;
  /** How the array was stored in a version 2 container (absent: raw little-endian bytes). */
  encoding?: 'zstd' | 'shuffle-zstd';
}

export interface Container {
  header: Record<string, any>;
  arrays: Record<string, ContainerArray>;
}

/**
 * Decode container bytes (magic, version 1 or 2, JSON header, little-endian arrays; version 2 arrays may be
 * zstd frames, decompressed here). Throws ClipFormatError.
 */
export declare function decodeContainer(data: BytesLike): Container;

interface ClipBase {
  nVertices: number;
  /**
   * Triangles (T * 3) as original vertex indices; format version 2 stores them in a canonical order (each
   * turned to start at its lowest curve rank, winding kept; rows sorted), so only the set matches the source.
   */
  faces: Int32Array;
  /** Rest (first-frame) positions, V * 3. */
  rest: Float32Array;
  /** Seconds of the source frames (cyclic: i * period / frames). */
  frameTimes: Float64Array;
  looping: boolean;
  /** SHA-256 hex of the topology part the coefficients were made for. */
  topologyId: string | null;
  /** Header of the coefficients part. */
  header: Record<string, any>;
  /** Header of the topology part. */
  topologyHeader: Record<string, any>;
  /** Body sizes as received (set by fetchClip). */
  bytes?: { topology: number; coefficients: number };
}

export interface RigidTracks {
  segmentT: Float64Array;
  centre: Float32Array;
  rotKnots: Float32Array;
  rotMu: Float32Array;
  transKnots: Float32Array;
  transMu: Float32Array;
}

/**
 * The bone layer of a format 1.1 clip (feature "bones", docs/format.md): B rigid bone transforms over time,
 * linear-blend skinning of the rest pose with at most 4 influences per vertex; the curves add a residual.
 */
export interface BoneLayer {
  /** false when every curve knot is 0: the frame is the skinned rest pose (no residual tables on the GPU). */
  residual: boolean;
  nBones: number;
  /** Influences K per vertex (1..4). */
  influences: number;
  /** The bone tracks' own segment boundaries (Sb+1), strictly increasing from 0 to 1. */
  segmentT: Float64Array;
  /** Rest-pose pivots (B, 3). */
  pivot: Float32Array;
  /** Bone of each influence (V, K), original vertex order. */
  index: Uint16Array;
  /** Normalised weights (V, K) float64, rows summing to 1. */
  weight: Float64Array;
  /** Time model of each channel (B, 6): 0 the paper's pair, 1 the natural spline. */
  timeModel: Uint8Array;
  /** Signed time constants (Sb, B, 6). */
  m: Float32Array;
  /** Knot values ((Sb+1), B * 6) float64 of the float32 values, knot-major. */
  knots: Float64Array;
  /** Natural-spline tangents in the layout of knots, or null without spline channels. */
  tangents: Float64Array | null;
}

/** The bone transforms of a bone layer at a time (float64), and the skinning of the rest pose with them. */
export declare class BonePose {
  constructor(bones: BoneLayer);
  /** Row-major R_b of every bone (B * 9) at the last at(). */
  readonly rot: Float64Array;
  /** T_b of every bone (B * 3) at the last at(). */
  readonly trans: Float64Array;
  /** The transforms at wrapped clip time tw in [0, 1]. */
  at(tw: number): this;
  /** Rows [R_b | c_b + T_b - R_b c_b] (B * 12): x -> R_b (x - c_b) + c_b + T_b as an affine map. */
  affine(out?: Float64Array): Float64Array;
  /** Skinned position of vertex v (float64) into out[o..o+2]. */
  skinVertex(rest: Float32Array, v: number, out: Float64Array | number[], o?: number): Float64Array | number[];
  /** Skinned rest pose (V * 3) into out (a Float32Array rounds each coordinate once). */
  skin(rest: Float32Array, out: Float32Array): Float32Array;
}

/** The checked bone layer of a coefficients part (docs/format.md's rejections as ClipFormatError). */
export declare function decodeBones(
  header: Record<string, any>,
  arrays: Record<string, ContainerArray>,
  nVertices: number,
  motion: string,
  knots: Float32Array,
): BoneLayer;

export interface DynamicClip extends ClipBase {
  kind: 'dynamic-pde';
  nCurves: number;
  nSegments: number;
  motion: 'displacement' | 'absolute' | 'rigid';
  paramMode: string;
  order: Int32Array;
  offsets: Int32Array;
  /** Curve of every vertex (V). */
  curveOf: Int32Array;
  u: Float32Array;
  uColumns: 1 | 3;
  segmentT: Float64Array;
  family: Uint8Array;
  m: Float32Array;
  D: Float32Array;
  /** Knots (S+1, C, 3, 4) as float32, decoded from their integer codes. */
  knots: Float32Array;
  /**
   * Time models (C, 3): 1 where the item is on the natural cubic spline through its knots in every segment
   * (docs/format.md §3.5), else 0 (the paper's time pairs); null when no item is on the spline.
   */
  timeModel: Uint8Array | null;
  rigid: RigidTracks | null;
  /** The bone layer (format 1.1, `required` lists "bones"): the curves are then a residual on it; else null. */
  bones: BoneLayer | null;
}

export interface SwimParams {
  mode: string;
  omega0: number;
  omega1: number;
  alpha: number;
  phi: number;
  frequency: number;
  amplitude: number;
  wave: 'standing' | 'travelling';
  radial: 'rotate' | 'translate';
  direction: 'lateral' | 'vertical';
}

export interface CyclicClip extends ClipBase {
  kind: 'cyclic-spine';
  nPatches: number;
  order: number;
  patch: Int32Array;
  uv: Float32Array;
  spine: Float64Array;
  frame: { origin: number[]; axis: number[]; lateral: number[]; up: number[]; xMin: number; xMax: number };
  swim: SwimParams;
  period: number;
  frames: number;
}

/** One time window of a streamable clip: its index entry (docs/format.md §3.10). */
export interface StreamWindow {
  index: number;
  array: string;
  /** Byte offset and size in the coefficients part's data (StreamingClip: offset/length in the resource). */
  offset: number;
  nbytes: number;
  /** Its first and last normalised time, knot (segments a .. b - 1). */
  t0: number;
  t1: number;
  a: number;
  b: number;
  s0?: number;
  s1?: number;
  length?: number;
}

/**
 * A clip of the streamable layout (format 1.2, feature "stream", docs/format.md §3.10): its head decoded (the
 * static data of a DynamicClip, without the per-segment arrays) and its time windows decoded when needed, at
 * most maxWindows at once. Evaluators and players take it as any dynamic clip.
 */
export interface WindowedClip extends Omit<DynamicClip, 'segmentT' | 'family' | 'm' | 'knots'> {
  readonly windowed: true;
  readonly nWindows: number;
  readonly index: StreamWindow[];
  maxWindows: number;
  /** The decoded windows: index -> {clip (a DynamicClip of its segments), tables, evaluator}. */
  readonly decoded: Map<number, { clip: DynamicClip; tables: object | null; evaluator: DynamicEvaluator | null }>;
  /** The window holding normalised time t. */
  windowAt(t: number): number;
  /** Whether a frame at t can be evaluated now. */
  ready(t: number): boolean;
  /** Move the play head to t (a StreamingClip fetches and evicts); whether t's window is decoded. */
  setPlayhead(t: number): boolean;
}

/**
 * A streamable clip played while it downloads (PDEClipLoader resolves with it once its first window is
 * decoded). Events: 'window' (detail {index, s0, s1, t0, t1, decoded}), 'evict' ({index}), 'progress'
 * ({loaded, position}), 'error' ({error}), 'end'.
 */
export interface StreamingClip extends WindowedClip, EventTarget {
  readonly streaming: true;
  /** The windows with their byte ranges in the resource. */
  readonly windows: StreamWindow[];
  /** The window index of the play head. */
  readonly playhead: number;
  /** The windows wanted now: the play head's and the next ones. */
  wanted(): number[];
  /** Resolves once t's window is decoded (the play head moved there). */
  whenReady(t: number): Promise<void>;
  /** Stop downloading and drop the windows. */
  close(): void;
}

export declare const STREAM_FEATURE: 'stream';
/** Whether a coefficients (or CLIP file) header is of the streamable layout (`required` lists "stream"). */
export declare function isStreamHeader(header: Record<string, any>): boolean;
/** The checked window index of a streamable coefficients header (ClipFormatError "damaged stream index"). */
export declare function streamIndex(header: Record<string, any>): StreamWindow[];
/** A streamable coefficients part held in memory, its windows decoded when first evaluated. */
export declare function decodeWindowedClip(
  topology: ArrayBuffer | ArrayBufferView,
  coefficients: ArrayBuffer | ArrayBufferView,
  options?: { maxWindows?: number },
): WindowedClip;
/** Thrown when a streaming clip is evaluated at a time whose window is not decoded. */
export declare class WindowPendingError extends Error {
  readonly window: number;
}

export type Clip = DynamicClip | CyclicClip | WindowedClip;

/** CPU evaluator: positions (V * 3, original vertex order) at normalised clip time t. */
export interface Evaluator {
  readonly nVertices: number;
  /**
   * Writes into out (allocated when omitted) and returns it; throws RangeError for a non-finite t, and for t
   * outside [0, 1] when the clip does not loop (looping clips wrap with period 1).
   */
  evaluate(t: number, out?: Float32Array): Float32Array;
}

export declare class DynamicEvaluator implements Evaluator {
  constructor(clip: DynamicClip);
  readonly nVertices: number;
  /** The bone transforms at the last evaluated time (clips with bones), else null. */
  readonly bones: BonePose | null;
  evaluate(t: number, out?: Float32Array): Float32Array;
}

export declare class CyclicEvaluator implements Evaluator {
  constructor(clip: CyclicClip);
  readonly nVertices: number;
  evaluate(t: number, out?: Float32Array): Float32Array;
}

/** Decode a clip from its two parts (synchronous; no topology_id check). */
export declare function decodeClip(topology: BytesLike, coefficients: BytesLike): Clip;
/** The two parts of a CLIP file. */
export declare function splitClipFile(data: BytesLike): {
  topology: Uint8Array;
  coefficients: Uint8Array;
  header: Record<string, any>;
};
/** Decode a CLIP file (synchronous; no topology_id check). */
export declare function decodeClipFile(data: BytesLike): Clip;
/** Decode a clip and check topology_id (SHA-256 via WebCrypto where available). */
export declare function loadClip(topology: BytesLike, coefficients: BytesLike): Promise<Clip>;
export declare function loadClipFile(data: BytesLike): Promise<Clip>;
export declare function sha256Hex(data: BytesLike): Promise<string | null>;

export interface FetchOptions {
  /** Sent as Authorization: Bearer KEY. */
  key?: string;
  headers?: Record<string, string>;
  fetch?: typeof globalThis.fetch;
  signal?: AbortSignal;
}

export declare function fetchBuffer(url: string, options?: Omit<FetchOptions, 'key'>): Promise<ArrayBuffer>;
/** Fetch both parts (in parallel) and decode them; the result has .bytes. */
export declare function fetchClip(
  options: FetchOptions & { topology: string; coefficients: string },
): Promise<Clip>;
/** Fetch clip clipId from a pdeanim service (GET /v1/clips/{id}/topology and /coefficients). */
export declare function fetchServiceClip(
  baseUrl: string,
  clipId: string,
  options?: FetchOptions,
): Promise<Clip>;
export declare function fetchClipFile(url: string, options?: FetchOptions): Promise<Clip>;

/** The CPU evaluator of a decoded clip (precomputes everything independent of t). */
export declare function createEvaluator(clip: DynamicClip, prepared?: object | null): DynamicEvaluator;
export declare function createEvaluator(clip: CyclicClip): CyclicEvaluator;
export declare function createEvaluator(clip: Clip, prepared?: object | null): Evaluator;

/** Per-vertex space basis (V * 12: vertex, coordinate, function) of a dynamic clip. */
export declare function vertexBasis(clip: DynamicClip): Float64Array;
/** Positions before the motion: rest, zeros, or rest - centre (V * 3). */
export declare function vertexBase(clip: DynamicClip): Float32Array;
/** The four balanced space functions (space kind 0 = D0, 1 = D1) into out[o..o+3]. */
export declare function spaceBasis(
  u: number,
  D: number,
  kind: 0 | 1,
  out: Float64Array | number[],
  o?: number,
): typeof out;
/** The time pair (phi0, phi1) of a signed constant into out[o], out[o+1]. */
export declare function timePair(
  tau: number,
  mu: number,
  out: Float64Array | number[],
  o?: number,
): typeof out;
export declare function rigidTimePair(
  tau: number,
  mu: number,
  out: Float64Array | number[],
  o?: number,
): typeof out;
/** [segment, tau, wrapped t] of t on the boundaries (written into out when given). */
export declare function locate(
  bounds: ArrayLike<number>,
  t: number,
  looping: boolean,
  out?: number[],
): [number, number, number];

/** Area-weighted vertex normals. */
export declare function computeNormals(
  positions: ArrayLike<number>,
  faces: ArrayLike<number>,
  out?: Float32Array,
): Float32Array;
export declare function boundingBoxDiagonal(positions: ArrayLike<number>): number;
/** Per vertex the (a, b) of its incident triangles; vertices at one rest position share one ring. */
export declare function vertexRings(
  faces: ArrayLike<number>,
  rest: ArrayLike<number>,
): { offset: Int32Array; pairs: Int32Array; group: Int32Array };
/** Unit area-weighted normals over vertexRings (three.js's computeVertexNormals); only of vertices when given. */
export declare function ringNormals(
  positions: ArrayLike<number>,
  rings: { offset: Int32Array; pairs: Int32Array },
  out?: Float32Array,
  vertices?: ArrayLike<number> | null,
): Float32Array;

/** Install the zstd streaming decoder class (fzstd's Decompress); the entry points install fzstd's. */
export declare function setZstdDecompress(cls: unknown): void;
/** t checked against the clip: finite, and in [0, 1] unless it loops; throws RangeError. */
export declare function checkTime(t: number, looping: boolean): number;
export declare function triangleFrame(
  positions: ArrayLike<number>,
  p: number,
  a: number,
  b: number,
  out: Float64Array | Float32Array,
  offset?: number,
): Float64Array | Float32Array;
