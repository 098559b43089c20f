// Type declarations of pdeanim/three: play a clip on three.js meshes (WebGLRenderer), keeping their materials.

import type {
  AnimationClip, DataTexture, Loader, LoadingManager, Matrix4, Mesh, Object3D, WebGLRenderer,
} from 'three';
import type { Clip, Evaluator } from './index.js';
import type { GpuLayout, MeshAttributes } from './gpu.js';

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
  /** Shared layout/textures/evaluator when several meshes play one clip. */
  resources?: ClipResources;
  /**
   * The renderer: its capabilities.maxTextureSize bounds the data textures (else 4096 is assumed), and with
   * float render targets (EXT_color_buffer_float) the clip is evaluated in a pass before drawing. A
   * WebGPURenderer is refused (use pdeanim/webgpu's refusal message: WEBGPU_REFUSAL).
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

export declare class ClipResources {
  constructor(clip: Clip, options?: AttachOptions);
  readonly clip: Clip;
  readonly layout: GpuLayout;
  readonly textures: Record<string, DataTexture>;
  readonly gpuReason: string | null;
  readonly evaluator: Evaluator;
  readonly uniforms: Record<string, { value: unknown }>;
  /** Bytes of the data textures. */
  readonly textureBytes: number;
  frame(t: number): void;
  dispose(): void;
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
  /** Whether the clip is evaluated in a pass before drawing (else in the vertex shader). */
  readonly pass: boolean;
  readonly resources: ClipResources;
  /** Bytes of the per-vertex attributes this player adds. */
  readonly attributeBytes: number;
  /** Bytes on the GPU for the clip on this mesh: data textures, evaluation pass (when it runs), attributes. */
  readonly gpuBytes: number;
  influence: number;
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
  readonly evaluator: Evaluator;
  readonly gpuUnavailableReason: string | null;
  readonly gpu: boolean;
  readonly time: number;
  /** Bytes on the GPU for the clip: data textures and every mesh's attributes. */
  readonly gpuBytes: number;
  influence: number;
  setTime(t: number): this;
  useGPU(on: boolean): boolean;
  positions(t: number, out?: Float32Array): Float32Array;
  detach(): void;
}

export type SceneOptions = Omit<AttachOptions, 'vertexMap' | 'clipToLocal' | 'resources'> & {
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
