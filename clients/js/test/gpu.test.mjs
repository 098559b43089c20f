// The GPU path without a browser: a JS emulation of the shader's float32 arithmetic (src/glsl.js), fed the
// same textures, attributes and uniforms, agrees with the CPU evaluator on every fixture to 1e-6 of the
// diagonal (those with items on the natural spline: four weights per item and a tangent texture); normals
// follow the surface; ClipPlayer patches every built-in material, its CPU fallback works, and a
// WebGPURenderer is refused with a reason.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import * as THREE from 'three';
import {
  TIME_PDE,
  computeNormals,
  createEvaluator,
  decodeClip,
  decodeClipFile,
} from '../src/index.js';
import { naturalSplineTangents, vertexBasis } from '../src/dynamic.js';
import { clipNormals, fittedWidth, frameNormals, gpuBytes, ringTable, gpuLayout, gpuTables, meshAttributes, timeUniforms } from '../src/gpu.js';
import { glslHeader, patchVertexShader } from '../src/glsl.js';
import { orthonormalBases } from '../src/orthobasis.js';
import { vertexRings } from '../src/geometry.js';
import { WEBGPU_REFUSAL, ClipPlayer, attachClip, attachClipToScene } from '../src/three.js';
import { FIXTURES, caseTolerance, fixtureParts, manifest, withoutStream, readBytes, retimed } from './helpers.mjs';

// streamable clips (format 1.2) decode window by window: test/stream.test.mjs checks their tables
const man = withoutStream(manifest());
// the fixtures with items on the natural spline (rigid, looping and knot-basis ones among them)
const splineCases = man.cases.filter((x) => x.spline_items > 0);
const f = Math.fround;

/** The times of a case the clip takes: any for looping clips, [0, 1] for the others. */
function inRange(c, times) {
  return c.looping ? times : times.filter((t) => t >= 0 && t <= 1);
}

/** A fixture's clip. */
function loadCase(c) {
  return decodeClipFile(readBytes(join(FIXTURES, c.clip)));
}

/** A fixture's clip with every item on the paper's time pairs (its spline items' constants 0: linear). */
function withoutSpline(c) {
  const { topology, coefficients } = fixtureParts(c);
  return decodeClip(topology, retimed(coefficients, { timeModel: () => TIME_PDE }));
}

/** texelFetch of texel i of a {data, width} texture, row-major as pdeFetch addresses it. */
function fetch(tex, i) {
  const w = tex.width;
  const o = (Math.floor(i / w) * w + (i % w)) * 4;
  return [...tex.data.subarray(o, o + 4)];
}

/** dot(a, b) of two vec4 in float32, as the GPU sums it. */
function dot4(a, b) {
  return f(f(f(f(a[0] * b[0]) + f(a[1] * b[1])) + f(a[2] * b[2])) + f(a[3] * b[3]));
}

/** The shader's pdeEval(v) in float32 arithmetic (after timeUniforms(layout, t) wrote the per-curve table). */
function emulate(layout, u, v) {
  const T = layout.textures;
  if (layout.kind === 'cyclic-spine') {
    const a = fetch(T.vertex, v * 3);
    const w = fetch(T.vertex, v * 3 + 1);
    const rl = fetch(T.vertex, v * 3 + 2)[0];
    let ca = 0;
    let cl = f(f(w[0] * f(u.sw)) + f(w[1] * f(u.cw)));
    if (layout.rotate) {
      const g = f(f(w[2] * f(u.sw)) + f(w[3] * f(u.cw)));
      const c = f(1 / f(Math.sqrt(f(1 + f(g * g)))));
      ca = f(f(f(c - 1) * a[3]) - f(f(g * c) * rl));
      cl = f(cl + f(f(f(g * c) * a[3]) + f(f(c - 1) * rl)));
    }
    return [0, 1, 2].map((k) => f(f(a[k] + f(ca * f(layout.axis[k]))) + f(cl * f(layout.bend[k]))));
  }
  // the GPU numbers the clip vertices: direct ones first (their positions in the per-frame table)
  const g = layout.gpuIndex[v];
  if (g < layout.nDirect) return fetch(T.frame, g).slice(0, 3);
  const r = (g - layout.nDirect) * 4;
  const head = fetch(T.vertex, r);
  const c = layout.nDirect + Math.round(head[0]) * layout.curveTexels;
  // the frame's coefficients of the curve (per coordinate a vec4) dotted with the vertex's basis row
  let p = [0, 1, 2].map((w) => f(head[1 + w] + dot4(fetch(T.frame, c + w), fetch(T.vertex, r + 1 + w))));
  if (layout.rigid) {
    const rows = [0, 1, 2].map((i) => fetch(T.frame, c + layout.coefficientTexels + i));
    p = rows.map((row) => f(dot4([row[0], row[1], row[2], 0], [...p, 0]) + row[3]));
  }
  return p;
}

/** The shader's positions (emulated from its uniforms and textures) at t are the CPU evaluator's. */
function agreesWithCpu(player, clip, t, diagonal) {
  player.setTime(t);
  const u = timeUniforms(player.layout, t);
  const cpu = createEvaluator(clip).evaluate(t);
  for (let v = 0; v < clip.nVertices; v++) {
    const g = emulate(player.layout, u, v);
    for (let w = 0; w < 3; w++) assert.ok(Math.abs(g[w] - cpu[v * 3 + w]) <= 1e-6 * diagonal);
  }
}

