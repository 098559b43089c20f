// three.js integration: play a pdeanim clip on an existing mesh, evaluated in the vertex shader (data
// textures + per-vertex attributes + per-frame uniforms), keeping the mesh's materials; CPU fallback.

import {
  BufferAttribute,
  DataTexture,
  FloatType,
  Matrix3,
  Matrix4,
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
import { createEvaluator } from './clip.js';
import { frameNormals, glslHeader, glslPassMain, gpuLayout, meshAttributes, timeUniforms } from './gpu.js';

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

/** A plain (not interleaved, not normalised) float32 copy of a 3-component attribute. */
function floatCopy(attr) {
  const out = new Float32Array(attr.count * 3);
  for (let i = 0; i < attr.count; i++) {
    out[i * 3] = attr.getX(i);
    out[i * 3 + 1] = attr.getY(i);
    out[i * 3 + 2] = attr.getZ(i);
  }
  return out;
}

function isPlainFloat(attr) {
  return !attr.isInterleavedBufferAttribute && !attr.normalized && attr.array instanceof Float32Array;
}

function toMatrix4(m) {
  if (!m) return new Matrix4();
  if (m.isMatrix4) return m.clone();
  return new Matrix4().fromArray(m);
}

/** Apply the affine matrix (elements, column-major) to positions (n * 3) into out. */
function transformPoints(e, src, out) {
  for (let i = 0; i < src.length; i += 3) {
    const x = src[i];
    const y = src[i + 1];
    const z = src[i + 2];
    out[i] = e[0] * x + e[4] * y + e[8] * z + e[12];
    out[i + 1] = e[1] * x + e[5] * y + e[9] * z + e[13];
    out[i + 2] = e[2] * x + e[6] * y + e[10] * z + e[14];
  }
  return out;
}

/** Apply the 3x3 normal matrix (elements, column-major) to normals (n * 3) and normalise, in place. */
function transformNormals(e, n) {
  for (let i = 0; i < n.length; i += 3) {
    const x = e[0] * n[i] + e[3] * n[i + 1] + e[6] * n[i + 2];
    const y = e[1] * n[i] + e[4] * n[i + 1] + e[7] * n[i + 2];
    const z = e[2] * n[i] + e[5] * n[i + 1] + e[8] * n[i + 2];
    const l = Math.hypot(x, y, z) || 1;
    n[i] = x / l;
    n[i + 1] = y / l;
    n[i + 2] = z / l;
  }
  return n;
}

/** Shared, mesh-independent state of a clip on the GPU and CPU: layout, textures, evaluator. */
export function clipResources(clip, options = {}) {
  // the renderer's limit when given (WebGL 2 guarantees only 2048), else 4096
  const limit = options.renderer?.capabilities?.maxTextureSize ?? 4096;
  const { maxTextureSize = limit, gpuMode = 'auto' } = options;
  const textureWidth = Math.min(options.textureWidth ?? 4096, maxTextureSize);
  const evaluator = createEvaluator(clip);
  const layout = gpuLayout(clip, {
    width: textureWidth,
    mode: gpuMode,
    evaluator: clip.kind === 'dynamic-pde' ? evaluator : null,
  });
  const gpuReason =
    layout.maxHeight > maxTextureSize
      ? `the clip needs a ${layout.maxHeight}-row data texture (limit ${maxTextureSize})`
      : null;
  const textures = Object.fromEntries(Object.entries(layout.textures).map(([k, t]) => [k, dataTexture(t)]));
  let lastT = null;
  let last = null;
  let pass = null;
  let passT = null;
  let version = 0; // bumped whenever the clip's state (table or uniforms) changes: the pass reruns then
  const res = {
    clip,
    layout,
    textures,
    gpuReason,
    evaluator,
    owned: 0,
    /**
     * The uniforms at t, and the per-curve table rewritten and marked for upload (once per distinct t, and
     * only when t moved to another segment or local time).
     */
    frame(t) {
      if (t !== lastT) {
        last = timeUniforms(layout, t);
        lastT = t;
        if (last.changed) {
          version++;
          if (textures.curve) textures.curve.needsUpdate = true;
        }
        if (pass) {
          pass.uniforms.pdeSeg.value = last.seg;
          pass.uniforms.pdeSinWt.value = last.sw;
          pass.uniforms.pdeCosWt.value = last.cw;
        }
      }
      return last;
    },
    /** The evaluation pass's output texture (created on first use). */
    positionTexture() {
      if (!pass) pass = makePass(layout, textures, last);
      return pass.target.texture;
    },
    /** Evaluate every clip vertex into the position texture, once per distinct t (nested render). */
    runPass(renderer) {
      if (!pass || passT === version) return;
      passT = version;
      const target = renderer.getRenderTarget();
      const xr = renderer.xr.enabled;
      renderer.xr.enabled = false;
      renderer.setRenderTarget(pass.target);
      renderer.render(pass.scene, pass.camera);
      renderer.setRenderTarget(target);
      renderer.xr.enabled = xr;
    },
    dispose() {
      for (const tex of Object.values(textures)) tex.dispose();
      if (pass) {
        pass.target.dispose();
        pass.material.dispose();
        pass.quad.geometry.dispose();
      }
    },
  };
  return res;
}

/** The evaluation pass: a full-screen quad whose fragments evaluate one clip vertex each. */
function makePass(layout, textures, current) {
  const uniforms = {
    pdeSeg: { value: current?.seg ?? 0 },
    pdeSinWt: { value: current?.sw ?? 0 },
    pdeCosWt: { value: current?.cw ?? 1 },
    pdeCurves: { value: layout.nCurves },
    pdeVertices: { value: layout.nVertices },
    pdeVertexTex: { value: textures.vertex },
    pdeFieldTex: { value: textures.field ?? null },
    pdeKnotTex: { value: textures.knot ?? null },
    pdeTangentTex: { value: textures.tangent ?? null },
    pdeCurveTex: { value: textures.curve ?? null },
    pdeAxis: { value: layout.axis ? [...layout.axis] : [1, 0, 0] },
    pdeBend: { value: layout.bend ? [...layout.bend] : [0, 1, 0] },
    pdeRotate: { value: Boolean(layout.rotate) },
  };
  const material = new ShaderMaterial({
    uniforms,
    vertexShader: 'void main() { gl_Position = vec4(position.xy, 0.0, 1.0); }',
    fragmentShader: `${glslHeader(layout, { stage: 'fragment' })}\n${glslPassMain()}`,
    depthTest: false,
    depthWrite: false,
  });
  const quad = new Mesh(new PlaneGeometry(2, 2), material);
  quad.frustumCulled = false;
  const scene = new Scene();
  scene.add(quad);
  const height = Math.max(1, Math.ceil(layout.nVertices / layout.width));
  const target = new WebGLRenderTarget(layout.width, height, {
    type: FloatType,
    format: RGBAFormat,
    minFilter: NearestFilter,
    magFilter: NearestFilter,
    depthBuffer: false,
    generateMipmaps: false,
  });
  return { uniforms, material, quad, scene, camera: new OrthographicCamera(), target };
}

/**
 * Play a decoded clip on mesh (a THREE.Mesh whose vertices are the clip's, or mapped to them by
 * options.vertexMap / a _pdeanim_vertex attribute). Returns a player: setTime(t), useGPU(bool), detach().
 * options: {gpu = true, vertexMap, clipToLocal (Matrix4 or 16 numbers, column-major: clip coordinates to
 * the mesh's local frame; default identity), renderer (its maxTextureSize bounds the data textures; with
 * float render targets the clip is evaluated in a pass before drawing), pass (force that either way),
 * textureWidth = 4096, maxTextureSize = renderer's or 4096, shadows = true,
 * frustumCulled = false, gpuMode = 'auto' | 'fields' | 'coefficients' (see gpuLayout), normals = 'frame'
 * (turned with each vertex's triangle: right lighting, 3 evaluations per vertex) | 'rest' (kept as they are:
 * one evaluation per vertex, for speed), resources (from clipResources, shared between meshes)}.
 */
export function attachClip(mesh, clip, options = {}) {
  const { gpu = true, shadows = true, frustumCulled = false, normals = 'frame' } = options;
  // the evaluation pass needs float render targets: used when the renderer is given and has them
  const pass =
    options.pass ??
    Boolean(options.renderer?.extensions?.has?.('EXT_color_buffer_float') && normals === 'frame');
  if (normals !== 'frame' && normals !== 'rest') throw new RangeError(`normals must be 'frame' or 'rest'`);
  const res = options.resources ?? clipResources(clip, options);
  res.owned++;
  const { layout, textures, gpuReason, evaluator } = res;
  const geometry = mesh.geometry;
  const vertexMap = resolveVertexMap(geometry, clip, options.vertexMap);
  if (!geometry.getAttribute('normal')) geometry.computeVertexNormals();
  const clipToLocal = toMatrix4(options.clipToLocal);
  const localToClip = clipToLocal.clone().invert();
  const normalToLocal = new Matrix3().getNormalMatrix(clipToLocal);
  const normalToClip = new Matrix3().getNormalMatrix(localToClip);

  // plain float32 attributes (dequantised, de-interleaved) that the CPU path can write into
  const original = { position: geometry.getAttribute('position'), normal: geometry.getAttribute('normal') };
  const restLocal = floatCopy(original.position);
  const restNormalsLocal = transformNormals(new Matrix3().elements, floatCopy(original.normal));
  for (const name of ['position', 'normal']) {
    if (!isPlainFloat(original[name])) {
      const copy = new BufferAttribute(floatCopy(original[name]), 3);
      geometry.setAttribute(name, copy);
    }
  }
  const posAttr = geometry.getAttribute('position');
  const nrmAttr = geometry.getAttribute('normal');
  const restClip = transformPoints(localToClip.elements, restLocal, new Float32Array(restLocal.length));
  const restNormalsClip = transformNormals(normalToClip.elements, Float32Array.from(restNormalsLocal));
  const attrs = meshAttributes({
    vertexMap,
    positions: restClip,
    normals: restNormalsClip,
    index: geometry.index ? geometry.index.array : null,
  });
  geometry.setAttribute('pdeVertex', new BufferAttribute(attrs.pdeVertex, 3));
  geometry.setAttribute('pdeNormalFrame', new BufferAttribute(attrs.pdeNormalFrame, 3));

  const uniforms = {
    pdeEnabled: { value: false },
    pdeSeg: { value: 0 },
    pdeCurves: { value: layout.nCurves },
    pdeSinWt: { value: 0 },
    pdeCosWt: { value: 1 },
    pdeVertices: { value: layout.nVertices },
    pdeClipToLocal: { value: clipToLocal },
    pdeNormalToLocal: { value: normalToLocal },
    pdeFieldTex: { value: textures.field ?? null },
    pdeVertexTex: { value: textures.vertex },
    pdeKnotTex: { value: textures.knot ?? null },
    pdeTangentTex: { value: textures.tangent ?? null },
    pdeCurveTex: { value: textures.curve ?? null },
    pdePosTex: { value: pass ? res.positionTexture() : null },
    pdeAxis: { value: layout.axis ? [...layout.axis] : [1, 0, 0] },
    pdeBend: { value: layout.bend ? [...layout.bend] : [0, 1, 0] },
    pdeRotate: { value: Boolean(layout.rotate) },
  };
  const header = glslHeader(layout, { normals, pass });
  // the header's defines vary with all of these (clips with spline items: another curve table, shader and a
  // tangent texture)
  const spline = layout.spline ? ':spline' : '';
  const key =
    `pdeanim:${layout.kind}:${layout.mode}:${layout.rigid}:${normals}:${layout.width}:${pass}${spline}`;
  const patch = (material) => {
    const m = material.clone();
    const previous = material.onBeforeCompile;
    m.onBeforeCompile = (shader, renderer) => {
      if (previous && previous !== material.constructor.prototype.onBeforeCompile) {
        previous.call(m, shader, renderer);
      }
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
  const hooks = [mesh.onBeforeRender, mesh.onBeforeShadow];
  if (pass) {
    // evaluate the clip's vertices before this mesh (or its shadow) is drawn: once per t for all meshes
    const before = hooks[0];
    mesh.onBeforeRender = function (renderer, ...rest) {
      if (onGPU) res.runPass(renderer);
      return before.call(this, renderer, ...rest);
    };
    if (hooks[1]) {
      const shadow = hooks[1];
      mesh.onBeforeShadow = function (renderer, ...rest) {
        if (onGPU) res.runPass(renderer);
        return shadow.call(this, renderer, ...rest);
      };
    }
  }
  const originalCulled = mesh.frustumCulled;
  mesh.frustumCulled = frustumCulled;
  // morph targets (e.g. of an animation GLB) would add their deltas to the clip's positions: off while
  // attached
  const originalInfluences = mesh.morphTargetInfluences ? [...mesh.morphTargetInfluences] : null;
  if (originalInfluences) mesh.morphTargetInfluences.fill(0);

  const clipPositions = new Float32Array(clip.nVertices * 3);
  const scratch = new Float32Array(vertexMap.length * 3);
  let onGPU = gpu && !gpuReason;
  let time = 0;

  function restoreRest() {
    posAttr.array.set(restLocal);
    nrmAttr.array.set(restNormalsLocal);
    posAttr.needsUpdate = true;
    nrmAttr.needsUpdate = true;
  }

  function writeCPU(positions) {
    for (let i = 0; i < vertexMap.length; i++) {
      const v = vertexMap[i] * 3;
      scratch[i * 3] = positions[v];
      scratch[i * 3 + 1] = positions[v + 1];
      scratch[i * 3 + 2] = positions[v + 2];
    }
    transformPoints(clipToLocal.elements, scratch, posAttr.array);
    posAttr.needsUpdate = true;
    if (normals === 'rest') return;
    frameNormals(positions, attrs, restNormalsClip, nrmAttr.array);
    transformNormals(normalToLocal.elements, nrmAttr.array);
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
    mesh,
    /** Whether the clip's vertices are evaluated in a pass before drawing (else in the vertex shader). */
    pass,
    resources: res,
    /** Why the GPU path is unavailable (null when it is available). */
    gpuUnavailableReason: gpuReason,
    get gpu() {
      return onGPU;
    },
    get time() {
      return time;
    },
    /**
     * Show the clip at normalised time t (GPU: a few uniforms; CPU: positions and normals rewritten).
     * evaluated: the clip's CPU positions at t when the caller already has them (shared between meshes).
     */
    setTime(t, evaluated = null) {
      const u = res.frame(t);
      time = t;
      uniforms.pdeSeg.value = u.seg;
      uniforms.pdeSinWt.value = u.sw;
      uniforms.pdeCosWt.value = u.cw;
      if (!onGPU) writeCPU(evaluated ?? evaluator.evaluate(t, clipPositions));
      return player;
    },
    /** Switch between GPU evaluation and the CPU fallback; returns whether the GPU is used. */
    useGPU(on) {
      onGPU = Boolean(on) && !gpuReason;
      uniforms.pdeEnabled.value = onGPU;
      if (onGPU) restoreRest();
      player.setTime(time);
      return onGPU;
    },
    /** The CPU-evaluated positions (V, 3) in clip vertex order at t (for checks; does not touch the mesh). */
    positions(t, out = new Float32Array(clip.nVertices * 3)) {
      return evaluator.evaluate(t, out);
    },
    /** Restore the mesh's materials and attributes; the textures are freed with their last user. */
    detach() {
      mesh.material = originalMaterial;
      [mesh.customDepthMaterial, mesh.customDistanceMaterial] = originalDepth;
      mesh.frustumCulled = originalCulled;
      if (originalInfluences) {
        mesh.morphTargetInfluences.splice(0, originalInfluences.length, ...originalInfluences);
      }
      restoreRest();
      geometry.setAttribute('position', original.position);
      geometry.setAttribute('normal', original.normal);
      geometry.deleteAttribute('pdeVertex');
      geometry.deleteAttribute('pdeNormalFrame');
      for (const m of [patched, mesh.customDepthMaterial].flat()) m?.dispose?.();
      [mesh.onBeforeRender, mesh.onBeforeShadow] = hooks;
      if (--res.owned === 0) res.dispose();
    },
  };
  player.useGPU(onGPU);
  return player;
}

/**
 * Play a clip on every mesh under root (e.g. gltf.scene from GLTFLoader): meshes in depth-first order take
 * consecutive ranges of the clip's vertices (the order pdeanim reads a glTF's primitives in, and writes its
 * frame and animation GLBs in), each placed with its transform relative to root so that the clip's
 * coordinates are root's. Returns a player over all meshes (one CPU evaluation per frame, shared textures).
 * options: as attachClip (without vertexMap/clipToLocal), plus filter(mesh) to skip meshes.
 */
export function attachClipToScene(root, clip, options = {}) {
  root.updateMatrixWorld(true);
  const rootInverse = root.matrixWorld.clone().invert();
  const meshes = [];
  root.traverse((o) => {
    if (o.isMesh && o.geometry?.getAttribute('position') && (!options.filter || options.filter(o))) {
      meshes.push(o);
    }
  });
  const total = meshes.reduce((n, m) => n + m.geometry.getAttribute('position').count, 0);
  if (total !== clip.nVertices) {
    throw new Error(`the meshes under root have ${total} vertices in all and the clip ${clip.nVertices}`);
  }
  const resources = clipResources(clip, options);
  let offset = 0;
  const players = meshes.map((mesh) => {
    const n = mesh.geometry.getAttribute('position').count;
    const vertexMap = Int32Array.from({ length: n }, (_, i) => offset + i);
    offset += n;
    const clipToLocal = rootInverse.clone().multiply(mesh.matrixWorld).invert();
    return attachClip(mesh, clip, { ...options, vertexMap, clipToLocal, resources });
  });
  const positions = new Float32Array(clip.nVertices * 3);
  let time = 0;
  const group = {
    clip,
    players,
    resources,
    gpuUnavailableReason: resources.gpuReason,
    get gpu() {
      return players.every((p) => p.gpu);
    },
    get time() {
      return time;
    },
    setTime(t) {
      time = t;
      const cpu = players.some((p) => !p.gpu);
      if (cpu) resources.evaluator.evaluate(t, positions);
      for (const p of players) p.setTime(t, cpu ? positions : null);
      return group;
    },
    useGPU(on) {
      for (const p of players) p.useGPU(on);
      group.setTime(time);
      return group.gpu;
    },
    positions(t, out = new Float32Array(clip.nVertices * 3)) {
      return resources.evaluator.evaluate(t, out);
    },
    detach() {
      for (const p of players) p.detach();
    },
  };
  return group;
}
