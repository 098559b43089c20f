// Type declarations of pdeanim/three: play a clip on a three.js mesh, evaluated in the vertex shader.

import type { DataTexture, Matrix4, Mesh, Object3D } from 'three';
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
  /** 'frame' (default): normals turned with each vertex's triangle (3 evaluations per vertex); 'rest':
   * kept as they are. */
  normals?: 'frame' | 'rest';
  /** 'auto' (default): per-knot per-vertex fields while they fit 64 MB, else 'coefficients'. */
  gpuMode?: 'auto' | 'fields' | 'coefficients';
  /** Shared layout/textures/evaluator (from clipResources) when several meshes play one clip. */
  resources?: ClipResources;
  /**
   * The renderer: its capabilities.maxTextureSize bounds the data textures (else 4096 is assumed), and with
   * float render targets (EXT_color_buffer_float) the clip is evaluated in a pass before drawing.
   */
  renderer?: { capabilities?: { maxTextureSize?: number }; extensions?: { has(name: string): boolean } };
  /** Evaluate in a pass (one evaluation per clip vertex, 3 texture reads per mesh vertex); default: when
   * the renderer is given and supports float render targets, with normals 'frame'. */
  pass?: boolean;
  /** Data texture width in texels (default 4096). */
  textureWidth?: number;
  /** Largest texture height the renderer allows (default 4096); larger clips fall back to the CPU. */
  maxTextureSize?: number;
  /** Also patch depth/distance materials so shadows move (default true). */
  shadows?: boolean;
  /** mesh.frustumCulled while attached (default false: the bounds move with the clip). */
  frustumCulled?: boolean;
}

export interface ClipResources {
  clip: Clip;
  layout: GpuLayout;
  textures: Record<string, DataTexture>;
  gpuReason: string | null;
  evaluator: Evaluator;
}

export interface ClipPlayer {
  readonly clip: Clip;
  readonly layout: GpuLayout;
  readonly uniforms: Record<string, { value: any }>;
  readonly textures: Record<string, DataTexture>;
  readonly evaluator: Evaluator;
  readonly vertexMap: Int32Array;
  readonly attributes: MeshAttributes;
  /** Why the GPU path is unavailable, or null. */
  readonly gpuUnavailableReason: string | null;
  readonly gpu: boolean;
  readonly time: number;
  readonly mesh: Mesh;
  /** Whether the clip is evaluated in a pass before drawing (else in the vertex shader). */
  readonly pass: boolean;
  readonly resources: ClipResources;
  /** Show the clip at normalised time t (evaluated: the clip's CPU positions at t, if already known). */
  setTime(t: number, evaluated?: Float32Array | null): ClipPlayer;
  /** Switch GPU evaluation on or off (CPU fallback); returns whether the GPU is used. */
  useGPU(on: boolean): boolean;
  /** CPU-evaluated positions in clip vertex order (does not touch the mesh). */
  positions(t: number, out?: Float32Array): Float32Array;
  /** Restore the mesh's materials and geometry and free the textures. */
  detach(): void;
}

/** Play a decoded clip on a mesh, keeping its materials (patched clones via onBeforeCompile). */
export declare function attachClip(mesh: Mesh, clip: Clip, options?: AttachOptions): ClipPlayer;

export interface ScenePlayer {
  readonly clip: Clip;
  readonly players: ClipPlayer[];
  readonly resources: ClipResources;
  readonly gpuUnavailableReason: string | null;
  readonly gpu: boolean;
  readonly time: number;
  setTime(t: number): ScenePlayer;
  useGPU(on: boolean): boolean;
  positions(t: number, out?: Float32Array): Float32Array;
  detach(): void;
}

/** Layout, textures and evaluator of a clip, to share between meshes. */
export declare function clipResources(clip: Clip, options?: AttachOptions): ClipResources;

/**
 * Play a clip on every mesh under root (depth-first; consecutive clip vertex ranges, each mesh placed by its
 * transform relative to root), e.g. gltf.scene of a GLB that pdeanim wrote.
 */
export declare function attachClipToScene(
  root: Object3D,
  clip: Clip,
  options?: Omit<AttachOptions, 'vertexMap' | 'clipToLocal' | 'resources'> & {
    filter?: (mesh: Mesh) => boolean;
  },
): ScenePlayer;