// (the bone fixtures' skinning: test/bones-gpu.test.mjs)
for (const c of man.cases.filter((x) => !x.bones)) {
  test(`emulated float32 shader matches the CPU evaluator to 1e-6 of the diagonal: ${c.name}`, () => {
    const clip = loadCase(c);
    const layout = gpuLayout(clip, { width: 64 }); // a narrow texture exercises the 2D texel addressing
    assert.equal(layout.spline, c.spline_items > 0, c.name);
    const ev = createEvaluator(clip);
    let worst = 0;
    let tol = 0;
    for (const t of inRange(c, c.t)) {
      const cpu = ev.evaluate(t);
      tol = Math.max(tol, caseTolerance(c, cpu)); // 1e-6 of the diagonal, plus float32 rounding of far coordinates
      const u = timeUniforms(layout, t);
      for (let v = 0; v < clip.nVertices; v++) {
        const g = emulate(layout, u, v);
        for (let w = 0; w < 3; w++) worst = Math.max(worst, Math.abs(g[w] - cpu[v * 3 + w]));
      }
    }
    // the orthonormal bases keep every term of the float32 sums below the values' scale (orthobasis.js)
    assert.ok(worst <= tol, `${c.name}: ${worst / c.diagonal} of the diagonal`);
  });
}

test('orthonormal bases: Q has orthonormal (or zero) columns per curve and coordinate, and Q R = B', () => {
  for (const c of man.cases.filter((x) => x.kind === 'dynamic-pde')) {
    const clip = loadCase(c);
    const { q, r } = orthonormalBases(clip);
    const B = vertexBasis(clip);
    for (let cv = 0; cv < clip.nCurves; cv++) {
      const verts = Array.from(clip.order.subarray(clip.offsets[cv], clip.offsets[cv + 1]));
      for (let w = 0; w < 3; w++) {
        const R = r.subarray((cv * 3 + w) * 16, (cv * 3 + w + 1) * 16);
        for (let i = 0; i < 4; i++) {
          for (let j = 0; j < 4; j++) {
            const g = verts.reduce((s, v) => s + q[v * 12 + w * 4 + i] * q[v * 12 + w * 4 + j], 0);
            if (i === j) assert.ok(Math.abs(g - 1) < 1e-6 || Math.abs(g) < 1e-12, `${c.name} ${g}`);
            else assert.ok(Math.abs(g) < 1e-6, `${c.name} Q'Q ${g}`);
          }
        }
        for (const v of verts) {
          for (let j = 0; j < 4; j++) {
            let qr = 0;
            for (let i = 0; i <= j; i++) qr += q[v * 12 + w * 4 + i] * R[i * 4 + j];
            const b = B[v * 12 + w * 4 + j];
            assert.ok(Math.abs(qr - b) <= 1e-6 * Math.max(1, Math.abs(b)), `${c.name}: ${qr} vs ${b}`);
          }
        }
      }
    }
  }
});

test('GPU tables are plain typed arrays (a worker can transfer them) and gpuLayout takes them back', () => {
  const clip = loadCase(man.cases.find((x) => x.motion === 'rigid'));
  const tables = gpuTables(clip, { width: 128 });
  for (const t of Object.values(tables.textures)) assert.ok(t.data instanceof Float32Array);
  assert.ok(tables.r instanceof Float64Array);
  const layout = gpuLayout(clip, { tables });
  assert.equal(layout.textures, tables.textures);
  // rows as long as the clip needs (a power of two), at most the width asked for
  assert.ok(tables.width <= 128 && Number.isInteger(Math.log2(tables.width)));
  const gpuCurves = tables.gpuCurve.filter((c) => c >= 0).length;
  const needed = {
    vertex: (clip.nVertices - tables.nDirect) * 4,
    frame: tables.nDirect + gpuCurves * tables.curveTexels,
    // the normals' rings (gpu.js ringTable): four values a texel
    ring: Math.ceil(ringTable(vertexRings(clip.faces, clip.rest), tables.gpuIndex).length / 4),
  };
  assert.equal(tables.width, fittedWidth(Math.max(needed.vertex, needed.frame, needed.ring), 128));
  for (const [k, t] of Object.entries(tables.textures)) assert.ok(t.width * t.height - Math.max(1, needed[k]) < t.width, k);
  assert.deepEqual(structuredClone(tables), tables);
});

test('frame normals are the area-weighted normals of the deformed surface (computeNormals)', () => {
  // fitted and cyclic clips (real surfaces); not fit-absolute-paper, whose fit folds the 42-vertex sphere
  // (recomputed normals flip there), nor the synthetic clips (random coefficients, no coherent surface)
  const real = man.cases.filter(
    (x) => (x.name.startsWith('fit-') && x.name !== 'fit-absolute-paper') || x.kind === 'cyclic-spine',
  );
  for (const c of real) {
    const clip = loadCase(c);
    const ev = createEvaluator(clip);
    const rest = ev.evaluate(0);
    const restNormals = computeNormals(rest, clip.faces);
    const map = Int32Array.from({ length: clip.nVertices }, (_, i) => i);
    const tables = gpuTables(clip);
    const attrs = meshAttributes({
      vertexMap: map,
      positions: rest,
      normals: restNormals,
      index: clip.faces,
      clipNormals: clipNormals(tables, clip.rest),
    });
    for (const t of [0.3, 0.8]) {
      const pos = ev.evaluate(t);
      const ring = clipNormals(tables, pos);
      const got = frameNormals(pos, attrs, restNormals, new Float32Array(pos.length), ring);
      const want = computeNormals(pos, clip.faces);
      let worst = 1;
      for (let i = 0; i < pos.length; i += 3)
        worst = Math.min(worst, got[i] * want[i] + got[i + 1] * want[i + 1] + got[i + 2] * want[i + 2]);
      // the same sums (the fixtures have no seam duplicates), in another order
      assert.ok(worst > 0.99999, `${c.name} t=${t}: worst cos ${worst}`);
    }
  }
});

