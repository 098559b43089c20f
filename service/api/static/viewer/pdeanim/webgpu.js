// pdeanim/webgpu: play pdeanim clips with three.js's WebGPURenderer (on its WebGPU backend and on its WebGL 2
// fallback), keeping the meshes' own materials: each is turned into its node material (as WebGPURenderer
// does) whose positionNode evaluates the clip (tsl.js: glsl.js's evaluation in TSL, on the same data textures
// of gpu.js). Same API as pdeanim/three: ClipPlayer, ScenePlayer, the Loader and the AnimationMixer link.

import './zstd.js';
import * as WEBGPU from 'three/webgpu';
import { ClipPlayer as BasePlayer } from './player.js';
import { ScenePlayer as BaseScene } from './scene.js';
import { checkTSL, playClip, shadowPositionNode } from './tsl.js';
import { isWebGPURenderer } from './webgl.js';

export { PLAYER_OPTIONS } from './player.js';
export { ClipResources, FrameTables } from './resources.js';
export { PDEClipLoader } from './loader.js';
export { clipAnimation, clipDuration } from './mixer.js';
export { decodeClipOffThread, workerUnavailableReason } from './offthread.js';

export const WEBGL_REFUSAL =
  'pdeanim/webgpu plays clips with node materials, which only WebGPURenderer draws (on either backend): ' +
  "play the clip on a WebGLRenderer with pdeanim/three's player";

/** The built-in material types with a node counterpart (WebGPURenderer's NodeLibrary maps the same). */
const NODE_TYPES = [
  'MeshBasicMaterial',
  'MeshLambertMaterial',
  'MeshPhongMaterial',
  'MeshStandardMaterial',
  'MeshPhysicalMaterial',
  'MeshToonMaterial',
  'MeshMatcapMaterial',
  'MeshNormalMaterial',
  'PointsMaterial',
  'LineBasicMaterial',
];

/** The node material class of a built-in material type (MeshStandardMaterial: MeshStandardNodeMaterial). */
function nodeClass(type) {
  return NODE_TYPES.includes(type) ? (WEBGPU[type.replace(/Material$/, 'NodeMaterial')] ?? null) : null;
}

/** Throw naming what is missing when the installed three.js lacks the node materials this module drives. */
function checkThree() {
  checkTSL();
  if (typeof WEBGPU.NodeMaterial?.prototype?.setupPosition !== 'function') {
    throw new Error("pdeanim/webgpu needs three.js's node materials as in r187: NodeMaterial has no setupPosition");
  }
}

/** The material each node material was made from (a mesh.clone() shares the player's one: use its original). */
const ORIGINAL = new WeakMap();

/**
 * A node material of the player's own for material: a clone of a node material, or a built-in material's
 * node counterpart with its properties copied (as WebGPURenderer converts it when drawing). Throws for
 * materials that have none (ShaderMaterial: its GLSL cannot run on WebGPU).
 */
function nodeMaterial(material) {
  material = ORIGINAL.get(material) ?? material;
  let m;
  if (material.isNodeMaterial) m = material.clone();
  else {
    const NodeClass = nodeClass(material.type);
    if (!NodeClass) {
      throw new Error(
        `pdeanim/webgpu: a ${material.type} has no node material to play the clip in (use a built-in ` +
          'material or a NodeMaterial)',
      );
    }
    m = new NodeClass();
    const uuid = m.uuid;
    for (const key in material) m[key] = material[key];
    m.uuid = uuid; // its own program, not the source material's
  }
  ORIGINAL.set(m, material);
  return m;
}

/** The largest 2D texture WebGPURenderer's backend takes (undefined before renderer.init() resolves). */
function backendTextureLimit(renderer) {
  const backend = renderer?.backend;
  const device = backend?.device;
  if (device?.limits?.maxTextureDimension2D) return device.limits.maxTextureDimension2D;
  const gl = backend?.gl;
  if (gl?.getParameter) return gl.getParameter(gl.MAX_TEXTURE_SIZE);
  return undefined;
}

