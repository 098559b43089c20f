// Type declarations of pdeanim/three: play a clip on three.js meshes (WebGLRenderer), keeping their materials.

import type {
  AnimationClip, DataTexture, Loader, LoadingManager, Matrix4, Mesh, Object3D, WebGLRenderer,
} from 'three';
import type { Clip, Evaluator } from './index.js';
import type { CrowdRow, GpuLayout, KnotTablePlan, KnotTables, MeshAttributes } from './gpu.js';

export interface AttachOptions {
  /** Evaluate on the GPU (default true); false starts with the CPU fallback. */
  gpu?: boolean;
  /** Clip vertex of every mesh vertex (default: a _pdeanim_vertex / _PDEANIM_VERTEX attribute, else
   * the identity). */
  vertexMap?: Int32Array | number[];
  /** Clip coordinates to the mesh's local frame (Matrix4 or 16 numbers, column-major; default identity). */
  clipToLocal?: Matrix4 | number[];
  /** 'frame' (default): each frame's area-weighted vertex normals, as three.js's computeVertexNormals
   * (hard-edge vertices turned with a triangle); 'rest': kept as they are (one evaluation per vertex). */
  normals?: 'frame' | 'rest';
  /** The clip's shared data texture, layout and evaluator (default: ClipResources.acquire(clip, options)). */
  resources?: ClipResources;
  /** A per-frame table shared by meshes that show the same time (default: the player's own). */
  frames?: FrameTables;
  /** InstancedMesh only: each instance's time offset (one per-frame table per distinct offset; GPU only). */
  timeOffsets?: ArrayLike<number>;
  /**
   * When players of the clip at distinct times take its crowd form (shared knot table, a time row each):
   * 'auto' (default) unless it takes more than twice the GPU bytes of a per-frame table per time, 'bytes'
   * where it takes fewer, 'always', 'never'. Sets ClipResources.crowdForm (for all the clip's players).
   */
  crowdForm?: 'auto' | 'bytes' | 'always' | 'never';
  /**
   * The renderer: its capabilities.maxTextureSize bounds the data textures (else 4096 is assumed), and with
   * float render targets (EXT_color_buffer_float) the clip is evaluated in a pass before drawing. A
   * WebGPURenderer is refused (WEBGPU_REFUSAL): play it with pdeanim/webgpu's player.
   */
  renderer?: WebGLRenderer;
  /** Evaluate in a pass (one evaluation per clip vertex); default: when the renderer is given and supports
   * float render targets, with normals 'frame'. */
  pass?: boolean;
  /** Data texture width in texels (default 4096). */
  textureWidth?: number;
  /** Largest texture size the renderer allows (default: the renderer's, else 4096); larger clips fall back
   * to the CPU. */
  maxTextureSize?: number;
  /** GPU tables made in a Web Worker (default: clip.gpuTables, set by PDEClipLoader/decodeClipOffThread). */
  tables?: GpuLayout;
  /** Also patch depth/distance materials so shadows move (default true). */
  shadows?: boolean;
  /** mesh.frustumCulled while attached (default false: the bounds move with the clip). */
  frustumCulled?: boolean;
  /** 1 (default): the clip alone; 0: the mesh as without it; between: a linear mix (after skinning). */
  influence?: number;
}

export declare const PLAYER_OPTIONS: readonly string[];
export declare const WEBGPU_REFUSAL: string;

