// Type declarations of pdeanim/webgpu: play a clip on three.js meshes with WebGPURenderer (its WebGPU backend
// or its WebGL 2 fallback), keeping their materials as node materials. The same API as pdeanim/three.

import type { Mesh, Object3D } from 'three';
import type { WebGPURenderer } from 'three/webgpu';
import type { Clip } from './index.js';
import type { AttachOptions as WebGLAttachOptions } from './three.js';
import { ClipPlayer as WebGLClipPlayer, ScenePlayer as WebGLScenePlayer } from './three.js';

export { ClipResources, FrameTables, PDEClipLoader, PLAYER_OPTIONS, clipAnimation, clipDuration } from './three.js';
export { decodeClipOffThread, workerUnavailableReason } from './three.js';

/**
 * pdeanim/three's options, with a WebGPURenderer (its device's or WebGL context's largest texture bounds the
 * data textures; a WebGLRenderer is refused) and without the evaluation pass (the vertex stage evaluates).
 */
export type AttachOptions = Omit<WebGLAttachOptions, 'renderer' | 'pass'> & {
  renderer?: WebGPURenderer;
  /** Not supported here: true is refused (the WebGPU player evaluates in the vertex stage). */
  pass?: false;
};

export type SceneOptions = Omit<AttachOptions, 'vertexMap' | 'clipToLocal' | 'resources' | 'frames' | 'timeOffsets'> & {
  filter?: (mesh: Mesh) => boolean;
};

/** The message a WebGLRenderer drawing a pdeanim/webgpu player gets (node materials need WebGPURenderer). */
export declare const WEBGL_REFUSAL: string;

/**
 * A decoded clip played on one mesh with WebGPURenderer: the mesh's materials become their node materials
 * (a built-in material's node counterpart, or a clone of a NodeMaterial) whose vertex stage evaluates the clip
 * after morphing, skinning and the material's own positionNode; shadows follow (castShadowPositionNode).
 */
export declare class ClipPlayer extends WebGLClipPlayer {
  constructor(mesh: Mesh, clip: Clip, options?: AttachOptions);
}

/** One clip on every mesh under root with WebGPURenderer (as pdeanim/three's ScenePlayer). */
export declare class ScenePlayer extends WebGLScenePlayer {
  constructor(root: Object3D, clip: Clip, options?: SceneOptions);
}

/** Play a decoded clip on a mesh with WebGPURenderer, keeping its materials (as node materials). */
export declare function attachClip(mesh: Mesh, clip: Clip, options?: AttachOptions): ClipPlayer;

/** Play a clip on every mesh under root with WebGPURenderer (see pdeanim/three's attachClipToScene). */
export declare function attachClipToScene(root: Object3D, clip: Clip, options?: SceneOptions): ScenePlayer;