/** Options for the base players: the backend's texture limit when a renderer is given. */
function withLimit(options) {
  if (options.maxTextureSize !== undefined || !options.renderer) return options;
  const limit = backendTextureLimit(options.renderer);
  return limit === undefined ? options : { ...options, maxTextureSize: limit };
}

/**
 * The WebGPU backend of the players: check(renderer) refuses a WebGLRenderer; no evaluation pass (the vertex
 * stage evaluates each clip vertex it reads); install(player) gives the mesh node materials whose
 * positionNode plays the clip (shadows follow it: WebGPURenderer draws shadows with the positionNode).
 */
export const webgpuBackend = {
  name: 'webgpu',
  check(renderer) {
    checkThree();
    if (renderer && !isWebGPURenderer(renderer)) throw new Error(WEBGL_REFUSAL);
  },
  usePass(options) {
    if (options.pass) throw new Error('pdeanim/webgpu evaluates the clip in the vertex stage: the pass option is WebGL only');
    return false;
  },
  install(player, { shadows }) {
    const { mesh } = player;
    const original = { material: mesh.material, onBeforeRender: mesh.onBeforeRender };
    const instanced = Boolean(mesh.isInstancedMesh);
    const made = [];
    const setup = (m) => {
      // the clip after three.js's morphing, skinning, instancing and the material's own positionNode
      const own = Object.getPrototypeOf(m).setupPosition;
      m.setupPosition = function (builder) {
        const result = own.call(this, builder);
        playClip(player, { instanced });
        return result;
      };
      // WebGPURenderer's shadow pass draws with castShadowPositionNode (else the positionNode)
      const source = ORIGINAL.get(m);
      if (shadows) m.castShadowPositionNode = shadowPositionNode(player, { instanced });
      else m.castShadowPositionNode = source?.castShadowPositionNode ?? null;
      m.needsUpdate = true;
    };
    const make = (material) => {
      const m = nodeMaterial(material);
      made.push(m);
      setup(m);
      return m;
    };
    mesh.material = Array.isArray(mesh.material) ? mesh.material.map(make) : make(mesh.material);
    const before = original.onBeforeRender;
    // node materials draw with WebGPURenderer only: refuse another renderer at the first frame
    mesh.onBeforeRender = function (renderer, ...rest) {
      if (!isWebGPURenderer(renderer)) throw new Error(WEBGL_REFUSAL);
      return before.call(this, renderer, ...rest);
    };
    return {
      /** Give a clone of the mesh (mesh.clone()) the mesh's own materials back. */
      restoreOn(clone) {
        clone.material = original.material;
      },
      /** Rebuild the node graphs after a switch between GPU and CPU evaluation. */
      refresh() {
        for (const m of made) setup(m);
      },
      uninstall() {
        mesh.material = original.material;
        mesh.onBeforeRender = original.onBeforeRender;
        for (const m of made) m.dispose();
      },
    };
  },
};

/**
 * Play a decoded clip on mesh with WebGPURenderer: pdeanim/three's ClipPlayer (same options, same API) on
 * node materials. Not supported here: the pass option (the vertex stage evaluates).
 */
export class ClipPlayer extends BasePlayer {
  constructor(mesh, clip, options = {}) {
    super(mesh, clip, withLimit(options), webgpuBackend);
  }
}

/** One clip on every mesh under root with WebGPURenderer: pdeanim/three's ScenePlayer on node materials. */
export class ScenePlayer extends BaseScene {
  constructor(root, clip, options = {}) {
    super(root, clip, withLimit(options), webgpuBackend);
  }
}

/** Play a decoded clip on mesh with WebGPURenderer (see ClipPlayer); returns the player. */
export function attachClip(mesh, clip, options = {}) {
  return new ClipPlayer(mesh, clip, options);
}

/** Play a clip on every mesh under root with WebGPURenderer (see ScenePlayer); returns the player. */
export function attachClipToScene(root, clip, options = {}) {
  return new ScenePlayer(root, clip, options);
}