/** What a clip needs on the GPU whatever the time: one per clip (and texture width), reference-counted. */
export declare class ClipResources {
  constructor(clip: Clip, options?: AttachOptions);
  /** The clip's shared instance for these options, retained for the caller (release() it). */
  static acquire(clip: Clip, options?: AttachOptions): ClipResources;
  readonly clip: Clip;
  readonly layout: GpuLayout;
  readonly textures: { vertex: DataTexture };
  readonly gpuReason: string | null;
  readonly evaluator: Evaluator;
  readonly uniforms: Record<string, { value: unknown }>;
  readonly users: number;
  /** Bytes of the shared data textures (once per clip): vertex records, normal rings and, in the crowd form,
   * the knot table. */
  readonly sharedBytes: number;
  /** Bytes of the data textures for one player: the shared textures and one per-frame table (or time row). */
  readonly textureBytes: number;
  /** The per-time tables made on these resources (one per player time; ScenePlayer's meshes share one). */
  readonly tables: Set<FrameTables>;
  /**
   * The crowd form, taken once players show distinct times (a second FrameTables, or timeOffsets): the
   * shared knot table and the atlas of per-player time rows; null before.
   */
  readonly crowd: {
    table: KnotTables;
    texture: DataTexture;
    row: CrowdRow;
    atlas: { slots: (FrameTables | null)[]; data: Float32Array; texture: DataTexture };
  } | null;
  /** Why the clip cannot take the crowd form (cyclic clips, no GPU path, too large a knot table), or null. */
  readonly crowdReason: string | null;
  /** Bytes of the crowd form's atlas of time rows (free rows included; 0 before). */
  readonly atlasBytes: number;
  /** Take the crowd form (every registered FrameTables switches); returns whether the clip is in it. */
  toCrowd(): boolean;
  /** When players at distinct times take the crowd form: 'auto' (default: unless it takes over twice the bytes). */
  crowdForm: 'auto' | 'bytes' | 'always' | 'never';
  /** The crowd form's knot table size (no values): knotTablePlan. */
  readonly knotPlan: KnotTablePlan;
  /**
   * GPU bytes of the registered times (and `adding` more slots) in each form: the knot table and an atlas of
   * time rows, or a per-frame table per time; null where the crowd form is not possible.
   */
  formBytes(adding?: number): { crowd: number; tables: number } | null;
  /** Whether the crowd form pays for the registered times (plus `adding` slots), by crowdForm. */
  crowdPays(adding?: number): boolean;
  retain(): this;
  release(): void;
  dispose(): void;
}

/**
 * A player's time (one slot per distinct offset of an instanced crowd): a per-frame table of every curve's
 * coefficients while the clip has one time, or in the clip's crowd form a time row per slot in the shared atlas.
 */
export declare class FrameTables {
  constructor(resources: ClipResources, options?: { offsets?: ArrayLike<number> | null });
  readonly resources: ClipResources;
  readonly offsets: Float64Array;
  /** Whether this time is in the clip's crowd form (time rows in the shared atlas). */
  readonly crowd: boolean;
  /** The texture the shaders read: this table, or the crowd form's atlas (null: a cyclic clip's player alone). */
  readonly texture: DataTexture | null;
  readonly uniforms: Record<string, { value: unknown }>;
  /** Bytes of the table texture and of the evaluation pass's texture, or of this time's rows in the atlas. */
  readonly bytes: number;
  frame(t: number): void;
  /** Run fn when the form changes (the players recompile their materials); returns an unsubscribe function. */
  onChange(fn: () => void): () => void;
  retain(): this;
  release(): void;
}

export declare class ClipPlayer {
  constructor(mesh: Mesh, clip: Clip, options?: AttachOptions);
  readonly clip: Clip;
  readonly mesh: Mesh;
  readonly layout: GpuLayout;
  readonly uniforms: Record<string, { value: unknown }>;
  readonly textures: Record<string, DataTexture>;
  readonly evaluator: Evaluator;
  readonly vertexMap: Int32Array;
  readonly attributes: MeshAttributes;
  /** Why the GPU path is unavailable, or null. */
  readonly gpuUnavailableReason: string | null;
  readonly gpu: boolean;
  readonly time: number;
  /** Whether the clip is evaluated in a pass before drawing (else in the vertex shader; never in the crowd form). */
  readonly pass: boolean;
  /** Whether the clip is in its crowd form (players at distinct times: a shared knot table, a time row each). */
  readonly crowd: boolean;
  /** A key of the shader variant (materials' program cache key): one for every player of a crowd. */
  readonly programKey: string;
  readonly resources: ClipResources;
  readonly frames: FrameTables;
  /** Whether the mesh is an InstancedMesh played with timeOffsets. */
  readonly slots: boolean;
  /** Bytes of the per-vertex attributes this player adds. */
  readonly attributeBytes: number;
  /** Bytes on the GPU for the clip on this mesh: the shared data texture, this player's per-frame table(s),
   * evaluation pass (when it runs) and attributes. */
  readonly gpuBytes: number;
  influence: number;
  /** A player on mesh.clone() (the mesh's own materials): its own time, sharing the clip's data texture. */
  clone(): ClipPlayer;
  /** Show the clip at normalised time t: [0, 1] unless the clip loops (else RangeError). */
  setTime(t: number, evaluated?: Float32Array | null): this;
  /** Switch GPU evaluation on or off (CPU fallback); returns whether the GPU is used. */
  useGPU(on: boolean): boolean;
  /** CPU-evaluated positions in clip vertex order (does not touch the mesh). */
  positions(t: number, out?: Float32Array): Float32Array;
  /** Restore the mesh's materials and geometry; the textures are freed with their last player. */
  detach(): void;
}