const MATERIALS = [
  THREE.MeshStandardMaterial,
  THREE.MeshPhysicalMaterial,
  THREE.MeshLambertMaterial,
  THREE.MeshPhongMaterial,
  THREE.MeshBasicMaterial,
  THREE.MeshToonMaterial,
  THREE.MeshNormalMaterial,
  THREE.MeshMatcapMaterial,
];
const SHADERS = {
  MeshStandardMaterial: 'standard',
  MeshPhysicalMaterial: 'physical',
  MeshLambertMaterial: 'lambert',
  MeshPhongMaterial: 'phong',
  MeshBasicMaterial: 'basic',
  MeshToonMaterial: 'toon',
  MeshNormalMaterial: 'normal',
  MeshMatcapMaterial: 'matcap',
  MeshDepthMaterial: 'depth',
  MeshDistanceMaterial: THREE.ShaderLib.distanceRGBA ? 'distanceRGBA' : 'distance',
};

function meshOf(clip, Material) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(Float32Array.from(clip.rest), 3));
  g.setIndex(new THREE.BufferAttribute(Uint32Array.from(clip.faces), 1));
  return new THREE.Mesh(g, new Material({ color: 0x336699 }));
}


test('attachClip patches every built-in material (and the shadow materials) and keeps their settings', () => {
  const c = man.cases.find((x) => x.motion === 'rigid');
  const clip = loadCase(c);
  for (const Material of MATERIALS) {
    const mesh = meshOf(clip, Material);
    const original = mesh.material;
    const player = attachClip(mesh, clip);
    assert.ok(player instanceof ClipPlayer);
    assert.notEqual(mesh.material, original);
    assert.equal(mesh.material.type, original.type);
    for (const m of [mesh.material, mesh.customDepthMaterial, mesh.customDistanceMaterial]) {
      const shader = {
        vertexShader: THREE.ShaderLib[SHADERS[m.type]].vertexShader,
        fragmentShader: '',
        uniforms: {},
      };
      m.onBeforeCompile(shader, null);
      assert.match(shader.vertexShader, /if \(pdeEnabled\) pdeCompute\(\);/);
      // after morphing and skinning: the clip's vertex, mixed by the influence
      assert.match(shader.vertexShader, /skinning_vertex>\n\tif \(pdeEnabled\) transformed = mix\(transformed, pdePosition, pdeInfluence\);/);
      assert.ok(shader.uniforms.pdeFrameTex.value instanceof THREE.DataTexture);
      assert.match(m.customProgramCacheKey(), /pdeanim:dynamic-pde:true:/);
    }
    assert.equal(player.gpu, true);
    assert.equal(player.uniforms.pdeEnabled.value, true);
    player.detach();
    assert.equal(mesh.material, original);
    assert.equal(mesh.geometry.getAttribute('pdeVertex'), undefined);
  }
});

test('unknown options are refused (an ignored option would fail silently)', () => {
  const clip = loadCase(man.cases.find((x) => x.motion === 'rigid'));
  assert.throws(() => attachClip(meshOf(clip, THREE.MeshBasicMaterial), clip, { THREE }), /unknown option\(s\) THREE/);
  assert.throws(() => attachClip(meshOf(clip, THREE.MeshBasicMaterial), clip, { gpuMode: 'fields' }), TypeError);
});

test('a WebGPURenderer is refused with a reason: at attach when given, at the first frame otherwise', () => {
  const clip = loadCase(man.cases.find((x) => x.motion === 'rigid'));
  const webgpu = { isWebGPURenderer: true };
  assert.throws(() => attachClip(meshOf(clip, THREE.MeshBasicMaterial), clip, { renderer: webgpu }), {
    message: WEBGPU_REFUSAL,
  });
  const mesh = meshOf(clip, THREE.MeshBasicMaterial);
  attachClip(mesh, clip);
  assert.throws(() => mesh.onBeforeRender(webgpu, null, null, mesh.geometry, mesh.material, null), {
    message: WEBGPU_REFUSAL,
  });
});

