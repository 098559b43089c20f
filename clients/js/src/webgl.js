// The WebGL backend of ClipPlayer: materials patched with onBeforeCompile (the GLSL of glsl.js) and, with
// float render targets, an evaluation pass that evaluates each clip vertex once per t before drawing.

import {
  FloatType,
  Mesh,
  MeshDepthMaterial,
  MeshDistanceMaterial,
  NearestFilter,
  OrthographicCamera,
  PlaneGeometry,
  RGBAFormat,
  Scene,
  ShaderMaterial,
  WebGLRenderTarget,
} from 'three';
import { glslHeader, glslPassMain, patchVertexShader } from './glsl.js';

export const WEBGPU_REFUSAL =
  'pdeanim/three patches WebGL shaders (onBeforeCompile), which WebGPURenderer does not run: play the clip ' +
  "with pdeanim/webgpu's player (the same API on node materials: import { attachClip } from 'pdeanim/webgpu')";

/** The material each patched clone was made from (a mesh.clone() shares the patched one: patch its original). */
const ORIGINAL = new WeakMap();

/**
 * The evaluation pass of a player's time (FrameTables): a full-screen quad whose fragments evaluate one clip
 * vertex each, into a texture.
 */
class EvaluationPass {
  constructor(frames) {
    const layout = frames.resources.layout;
    this.frames = frames;
    this.material = new ShaderMaterial({
      uniforms: { ...frames.resources.uniforms, ...frames.uniforms },
      vertexShader: 'void main() { gl_Position = vec4(position.xy, 0.0, 1.0); }',
      fragmentShader: `${glslHeader(layout, { stage: 'fragment' })}\n${glslPassMain()}`,
      depthTest: false,
      depthWrite: false,
    });
    this.quad = new Mesh(new PlaneGeometry(2, 2), this.material);
    this.quad.frustumCulled = false;
    this.scene = new Scene();
    this.scene.add(this.quad);
    this.camera = new OrthographicCamera();
    const height = Math.max(1, Math.ceil(layout.nVertices / layout.width));
    this.target = new WebGLRenderTarget(layout.width, height, {
      type: FloatType,
      format: RGBAFormat,
      minFilter: NearestFilter,
      magFilter: NearestFilter,
      depthBuffer: false,
      generateMipmaps: false,
    });
    this.done = -1;
  }

  /** Bytes of the position texture. */
  get bytes() {
    return this.target.width * this.target.height * 16;
  }

  /** Evaluate every clip vertex into the position texture, once per state of the clip (nested render). */
  run(renderer) {
    if (this.done === this.frames.version) return;
    this.done = this.frames.version;
    const target = renderer.getRenderTarget();
    const xr = renderer.xr.enabled;
    renderer.xr.enabled = false;
    renderer.setRenderTarget(this.target);
    renderer.render(this.scene, this.camera);
    renderer.setRenderTarget(target);
    renderer.xr.enabled = xr;
  }

  dispose() {
    this.target.dispose();
    this.material.dispose();
    this.quad.geometry.dispose();
  }
}

/** Whether a renderer is a three.js WebGPURenderer (whatever its backend). */
export function isWebGPURenderer(renderer) {
  return Boolean(renderer?.isWebGPURenderer);
}

/**
 * The WebGL backend: check(renderer) refuses WebGPURenderer; usePass(options) says whether the evaluation
 * pass runs; install(player) patches the mesh's materials (and its depth materials) and hooks the pass.
 */
