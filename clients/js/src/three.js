// three.js integration: play a pdeanim clip on an existing mesh, evaluated in the vertex shader (data
// textures + per-vertex attributes + per-frame uniforms), keeping the mesh's materials; CPU fallback.

import {
  DataTexture,
  FloatType,
  MeshDepthMaterial,
  MeshDistanceMaterial,
  NearestFilter,
  RGBAFormat,
  BufferAttribute,
} from 'three';
import { createEvaluator } from './clip.js';
import { frameNormals, glslHeader, gpuLayout, meshAttributes, timeUniforms } from './gpu.js';

const MAP_ATTRIBUTES = ['_pdeanim_vertex', '_PDEANIM_VERTEX'];

function dataTexture(t) {
  const tex = new DataTexture(t.data, t.width, t.height, RGBAFormat, FloatType);
  tex.minFilter = NearestFilter;
  tex.magFilter = NearestFilter;
  tex.generateMipmaps = false;
  tex.needsUpdate = true;
  return tex;
}

/** The clip vertex of every mesh vertex: options.vertexMap, a _pdeanim_vertex attribute, or the identity. */
function resolveVertexMap(geometry, clip, vertexMap) {
  const count = geometry.attributes.position.count;
  let map = vertexMap;
  if (!map) {
    const attr = MAP_ATTRIBUTES.map((n) => geometry.getAttribute(n)).find(Boolean);
    if (attr) map = Int32Array.from({ length: count }, (_, i) => Math.round(attr.getX(i)));
  }
  if (!map) {
    if (count !== clip.nVertices) {
      throw new Error(
        `the mesh has ${count} vertices and the clip ${clip.nVertices}: pass options.vertexMap ` +
          '(the clip vertex of each mesh vertex) or a _pdeanim_vertex attribute',
      );
    }
    map = Int32Array.from({ length: count }, (_, i) => i);
  }
  if (map.length !== count || map.some((v) => !(v >= 0 && v < clip.nVertices))) {
    throw new Error('vertexMap must give a clip vertex (0 .. nVertices - 1) for every mesh vertex');
  }
  return map;
}

function patchShader(shader, header) {
  const vs = shader.vertexShader;
  if (!vs.includes('#include <begin_vertex>') || !vs.includes('void main() {')) {
    throw new Error("pdeanim: the material's vertex shader has no <begin_vertex> chunk to patch");
  }
  shader.vertexShader = vs
    .replace('#include <common>', `#include <common>\n${header}`)
    .replace('void main() {', 'void main() {\n\tif (pdeEnabled) pdeCompute();')
    .replace(
      '#include <beginnormal_vertex>',
      '#include <beginnormal_vertex>\n\tif (pdeEnabled) objectNormal = pdeNormal;',
    )
    .replace(
      '#include <begin_vertex>',
      '#include <begin_vertex>\n\tif (pdeEnabled) transformed = pdePosition;',
    );
}

/**
 * Play a decoded clip on mesh (a THREE.Mesh whose vertices are the clip's, or mapped to them by
 * options.vertexMap / a _pdeanim_vertex attribute). Returns a player: setTime(t), useGPU(bool), detach().
 * options: {gpu = true, vertexMap, textureWidth = 4096, maxTextureSize = 4096, shadows = true,
 * frustumCulled = false, gpuMode = 'auto' | 'fields' | 'coefficients' (see gpuLayout)}.
 */