test('setTime drives the uniforms; the CPU fallback fills its own attributes, the geometry is kept', () => {
  for (const c of [
    man.cases.find((x) => x.motion === 'rigid' && x.looping && x.spline_items === 0),
    man.cases.find((x) => x.motion === 'rigid' && x.spline_items > 0),
    man.cases.find((x) => x.kind === 'cyclic-spine'),
  ]) {
    const clip = loadCase(c);
    const mesh = meshOf(clip, THREE.MeshStandardMaterial);
    const rest = Float32Array.from(mesh.geometry.getAttribute('position').array);
    const player = attachClip(mesh, clip);
    player.setTime(0.4);
    const table = player.textures.frame ? Float32Array.from(player.textures.frame.image.data) : null;
    const version = player.textures.frame?.version;
    const u = timeUniforms(player.layout, 0.4);
    assert.equal(player.uniforms.pdeSeg.value, u.seg);
    assert.equal(player.uniforms.pdeSinWt.value, u.sw);
    if (table) {
      assert.deepEqual(Float32Array.from(player.textures.frame.image.data), table);
      player.setTime(0.4); // the same t: no new upload
      assert.equal(player.textures.frame.version, version);
      player.setTime(0.45);
      assert.ok(player.textures.frame.version > version);
    }
    const key = mesh.material.customProgramCacheKey();
    assert.equal(player.useGPU(false), false);
    assert.notEqual(mesh.material.customProgramCacheKey(), key); // another shader variant
    const shader = { vertexShader: THREE.ShaderLib.standard.vertexShader, fragmentShader: '', uniforms: {} };
    mesh.material.onBeforeCompile(shader, null);
    assert.match(shader.vertexShader, /#define PDEANIM_CPU/);
    player.setTime(0.4);
    const cpu = createEvaluator(clip).evaluate(0.4);
    assert.deepEqual(Array.from(mesh.geometry.getAttribute('pdeCpuPosition').array), Array.from(cpu));
    const n = mesh.geometry.getAttribute('pdeCpuNormal').array;
    for (let i = 0; i < n.length; i += 3) assert.ok(Math.abs(Math.hypot(n[i], n[i + 1], n[i + 2]) - 1) < 1e-5);
    assert.deepEqual(Float32Array.from(mesh.geometry.getAttribute('position').array), rest);
    player.useGPU(true);
    player.detach();
    assert.equal(mesh.geometry.getAttribute('pdeCpuPosition'), undefined);
  }
});

test('influence: 1 the clip alone, 0 the mesh as without it (evaluation off), between a mix', () => {
  const clip = loadCase(man.cases.find((x) => x.motion === 'rigid'));
  const player = attachClip(meshOf(clip, THREE.MeshStandardMaterial), clip);
  assert.equal(player.influence, 1);
  player.influence = 0.25;
  assert.equal(player.uniforms.pdeInfluence.value, 0.25);
  assert.equal(player.uniforms.pdeEnabled.value, true);
  player.influence = 0;
  assert.equal(player.uniforms.pdeEnabled.value, false);
  assert.throws(() => {
    player.influence = 1.5;
  }, RangeError);
});

test('clips that do not loop refuse t outside [0, 1] on the GPU path too; looping ones wrap', () => {
  const open = loadCase(man.cases.find((x) => x.kind === 'dynamic-pde' && !x.looping));
  const player = attachClip(meshOf(open, THREE.MeshBasicMaterial), open);
  assert.throws(() => player.setTime(1.5), /must lie in \[0, 1\]/);
  player.useGPU(false);
  assert.throws(() => player.setTime(-0.1), /must lie in \[0, 1\]/);
  const loop = loadCase(man.cases.find((x) => x.kind === 'dynamic-pde' && x.looping));
  const lp = attachClip(meshOf(loop, THREE.MeshBasicMaterial), loop);
  lp.setTime(0.3);
  const seg = lp.uniforms.pdeSeg.value;
  lp.setTime(2.3);
  assert.equal(lp.uniforms.pdeSeg.value, seg);
});

test('a mesh with split vertices plays through a vertex map', () => {
  const c = man.cases.find((x) => x.name === 'fit-displacement-chord');
  const clip = loadCase(c);
  // non-indexed geometry: every triangle corner is its own vertex, like a glTF primitive with hard edges
  const corners = Int32Array.from(clip.faces);
  const g = new THREE.BufferGeometry();
  const split = new Float32Array(corners.length * 3).map(
    (_, k) => clip.rest[corners[Math.floor(k / 3)] * 3 + (k % 3)],
  );
  g.setAttribute('position', new THREE.BufferAttribute(split, 3));
  assert.throws(() => attachClip(new THREE.Mesh(g, new THREE.MeshBasicMaterial()), clip), /vertexMap/);
  g.setAttribute('_pdeanim_vertex', new THREE.BufferAttribute(Float32Array.from(corners), 1));
  const mesh = new THREE.Mesh(g, new THREE.MeshBasicMaterial());
  const player = attachClip(mesh, clip, { gpu: false });
  player.setTime(0.7);
  const cpu = createEvaluator(clip).evaluate(0.7);
  const pos = g.getAttribute('pdeCpuPosition').array;
  for (let k = 0; k < corners.length; k++) {
    for (let w = 0; w < 3; w++) assert.equal(pos[k * 3 + w], cpu[corners[k] * 3 + w]);
  }
  assert.deepEqual(
    Array.from(player.attributes.pdeVertex.filter((_, i) => i % 3 === 0)),
    Array.from(corners),
  );
});

test('small renderer textures: narrow data textures, or the CPU fallback when they do not fit', () => {
  const clip = loadCase(man.cases.find((x) => x.name === 'fit-displacement-chord'));
  const narrow = attachClip(meshOf(clip, THREE.MeshBasicMaterial), clip, {
    renderer: { capabilities: { maxTextureSize: 8 } },
  });
  assert.ok(Object.values(narrow.layout.textures).every((t) => t.width <= 8));
  assert.match(narrow.gpuUnavailableReason, /limit 8\)/);
  assert.equal(narrow.gpu, false);
  const fits = attachClip(meshOf(clip, THREE.MeshBasicMaterial), clip, {
    renderer: { capabilities: { maxTextureSize: 64 } },
  });
  assert.equal(fits.gpu, true);
  assert.ok(Object.values(fits.layout.textures).every((t) => t.width <= 64 && t.height <= 64));
});