export const webglBackend = {
  name: 'webgl',
  /** Its shaders read the clip's crowd form (glsl.js PDEANIM_KNOTS): players at distinct times share the knots. */
  crowd: true,
  check(renderer) {
    if (isWebGPURenderer(renderer)) throw new Error(WEBGPU_REFUSAL);
  },
  /** The evaluation pass needs float render targets: used when the renderer is given and has them. */
  usePass(options, normals) {
    return options.pass ?? Boolean(options.renderer?.extensions?.has?.('EXT_color_buffer_float') && normals === 'frame');
  },
  install(player, { shadows }) {
    const { mesh, frames, uniforms } = player;
    if (player.pass) {
      frames.pass ??= new EvaluationPass(frames);
      uniforms.pdePosTex.value = frames.pass.target.texture;
    }
    const patch = (material) => patchMaterial(material, player);
    const original = {
      material: mesh.material,
      depth: mesh.customDepthMaterial,
      distance: mesh.customDistanceMaterial,
      onBeforeRender: mesh.onBeforeRender,
      onBeforeShadow: mesh.onBeforeShadow,
    };
    const patched = Array.isArray(mesh.material) ? mesh.material.map(patch) : patch(mesh.material);
    mesh.material = patched;
    if (shadows) {
      mesh.customDepthMaterial = patch(original.depth ?? new MeshDepthMaterial());
      mesh.customDistanceMaterial = patch(original.distance ?? new MeshDistanceMaterial());
    }
    const before = original.onBeforeRender;
    // a WebGPURenderer skips onBeforeCompile: refuse at the first frame rather than draw a still mesh
    // (named parameters, no rest array: this runs for every mesh of a crowd every frame)
    mesh.onBeforeRender = function (renderer, scene, camera, geometry, material, group) {
      if (isWebGPURenderer(renderer)) throw new Error(WEBGPU_REFUSAL);
      if (player.pass && player.gpu && uniforms.pdeEnabled.value) frames.pass.run(renderer);
      return before.call(this, renderer, scene, camera, geometry, material, group);
    };
    if (original.onBeforeShadow) {
      const shadow = original.onBeforeShadow;
      mesh.onBeforeShadow = function (renderer, object, camera, shadowCamera, geometry, material, group) {
        if (player.pass && player.gpu && uniforms.pdeEnabled.value) frames.pass.run(renderer);
        return shadow.call(this, renderer, object, camera, shadowCamera, geometry, material, group);
      };
    }
    const materials = [patched, mesh.customDepthMaterial, mesh.customDistanceMaterial].flat();
    return {
      /** Recompile after a switch between GPU and CPU evaluation (another shader variant). */
      /** Give a clone of the mesh (mesh.clone()) the mesh's own materials back. */
      restoreOn(clone) {
        clone.material = original.material;
        clone.customDepthMaterial = original.depth;
        clone.customDistanceMaterial = original.distance;
      },
      refresh() {
        for (const m of materials) m.needsUpdate = true;
      },
      uninstall() {
        mesh.material = original.material;
        mesh.customDepthMaterial = original.depth;
        mesh.customDistanceMaterial = original.distance;
        mesh.onBeforeRender = original.onBeforeRender;
        if (original.onBeforeShadow) mesh.onBeforeShadow = original.onBeforeShadow;
        for (const m of materials) m?.dispose?.();
      },
    };
  },
};

/** A clone of material whose vertex shader evaluates the clip (program variant per layout and mode). */
function patchMaterial(material, player) {
  material = ORIGINAL.get(material) ?? material;
  const m = material.clone();
  ORIGINAL.set(m, material);
  const previous = material.onBeforeCompile;
  const inherited = material.constructor.prototype.onBeforeCompile;
  m.onBeforeCompile = (shader, renderer) => {
    if (previous && previous !== inherited) previous.call(m, shader, renderer);
    Object.assign(shader.uniforms, player.uniforms);
    const { normals, pass, slots } = player;
    const knotWidth = player.crowd ? (player.resources.crowd?.table.width ?? 0) : 0;
    const header = glslHeader(player.layout, { normals, pass, cpu: !player.gpu, slots, knotWidth });
    shader.vertexShader = patchVertexShader(shader.vertexShader, header);
  };
  const prevKey = material.customProgramCacheKey?.bind(material);
  m.customProgramCacheKey = () => `${prevKey ? prevKey() : ''}|${player.programKey}`;
  return m;
}