export declare class ScenePlayer {
  constructor(root: Object3D, clip: Clip, options?: SceneOptions);
  readonly root: Object3D;
  readonly clip: Clip;
  readonly players: ClipPlayer[];
  readonly resources: ClipResources;
  readonly frames: FrameTables;
  readonly evaluator: Evaluator;
  readonly gpuUnavailableReason: string | null;
  readonly gpu: boolean;
  readonly time: number;
  /** Bytes on the GPU for the clip: the shared data texture, this player's per-frame table and every mesh's
   * attributes. */
  readonly gpuBytes: number;
  influence: number;
  /** A player on root.clone() (the meshes' own materials): its own time, sharing the clip's data texture. */
  clone(): ScenePlayer;
  setTime(t: number): this;
  useGPU(on: boolean): boolean;
  positions(t: number, out?: Float32Array): Float32Array;
  detach(): void;
}

export type SceneOptions = Omit<AttachOptions, 'vertexMap' | 'clipToLocal' | 'resources' | 'frames' | 'timeOffsets'> & {
  filter?: (mesh: Mesh) => boolean;
};

/** Play a decoded clip on a mesh, keeping its materials (patched clones via onBeforeCompile). */
export declare function attachClip(mesh: Mesh, clip: Clip, options?: AttachOptions): ClipPlayer;

/**
 * Play a clip on every mesh under root (depth-first; consecutive clip vertex ranges, each mesh placed by its
 * transform relative to root), e.g. the user's own glTF scene, or a GLB that pdeanim wrote.
 */
export declare function attachClipToScene(root: Object3D, clip: Clip, options?: SceneOptions): ScenePlayer;

/** A three.js Loader of CLIP files and of service clip URLs (…/v1/clips/ID), decoding in a Web Worker. */
export declare class PDEClipLoader extends Loader<Clip> {
  constructor(manager?: LoadingManager);
  setWorker(on: boolean): this;
  setTextureWidth(width: number): this;
  /**
   * Play streamable clips (format 1.2, feature "stream") while they download: the loader resolves with a
   * StreamingClip once the first window is decoded (default true; a service clip is asked for with
   * ?layout=stream). false: the whole body first.
   */
  setStreaming(on: boolean): this;
  /** Windows of a streaming clip decoded at once (default 4, at least 2). */
  setMaxWindows(n: number): this;
  parse(buffer: ArrayBuffer): Clip;
  parseAsync(buffer: ArrayBuffer): Promise<Clip>;
}

/** Seconds of a clip: its source frames' span (cyclic clips: one period). */
export declare function clipDuration(clip: Clip): number;
/**
 * An AnimationClip for an AnimationMixer rooted at the player's mesh/root or an ancestor: action time
 * 0 .. duration maps to t = 0 .. 1, its effective weight to the player's influence. pose: the skeletal
 * animation the clip was fitted on (its time 0 .. its duration is t = 0 .. 1): the action also drives those
 * bones, so that crossfades with skeletal actions blend bones between poses, not with the bind pose.
 */
export declare function clipAnimation(
  player: ClipPlayer | ScenePlayer,
  options?: { name?: string; duration?: number; pose?: AnimationClip | null },
): AnimationClip;

/** Decode a clip (and its GPU tables) in a Web Worker where one can run, else here. */
export declare function decodeClipOffThread(
  parts: { topology?: ArrayBuffer | ArrayBufferView; coefficients?: ArrayBuffer | ArrayBufferView; file?: ArrayBuffer | ArrayBufferView },
  options?: { tables?: boolean; width?: number; useWorker?: boolean },
): Promise<Clip>;
/** Why clips cannot be decoded in a Web Worker here (null when they can). */
export declare function workerUnavailableReason(): string | null;
/**
 * Open a streamable clip for decoding window by window (in the Web Worker where one can run): its topology
 * part and head (the coefficients part's bytes up to its first window), checked, with the GPU tables all
 * windows share.
 */
export declare function openStreamOffThread(
  parts: { topology: ArrayBuffer | ArrayBufferView; head: ArrayBuffer | ArrayBufferView },
  options?: { tables?: boolean; width?: number; useWorker?: boolean },
): Promise<{
  shell: object;
  tables: GpuLayout | null;
  decode(index: number, bytes: Uint8Array): Promise<{ clip: Clip; tables: object | null }>;
  close(): void;
}>;
