// Type declarations of pdeanim/three: play a clip on a three.js mesh, evaluated in the vertex shader.

import type { DataTexture, Mesh } from 'three';
import type { Clip, Evaluator } from './index.js';
import type { GpuLayout, MeshAttributes } from './gpu.js';

export interface AttachOptions {
  /** Evaluate on the GPU (default true); false starts with the CPU fallback. */
  gpu?: boolean;
  /** Clip vertex of every mesh vertex (default: a _pdeanim_vertex / _PDEANIM_VERTEX attribute, else
   * the identity). */
  vertexMap?: Int32Array | number[];
  /** Data texture width in texels (default 4096). */
  textureWidth?: number;
  /** Largest texture height the renderer allows (default 4096); larger clips fall back to the CPU. */
  maxTextureSize?: number;
  /** Also patch depth/distance materials so shadows move (default true). */
  shadows?: boolean;
  /** mesh.frustumCulled while attached (default false: the bounds move with the clip). */
  frustumCulled?: boolean;
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
  /** Show the clip at normalised time t. */
  setTime(t: number): ClipPlayer;
  /** Switch GPU evaluation on or off (CPU fallback); returns whether the GPU is used. */
  useGPU(on: boolean): boolean;
  /** CPU-evaluated positions in clip vertex order (does not touch the mesh). */
  positions(t: number, out?: Float32Array): Float32Array;
  /** Restore the mesh's materials and geometry and free the textures. */
  detach(): void;
}

/** Play a decoded clip on a mesh, keeping its materials (patched clones via onBeforeCompile). */
export declare function attachClip(mesh: Mesh, clip: Clip, options?: AttachOptions): ClipPlayer;