test("normals: 'rest' skips the neighbour evaluations and keeps the normals", () => {
  const clip = loadCase(man.cases.find((x) => x.name === 'fit-displacement-chord'));
  assert.match(glslHeader(gpuLayout(clip), { normals: 'rest' }), /#define PDEANIM_REST_NORMALS/);
  assert.doesNotMatch(glslHeader(gpuLayout(clip)), /#define PDEANIM_REST_NORMALS/);
  const mesh = meshOf(clip, THREE.MeshStandardMaterial);
  mesh.geometry.computeVertexNormals();
  const rest = Float32Array.from(mesh.geometry.getAttribute('normal').array);
  const player = attachClip(mesh, clip, { gpu: false, normals: 'rest' });
  assert.match(mesh.material.customProgramCacheKey(), /:rest:/);
  player.setTime(0.6);
  const got = mesh.geometry.getAttribute('pdeCpuNormal').array;
  for (let i = 0; i < got.length; i++) assert.ok(Math.abs(got[i] - rest[i]) < 1e-6);
  assert.throws(
    () => attachClip(meshOf(clip, THREE.MeshBasicMaterial), clip, { normals: 'smooth' }),
    RangeError,
  );
});

test('the GLSL declares what the patched chunks use; shaders without the chunks are refused', () => {
  const clip = loadCase(man.cases.find((x) => x.kind === 'cyclic-spine'));
  const header = glslHeader(gpuLayout(clip));
  assert.match(header, /#define PDEANIM_CYCLIC/);
  for (const name of ['pdeVertex', 'pdeNormalFrame', 'pdeVertexTex', 'pdeSinWt', 'pdeCompute', 'pdeInfluence']) {
    assert.ok(header.includes(name), name);
  }
  assert.throws(() => patchVertexShader('void main() { gl_Position = vec4(0.0); }', header), /skinning_vertex|common/);
});

/** Split a clip's mesh into meshes over consecutive vertex ranges (faces inside each range), under root. */
function splitScene(clip, cuts) {
  const root = new THREE.Group();
  root.position.set(0.5, -1, 2);
  root.rotation.set(0.3, -0.7, 0.2);
  const parent = new THREE.Group();
  parent.scale.set(2, 2, 2);
  parent.rotation.set(0, 1.1, 0);
  root.add(parent);
  root.updateMatrixWorld(true);
  const meshes = [];
  const bounds = [0, ...cuts, clip.nVertices];
  for (let k = 0; k + 1 < bounds.length; k++) {
    const [lo, hi] = [bounds[k], bounds[k + 1]];
    const mesh = new THREE.Mesh(new THREE.BufferGeometry(), new THREE.MeshStandardMaterial());
    mesh.position.set(k, 0.25 * k, -k);
    mesh.scale.set(1 + k, 0.5, 1);
    (k < 2 ? parent : root).add(mesh); // depth-first order = creation order
    root.updateMatrixWorld(true);
    // local positions = (root^-1 mesh.matrixWorld)^-1 clip positions, stored quantised for the first mesh
    const rel = root.matrixWorld.clone().invert().multiply(mesh.matrixWorld);
    const inv = rel.clone().invert();
    const local = new Float32Array((hi - lo) * 3);
    for (let v = lo; v < hi; v++) {
      const p = new THREE.Vector3().fromArray(clip.rest, v * 3).applyMatrix4(inv);
      p.toArray(local, (v - lo) * 3);
    }
    if (k === 0) {
      const scale = Math.max(...local.map(Math.abs));
      const q = Int16Array.from(local, (x) => Math.round((x / scale) * 32767));
      mesh.geometry.setAttribute('position', new THREE.BufferAttribute(q, 3, true));
      const s = new THREE.Matrix4().makeScale(scale, scale, scale);
      mesh.geometry.applyMatrix4(new THREE.Matrix4()); // keeps the quantised attribute
      mesh.matrixAutoUpdate = false;
      mesh.matrix.copy(mesh.matrix.clone().multiply(s));
    } else {
      mesh.geometry.setAttribute('position', new THREE.BufferAttribute(local, 3));
    }
    const faces = [];
    for (let f = 0; f < clip.faces.length; f += 3) {
      const tri = [clip.faces[f], clip.faces[f + 1], clip.faces[f + 2]];
      if (tri.every((v) => v >= lo && v < hi)) faces.push(...tri.map((v) => v - lo));
    }
    mesh.geometry.setIndex(faces);
    meshes.push(mesh);
  }
  root.updateMatrixWorld(true);
  return { root, meshes, bounds };
}


test('attachClipToScene places every mesh with its transform (quantised positions too)', () => {
  const c = man.cases.find((x) => x.name === 'fit-rigid-chord');
  const clip = loadCase(c);
  const { root, meshes, bounds } = splitScene(clip, [18, 30]);
  assert.ok(meshes[0].geometry.getAttribute('position').normalized);
  const player = attachClipToScene(root, clip, { gpu: false });
  assert.equal(player.players.length, 3);
  player.setTime(0.4);
  const cpu = createEvaluator(clip).evaluate(0.4);
  const rootInverse = root.matrixWorld.clone().invert();
  meshes.forEach((mesh, k) => {
    const rel = rootInverse.clone().multiply(mesh.matrixWorld);
    const pos = mesh.geometry.getAttribute('pdeCpuPosition');
    assert.ok(mesh.geometry.getAttribute('position').normalized || k > 0); // the mesh's own attribute kept
    for (let i = 0; i < pos.count; i++) {
      const p = new THREE.Vector3(pos.getX(i), pos.getY(i), pos.getZ(i)).applyMatrix4(rel);
      const v = bounds[k] + i;
      // float32 local coordinates through two affine maps: 1e-6 of the diagonal is ~10x the rounding
      assert.ok(p.distanceTo(new THREE.Vector3().fromArray(cpu, v * 3)) < 1e-6 * c.diagonal, `mesh ${k} v ${v}`);
    }
    // the GPU uniforms carry the same map
    const e = player.players[k].uniforms.pdeClipToLocal.value.clone().multiply(rel).elements;
    new THREE.Matrix4().elements.forEach((x, i) => assert.ok(Math.abs(e[i] - x) < 1e-9));
  });
  player.useGPU(true);
  assert.equal(player.gpu, true);
  assert.ok(player.gpuBytes > player.resources.textureBytes);
  player.detach();
  assert.ok(meshes[0].geometry.getAttribute('position').normalized);
});

test('meshes that share one geometry each get their own copy (their attributes differ)', () => {
  const clip = loadCase(man.cases.find((x) => x.name === 'fit-rigid-chord'));
  const n = clip.nVertices / 3;
  assert.ok(Number.isInteger(n));
  const { root, meshes } = splitScene(clip, [n, 2 * n]);
  meshes[2].geometry = meshes[1].geometry; // two meshes, one geometry (as GLTFLoader makes for one glTF mesh)
  const player = attachClipToScene(root, clip, { gpu: false });
  assert.notEqual(meshes[1].geometry, meshes[2].geometry);
  const first = (m) => m.geometry.getAttribute('pdeVertex').array[0];
  assert.deepEqual([first(meshes[1]), first(meshes[2])], [n, 2 * n]);
  player.detach();
});

test('normals of a transformed mesh are the clip-space normals turned into its frame', () => {
  const c = man.cases.find((x) => x.name === 'fit-displacement-chord');
  const clip = loadCase(c);
  const { root, meshes } = splitScene(clip, []);
  const mesh = meshes[0];
  mesh.geometry.computeVertexNormals();
  const player = attachClipToScene(root, clip, { gpu: false });
  player.setTime(0.55);
  const rel = root.matrixWorld.clone().invert().multiply(mesh.matrixWorld);
  const nm = new THREE.Matrix3().getNormalMatrix(rel);
  const nrm = mesh.geometry.getAttribute('pdeCpuNormal');
  const want = computeNormals(createEvaluator(clip).evaluate(0.55), clip.faces);
  let sum = 0;
  for (let i = 0; i < nrm.count; i++) {
    const n = new THREE.Vector3(nrm.getX(i), nrm.getY(i), nrm.getZ(i)).applyMatrix3(nm).normalize();
    sum += n.dot(new THREE.Vector3().fromArray(want, i * 3));
  }
  // as in the clip-space test above: the area-weighted normals, turned into the mesh's frame
  assert.ok(sum / nrm.count > 0.99999, `mean cos ${sum / nrm.count}`);
});

test('with a renderer the clip is evaluated in a pass before drawing, once per t', () => {
  const clip = loadCase(man.cases.find((x) => x.motion === 'rigid' && x.looping));
  const calls = [];
  const renderer = {
    capabilities: { maxTextureSize: 4096 },
    extensions: { has: (name) => name === 'EXT_color_buffer_float' },
    xr: { enabled: false },
    getRenderTarget: () => 'outer',
    setRenderTarget: (target) => calls.push(['target', target === 'outer' ? 'outer' : 'pass']),
    render: (scene) => calls.push(['render', scene.children.length]),
  };
  const mesh = meshOf(clip, THREE.MeshStandardMaterial);
  const ownHook = mesh.onBeforeRender;
  const player = attachClip(mesh, clip, { renderer });
  assert.equal(player.pass, true);
  assert.ok(player.uniforms.pdePosTex.value.isTexture);
  const shader = { vertexShader: THREE.ShaderLib.standard.vertexShader, fragmentShader: '', uniforms: {} };
  mesh.material.onBeforeCompile(shader, null);
  assert.match(shader.vertexShader, /#define PDEANIM_PASS/);
  player.setTime(0.3);
  mesh.onBeforeRender(renderer, null, null, mesh.geometry, mesh.material, null);
  mesh.onBeforeRender(renderer, null, null, mesh.geometry, mesh.material, null); // same t: no second pass
  assert.deepEqual(calls, [
    ['target', 'pass'],
    ['render', 1],
    ['target', 'outer'],
  ]);
  player.setTime(0.6);
  mesh.onBeforeShadow(renderer, null, null, null, mesh.geometry, mesh.material, null);
  assert.equal(calls.length, 6);
  player.useGPU(false); // the CPU path needs no pass
  player.setTime(0.9);
  mesh.onBeforeRender(renderer, null, null, mesh.geometry, mesh.material, null);
  assert.equal(calls.length, 6);
  player.detach();
  assert.equal(mesh.onBeforeRender, ownHook);
  assert.equal(
    attachClip(meshOf(clip, THREE.MeshBasicMaterial), clip, { renderer, normals: 'rest' }).pass,
    false,
  );
});

/**
 * The frame's coefficients of item i of curve c (4 numbers in its orthonormal basis), computed here
 * independently in float64: the CPU evaluator's weights (ref.prepare(t) made them) on the knots (and the
 * spline's tangents of the knots), then R.
 */
function referenceCoefficients(clip, ref, r, tangents, seg, i) {
  const C = clip.nCurves;
  const rk = (j) => {
    const k = clip.knots.subarray((j * C * 3 + i) * 4, (j * C * 3 + i) * 4 + 4);
    return [0, 1, 2, 3].map((row) => k.reduce((sum, x, col) => sum + r[i * 16 + row * 4 + col] * x, 0));
  };
  const at = (arr, j, k) => arr[(j * C * 3 + i) * 4 + k];
  const [p0, p1] = [rk(seg), rk(seg + 1)];
  return [0, 1, 2, 3].map((k) => {
    if (ref.spline !== null) {
      const [wl, w0, w1, wh] = ref.weights.subarray(i * 4, i * 4 + 4);
      const tl = tangents ? at(tangents, seg, k) : 0;
      const th = tangents ? at(tangents, seg + 1, k) : 0;
      return wl * tl + w0 * p0[k] + w1 * p1[k] + wh * th;
    }
    return ref.phi0[i] * p0[k] + ref.phi1[i] * p1[k];
  });
}

/** The natural-spline tangents of every knot's coefficients in the orthonormal bases (float64). */
function referenceTangents(clip, r) {
  const n = clip.knots.length;
  const rk = new Float64Array(n);
  for (let o = 0; o < n; o += 4) {
    const R = ((o / 4) % (clip.nCurves * 3)) * 16;
    for (let i = 0; i < 4; i++) for (let j = i; j < 4; j++) rk[o + i] += r[R + i * 4 + j] * clip.knots[o + j];
  }
  return naturalSplineTangents(clip.segmentT, rk, clip.nCurves * 12, new Float64Array(n));
}

test('the per-frame table: direct vertices their positions, then per GPU curve its coefficients (R times the weighted knots) and rigid rows', () => {
  const cases = man.cases.filter((x) => x.kind === 'dynamic-pde' && !x.bones);
  assert.ok(cases.length >= 5 && cases.some((x) => x.spline_items > 0) && cases.some((x) => x.motion === 'rigid'));
  let directSeen = 0;
  let gpuSeen = 0;
  for (const c of cases) {
    const clip = loadCase(c);
    const ev = createEvaluator(clip);
    const layout = gpuLayout(clip, { evaluator: ev }); // shared with the CPU path, as attachClip does
    assert.equal(layout.coefficientTexels, 3);
    assert.equal(layout.curveTexels, layout.rigid ? 6 : 3);
    assert.equal(layout.spline, c.spline_items > 0);
    // the knots stay on the CPU: the GPU holds the vertex records and one frame
    assert.deepEqual(Object.keys(layout.textures).sort(), ['frame', 'ring', 'vertex']);
    // direct vertices: those of curves with at most curveTexels vertices, numbered first
    const C = clip.nCurves;
    const length = (k) => clip.offsets[k + 1] - clip.offsets[k];
    let nDirect = 0;
    for (let k = 0; k < C; k++) if (length(k) <= layout.curveTexels) nDirect += length(k);
    assert.equal(layout.nDirect, nDirect, c.name);
    assert.deepEqual([...layout.gpuIndex].sort((a, b) => a - b), [...Array(clip.nVertices).keys()]);
    for (let v = 0; v < clip.nVertices; v++) {
      assert.equal(layout.gpuIndex[v] < nDirect, length(clip.curveOf[v]) <= layout.curveTexels);
    }
    directSeen += nDirect;
    gpuSeen += clip.nVertices - nDirect;
    const { r } = orthonormalBases(clip);
    const tangents = layout.spline ? referenceTangents(clip, r) : null;
    const ref = createEvaluator(clip);
    const K = layout.curveTexels * 4;
    const d = layout.textures.frame.data;
    let prev = null;
    for (const t of inRange(c, [...c.t, ...c.t.map((x) => x + 1)])) {
      const u = timeUniforms(layout, t);
      ev.evaluate(c.looping ? t + 0.3 : Math.min(t + 0.3, 1)); // the CPU path moving the shared evaluator must not disturb the table
      const cpu = ref.evaluate(t);
      const s = ref.prepare(t);
      assert.equal(u.seg, s);
      for (let v = 0; v < clip.nVertices; v++) {
        const g = layout.gpuIndex[v];
        if (g >= nDirect) continue;
        // placed on the CPU in float64: the CPU evaluator's positions, float32 rounding apart
        for (let w = 0; w < 3; w++) assert.ok(Math.abs(d[g * 4 + w] - cpu[v * 3 + w]) <= 1e-7 * c.diagonal, c.name);
      }
      for (let k = 0; k < C; k++) {
        const cg = layout.gpuCurve[k];
        assert.equal(cg < 0, length(k) <= layout.curveTexels);
        if (cg < 0) continue;
        const o = nDirect * 4 + cg * K;
        for (let w = 0; w < 3; w++) {
          const want = referenceCoefficients(clip, ref, r, tangents, s, k * 3 + w);
          const scale = Math.hypot(...want) + 1e-30;
          // float32 rounding (and the float32 tangents) apart
          for (let j = 0; j < 4; j++) assert.ok(Math.abs(d[o + w * 4 + j] - want[j]) <= 1e-6 * scale, `${c.name} t = ${t}`);
        }
        if (!layout.rigid) continue;
        for (let i = 0; i < 3; i++) {
          assert.equal(d[o + 12 + i * 4], Math.fround(ref.rot[k * 9 + i * 3]));
          assert.equal(d[o + 15 + i * 4], Math.fround(ref.trans[k * 3 + i]));
        }
      }
      const loc = ref.locate(t);
      const key = `${loc[0]} ${loc[1]} ${layout.rigid ? loc[2] : ''}`;
      assert.equal(u.changed, key !== prev, `${c.name} t = ${t}`);
      prev = key;
    }
  }
  assert.ok(directSeen > 0 && gpuSeen > 0, 'the fixtures have both kinds of vertices');
});

test('a t with the same segment and local time uploads nothing', () => {
  const c = man.cases.find((x) => x.name === 'fit-displacement-chord');
  const clip = loadCase(c);
  const player = attachClip(meshOf(clip, THREE.MeshStandardMaterial), clip);
  player.setTime(1);
  const version = player.textures.frame.version;
  player.setTime(1); // the same state
  assert.equal(player.textures.frame.version, version);
  player.setTime(0.5);
  assert.ok(player.textures.frame.version > version);
  player.detach();
});

test('spline clips: the tangents of the knots (in the orthonormal bases) are solved once per clip, on the CPU', () => {
  for (const c of splineCases) {
    const clip = loadCase(c);
    const layout = gpuLayout(clip, { width: 64 });
    const want = referenceTangents(clip, orthonormalBases(clip).r);
    assert.ok(layout.tangents instanceof Float32Array);
    // in the orthonormal bases (on the scale of the values), rounded to float32
    want.forEach((x, i) => assert.ok(Math.abs(layout.tangents[i] - x) <= 1e-6 * (1e-3 + Math.abs(x)), c.name));
    assert.equal(gpuLayout(withoutSpline(c)).tangents, null);
  }
  for (const c of man.cases.filter((x) => x.kind === 'dynamic-pde' && !(x.spline_items > 0))) {
    assert.equal(gpuLayout(loadCase(c)).tangents, null, c.name);
  }
});

test('spline clips: one shader for every time model (the CPU forms the coefficients); cache keys differ', () => {
  for (const motion of ['rigid', 'displacement']) {
    const c = splineCases.find((x) => x.motion === motion);
    const clip = loadCase(c);
    const plainClip = withoutSpline(c);
    const rigid = motion === 'rigid';
    const header = glslHeader(gpuLayout(clip));
    const plainLayout = gpuLayout(plainClip);
    const plain = glslHeader(plainLayout);
    assert.equal(header, plain);
    assert.match(header, new RegExp(`#define PDEANIM_CURVE_TEXELS ${rigid ? 6 : 3}\\n`));
    assert.match(header, /#define PDEANIM_COEFFICIENT_TEXELS 3\n/);
    // one player alone: no knot table (the crowd form's), no tangent textures, no define of the time model
    assert.doesNotMatch(header, /#define PDEANIM_KNOTS|pdeTangentTex|PDEANIM_SPLINE|PDEANIM_TANGENTS|pdeSegments/);
    assert.equal(plainLayout.spline, false);
    const mesh = meshOf(clip, THREE.MeshStandardMaterial);
    const player = attachClip(mesh, clip);
    const shader = { vertexShader: THREE.ShaderLib.standard.vertexShader, fragmentShader: '', uniforms: {} };
    mesh.material.onBeforeCompile(shader, null);
    assert.equal(shader.uniforms.pdeFrameTex.value, player.textures.frame);
    assert.equal(shader.uniforms.pdeKnotTex.value, null);
    assert.doesNotMatch(shader.vertexShader, /#define PDEANIM_KNOTS/);
    const key = mesh.material.customProgramCacheKey();
    assert.match(key, /pdeanim:dynamic-pde:\w+:true:frame:\d+:gpu$/);
    const other = attachClip(meshOf(plainClip, THREE.MeshStandardMaterial), plainClip);
    const plainKey = other.mesh.material.customProgramCacheKey();
    assert.match(plainKey, /pdeanim:dynamic-pde:\w+:false:frame:\d+:gpu$/);
    let scene = null;
    const renderer = {
      extensions: { has: (name) => name === 'EXT_color_buffer_float' },
      xr: { enabled: false },
      getRenderTarget: () => null,
      setRenderTarget: () => {},
      render: (x) => {
        scene = x;
      },
    };
    // (another decoded copy: one player alone, not in the crowd form of clip's two players)
    const passMesh = meshOf(clip, THREE.MeshStandardMaterial);
    const passed = attachClip(passMesh, loadCase(c), { renderer });
    assert.equal(passed.pass, true);
    passed.setTime(0.2);
    passMesh.onBeforeRender(renderer, null, null, passMesh.geometry, passMesh.material, null);
    const quad = scene.children[0].material;
    assert.equal(quad.uniforms.pdeFrameTex.value, passed.textures.frame);
    assert.match(quad.fragmentShader, /#define PDEANIM_CURVE_TEXELS/);
    // the GPU path and the CPU fallback agree on the positions it shows, with and without spline items
    agreesWithCpu(player, clip, 0.43, c.diagonal);
    agreesWithCpu(other, plainClip, 0.43, c.diagonal);
    player.detach();
    other.detach();
    passed.detach();
  }
});

/**
 * GPU memory against the download (docs/performance.md, JavaScript client): every fixture's textures,
 * evaluation pass and attributes on a mesh of its own topology stay under 8x the bytes of its two parts (the
 * service's download), as ClipPlayer.gpuBytes reports them.
 */
test('GPU bytes of every fixture stay under 8x its download (textures, pass, attributes)', () => {
  const renderer = {
    extensions: { has: (name) => name === 'EXT_color_buffer_float' },
    capabilities: { maxTextureSize: 4096 },
  };
  for (const c of man.cases) {
    const { topology, coefficients } = fixtureParts(c);
    const download = topology.byteLength + coefficients.byteLength;
    const clip = loadCase(c);
    const layout = gpuLayout(clip);
    const bytes = gpuBytes(layout);
    assert.ok(bytes <= 8 * download, `${c.name}: ${bytes} GPU bytes, ${(bytes / download).toFixed(1)}x its ${download}`);
    // the player reports the same figure once its pass exists
    const player = attachClip(meshOf(clip, THREE.MeshStandardMaterial), clip, { renderer });
    assert.equal(player.pass, true);
    assert.equal(player.gpuBytes, bytes, c.name);
    player.detach();
  }
});

test('the CPU evaluator takes the time index made with the GPU tables (in a worker) and evaluates the same', () => {
  for (const c of man.cases.filter((x) => x.kind === 'dynamic-pde').slice(0, 6)) {
    const clip = loadCase(c);
    clip.gpuTables = structuredClone(gpuTables(clip)); // as a worker transfers them
    const player = attachClip(meshOf(clip, THREE.MeshStandardMaterial), clip);
    assert.equal(player.evaluator.muIndex, clip.gpuTables.timeIndex.muIndex, c.name);
    const t = inRange(c, [0.37, 0.9])[0];
    assert.deepEqual(player.evaluator.evaluate(t), createEvaluator(clip).evaluate(t), c.name);
    player.detach();
  }
});
