// pdeanim/three: play pdeanim clips with three.js's WebGLRenderer, keeping the meshes' own materials: the
// player (one mesh, or every mesh of a scene such as a glTF), the Loader, and the AnimationMixer link.
// WebGPURenderer (either backend): pdeanim/webgpu, the same API on node materials.

import './zstd.js';

export { ClipPlayer, attachClip, PLAYER_OPTIONS } from './player.js';
export { ScenePlayer, attachClipToScene } from './scene.js';
export { ClipResources, FrameTables } from './resources.js';
export { PDEClipLoader } from './loader.js';
export { clipAnimation, clipDuration } from './mixer.js';
export { decodeClipOffThread, openStreamOffThread, workerUnavailableReason } from './offthread.js';
export { WEBGPU_REFUSAL } from './webgl.js';