export function attachClip(mesh, clip, options = {}) {
  const {
    gpu = true,
    textureWidth = 4096,
    maxTextureSize = 4096,
    shadows = true,
    frustumCulled = false,
    gpuMode = 'auto',
  } = options;
  const geometry = mesh.geometry;
  const vertexMap = resolveVertexMap(geometry, clip, options.vertexMap);
  if (!geometry.getAttribute('normal')) geometry.computeVertexNormals();
  const posAttr = geometry.getAttribute('position');
  const nrmAttr = geometry.getAttribute('normal');
  const restPositions = Float32Array.from(posAttr.array);
  const restNormals = Float32Array.from(nrmAttr.array);
  const attrs = meshAttributes({
    vertexMap,
    positions: restPositions,
    normals: restNormals,
    index: geometry.index ? geometry.index.array : null,
  });
  geometry.setAttribute('pdeVertex', new BufferAttribute(attrs.pdeVertex, 3));
  geometry.setAttribute('pdeNormalFrame', new BufferAttribute(attrs.pdeNormalFrame, 3));

  const layout = gpuLayout(clip, { width: textureWidth, mode: gpuMode });
  const gpuReason =
    layout.maxHeight > maxTextureSize
      ? `the clip needs a ${layout.maxHeight}-row data texture (limit ${maxTextureSize})`
      : null;
  const textures = Object.fromEntries(Object.entries(layout.textures).map(([k, t]) => [k, dataTexture(t)]));
  const uniforms = {
    pdeEnabled: { value: false },
    pdeSeg: { value: 0 },
    pdeTau: { value: 0 },
    pdeCurves: { value: layout.nCurves },
    pdeRSeg: { value: 0 },
    pdeRTau: { value: 0 },
    pdeSinWt: { value: 0 },
    pdeCosWt: { value: 1 },
    pdeVertices: { value: layout.nVertices },
    pdeFieldTex: { value: textures.field ?? null },
    pdeVertexTex: { value: textures.vertex },
    pdeKnotTex: { value: textures.knot ?? null },
    pdeMuTex: { value: textures.mu ?? null },
    pdeRigidTex: { value: textures.rigid ?? null },
    pdeAxis: { value: layout.axis ? [...layout.axis] : [1, 0, 0] },
    pdeBend: { value: layout.bend ? [...layout.bend] : [0, 1, 0] },
    pdeRotate: { value: Boolean(layout.rotate) },
  };
  const header = glslHeader(layout);
  const key = `pdeanim:${layout.kind}:${layout.mode}:${layout.rigid}`;
  const patch = (material) => {
    const m = material.clone();
    const previous = material.onBeforeCompile;
    m.onBeforeCompile = (shader, renderer) => {
      if (previous && previous !== material.constructor.prototype.onBeforeCompile)
        previous.call(m, shader, renderer);
      Object.assign(shader.uniforms, uniforms);
      patchShader(shader, header);
    };
    const prevKey = material.customProgramCacheKey?.bind(material);
    m.customProgramCacheKey = () => `${prevKey ? prevKey() : ''}|${key}`;
    return m;
  };
  const originalMaterial = mesh.material;
  const patched = Array.isArray(originalMaterial) ? originalMaterial.map(patch) : patch(originalMaterial);
  const originalDepth = [mesh.customDepthMaterial, mesh.customDistanceMaterial];
  mesh.material = patched;
  if (shadows) {
    mesh.customDepthMaterial = patch(new MeshDepthMaterial());
    mesh.customDistanceMaterial = patch(new MeshDistanceMaterial());
  }
  const originalCulled = mesh.frustumCulled;
  mesh.frustumCulled = frustumCulled;

  const evaluator = createEvaluator(clip);
  const clipPositions = new Float32Array(clip.nVertices * 3);
  let onGPU = gpu && !gpuReason;
  let time = 0;

  function writeCPU(t) {
    evaluator.evaluate(t, clipPositions);
    const pos = posAttr.array;
    for (let i = 0; i < vertexMap.length; i++) {
      const v = vertexMap[i] * 3;
      pos[i * 3] = clipPositions[v];
      pos[i * 3 + 1] = clipPositions[v + 1];
      pos[i * 3 + 2] = clipPositions[v + 2];
    }
    frameNormals(clipPositions, attrs, restNormals, nrmAttr.array);
    posAttr.needsUpdate = true;
    nrmAttr.needsUpdate = true;
  }

  const player = {
    clip,
    layout,
    uniforms,
    textures,
    evaluator,
    vertexMap,
    attributes: attrs,
    /** Why the GPU path is unavailable (null when it is available). */
    gpuUnavailableReason: gpuReason,
    get gpu() {
      return onGPU;
    },
    get time() {
      return time;
    },
    /** Show the clip at normalised time t (GPU: a few uniforms; CPU: positions and normals rewritten). */
    setTime(t) {
      const u = timeUniforms(layout, t);
      time = t;
      uniforms.pdeSeg.value = u.seg;
      uniforms.pdeTau.value = u.tau;
      uniforms.pdeRSeg.value = u.rseg;
      uniforms.pdeRTau.value = u.rtau;
      uniforms.pdeSinWt.value = u.sw;
      uniforms.pdeCosWt.value = u.cw;
      if (!onGPU) writeCPU(t);
      return player;
    },
    /** Switch between GPU evaluation and the CPU fallback; returns whether the GPU is used. */
    useGPU(on) {
      onGPU = Boolean(on) && !gpuReason;
      uniforms.pdeEnabled.value = onGPU;
      if (onGPU) {
        posAttr.array.set(restPositions);
        nrmAttr.array.set(restNormals);
        posAttr.needsUpdate = true;
        nrmAttr.needsUpdate = true;
      }
      player.setTime(time);
      return onGPU;
    },
    /** The CPU-evaluated positions (V, 3) in clip vertex order at t (for checks; does not touch the mesh). */
    positions(t, out = new Float32Array(clip.nVertices * 3)) {
      return evaluator.evaluate(t, out);
    },
    /** Restore the mesh's materials and geometry and free the textures. */
    detach() {
      mesh.material = originalMaterial;
      [mesh.customDepthMaterial, mesh.customDistanceMaterial] = originalDepth;
      mesh.frustumCulled = originalCulled;
      posAttr.array.set(restPositions);
      nrmAttr.array.set(restNormals);
      posAttr.needsUpdate = true;
      nrmAttr.needsUpdate = true;
      geometry.deleteAttribute('pdeVertex');
      geometry.deleteAttribute('pdeNormalFrame');
      for (const m of [patched, mesh.customDepthMaterial].flat()) m?.dispose?.();
      for (const tex of Object.values(textures)) tex.dispose();
    },
  };
  player.useGPU(onGPU);
  return player;
}
