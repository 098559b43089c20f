// The GPU path without a browser: a line-by-line JS emulation of the vertex shader (src/gpu.js), fed the
// same textures, attributes and uniforms, agrees with the CPU evaluator on every fixture; normals follow
// the surface; the three.js integration patches every built-in material and its CPU fallback works.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import * as THREE from 'three';
import { computeNormals, createEvaluator, decodeClip, decodeClipFile, hermiteWeights } from '../src/index.js';
import { naturalSplineTangents, splineWeights } from '../src/dynamic.js';
import { frameNormals, glslHeader, gpuLayout, meshAttributes, timeUniforms } from '../src/gpu.js';
import { attachClip, attachClipToScene } from '../src/three.js';
import {
  FIXTURES,
  coefficientsV4,
  manifest,
  readBytes,
  versionFiveCases,
  versionFourCases,
} from './helpers.mjs';

const man = manifest();
// version 4 clips (Catmull-Rom time tangents) and version 5 ones (natural-spline tangents) re-encoded from
// the version 2 and 3 fixtures (helpers.mjs)
const v4 = versionFourCases();
const v5 = versionFiveCases();

/**
 * The four weighted terms' (knot, texture) with time tangents: version 4 the knots lo(s), s, s+1, hi(s+1) of
 * the field or knot texture; version 5 (spline) T_s and T_s+1 from the tangent texture around P_s, P_s+1.
 */
function tangentTerms(layout, seg) {
  const T = layout.textures;
  const main = layout.mode === 'fields' ? T.field : T.knot;
  if (layout.spline) {
    return [
      [seg, T.tangent],
      [seg, main],
      [seg + 1, main],
      [seg + 1, T.tangent],
    ];
  }
  const sl = Math.max(seg - 1, 0);
  const sh = Math.min(seg + 2, layout.nSegments); // the pdeSegments uniform
  return [
    [sl, main],
    [seg, main],
    [seg + 1, main],
    [sh, main],
  ];
}

/** texelFetch of texel i of a {data, width} texture, row-major as pdeFetch addresses it. */
function fetch(tex, i) {
  const w = tex.width;
  const x = i % w;
  const y = Math.floor(i / w);
  const o = (y * w + x) * 4;
  return [...tex.data.subarray(o, o + 4)];
}

/** The shader's pdeEval(v) in JS (after timeUniforms(layout, t) wrote the per-curve table). */
function emulate(layout, u, v) {
  const T = layout.textures;
  const C = layout.nCurves;
  if (layout.kind === 'cyclic-spine') {
    const a = fetch(T.vertex, v * 3);
    const w = fetch(T.vertex, v * 3 + 1);
    const rl = fetch(T.vertex, v * 3 + 2)[0];
    let ca = 0;
    let cl = w[0] * u.sw + w[1] * u.cw;
    if (layout.rotate) {
      const g = w[2] * u.sw + w[3] * u.cw;
      const c = 1 / Math.sqrt(1 + g * g);
      ca = (c - 1) * a[3] - g * c * rl;
      cl += g * c * a[3] + (c - 1) * rl;
    }
    return [0, 1, 2].map((k) => a[k] + ca * layout.axis[k] + cl * layout.bend[k]);
  }
  const fields = layout.mode === 'fields';
  const K = layout.curveTexels;
  const head = fetch(T.vertex, fields ? v : v * 4);
  const c = Math.round(head[0]);
  const V = layout.nVertices;
  if (layout.tangents) {
    // four weights per item on the knots lo(s), s, s+1, hi(s+1) (version 5: on T_s, P_s, P_s+1, T_s+1),
    // summed ((l + 0) + 1) + h, then + base
    const terms = tangentTerms(layout, u.seg);
    const f = [0, 1, 2, 3].map((j) => fetch(T.curve, c * K + j));
    let p = [0, 1, 2].map((w) => {
      if (fields) {
        const sum = terms.reduce((acc, [j, tex], i) => acc + f[i][w] * fetch(tex, j * V + v)[w], 0);
        return head[1 + w] + sum;
      }
      const kn = terms.map(([j, tex]) => fetch(tex, (j * C + c) * 3 + w));
      const b = fetch(T.vertex, v * 4 + 1 + w);
      const dot = (k) => kn.reduce((a, kj, i) => a + f[i][w] * kj[k], 0) * b[k];
      return head[1 + w] + [0, 1, 2, 3].reduce((s, k) => s + dot(k), 0);
    });
    if (layout.rigid) {
      const r = [0, 1, 2].map((i) => fetch(T.curve, c * K + layout.weightTexels + i));
      p = r.map((row) => row[0] * p[0] + row[1] * p[1] + row[2] * p[2] + row[3]);
    }
    return p;
  }
  const f0 = fetch(T.curve, c * K);
  const f1 = fetch(T.curve, c * K + 1);
  let p = [0, 1, 2].map((w) => {
    if (fields) {
      return (
        head[1 + w] +
        f0[w] * fetch(T.field, u.seg * V + v)[w] +
        f1[w] * fetch(T.field, (u.seg + 1) * V + v)[w]
      );
    }
    const k0 = fetch(T.knot, (u.seg * C + c) * 3 + w);
    const k1 = fetch(T.knot, ((u.seg + 1) * C + c) * 3 + w);
    const b = fetch(T.vertex, v * 4 + 1 + w);
    return head[1 + w] + [0, 1, 2, 3].reduce((s, k) => s + (f0[w] * k0[k] + f1[w] * k1[k]) * b[k], 0);
  });
  if (layout.rigid) {
    const r = [2, 3, 4].map((i) => fetch(T.curve, c * K + i));
    p = r.map((row) => row[0] * p[0] + row[1] * p[1] + row[2] * p[2] + row[3]);
  }
  return p;
}

/** Sum over the 8 terms of |phi * knot * basis| per coordinate (the scale of float32 rounding on the GPU). */
function agreesWithCpu(player, clip, t, diagonal) {
  // the shader's positions (emulated from its uniforms and textures) at t are the CPU evaluator's
  player.setTime(t);
  const u = timeUniforms(player.layout, t);
  const cpu = createEvaluator(clip).evaluate(t);
  for (let v = 0; v < clip.nVertices; v++) {
    const g = emulate(player.layout, u, v);
    for (let w = 0; w < 3; w++) assert.ok(Math.abs(g[w] - cpu[v * 3 + w]) <= 1e-6 * diagonal);
  }
}

function termMagnitude(layout, u, v) {
  if (layout.mode !== 'coefficients') return [0, 0, 0];
  const T = layout.textures;
  const C = layout.nCurves;
  const c = Math.round(fetch(T.vertex, v * 4)[0]);
  if (layout.tangents) {
    const terms = tangentTerms(layout, u.seg);
    const f = [0, 1, 2, 3].map((j) => fetch(T.curve, c * layout.curveTexels + j));
    return [0, 1, 2].map((w) => {
      const b = fetch(T.vertex, v * 4 + 1 + w);
      let sum = 0;
      terms.forEach(([j, tex], i) => {
        const kn = fetch(tex, (j * C + c) * 3 + w);
        for (let k = 0; k < 4; k++) sum += Math.abs(f[i][w] * kn[k] * b[k]);
      });
      return sum;
    });
  }
  const f0 = fetch(T.curve, c * layout.curveTexels);
  const f1 = fetch(T.curve, c * layout.curveTexels + 1);
  return [0, 1, 2].map((w) => {
    const k0 = fetch(T.knot, (u.seg * C + c) * 3 + w);
    const k1 = fetch(T.knot, ((u.seg + 1) * C + c) * 3 + w);
    const b = fetch(T.vertex, v * 4 + 1 + w);
    return [0, 1, 2, 3].reduce(
      (s, k) => s + Math.abs(f0[w] * k0[k] * b[k]) + Math.abs(f1[w] * k1[k] * b[k]),
      0,
    );
  });
}

/** A fixture's clip, or a version 4 or 5 case's (decoded from its two parts). */
function loadCase(c) {
  if (c.coefficients) return decodeClip(c.topology, c.coefficients);
  return decodeClipFile(readBytes(join(FIXTURES, c.clip)));
}

for (const [c, mode] of [...man.cases, ...v4, ...v5].flatMap((x) =>
  x.kind === 'dynamic-pde' || x.coefficients
    ? [
        [x, 'fields'],
        [x, 'coefficients'],
      ]
    : [[x, 'auto']],
)) {
  test(`emulated shader (${mode}) matches the CPU evaluator: ${c.name}`, () => {
    const clip = loadCase(c);
    // version 4 clips: the table carries four weights per item, on knots lo(s), s, s+1, hi(s+1); version 5
    // ones on T_s, P_s, P_s+1, T_s+1, with a tangent texture
    if (c.coefficients) assert.ok(gpuLayout(clip).tangents, c.name);
    const spline = clip.tangentSpline === 'natural' && clip.tangents.includes(1);
    assert.equal(gpuLayout(clip).spline, spline, c.name);
    const layout = gpuLayout(clip, { width: 64, mode }); // a narrow texture exercises the 2D texel addressing
    const ev = createEvaluator(clip);
    // Mode "fields" holds the CPU path's float32 P_k: 1e-6 of the diagonal. Mode "coefficients" holds the
    // space basis in float32 (the CPU path multiplies it with the knots in float64): each of the 8 terms
    // knot * basis carries a relative rounding of 2^-24, so the bound per value is 1e-6 of the diagonal plus
    // 4 * 2^-24 times the sum of the terms' magnitudes (fitted clips' basis sums cancel: terms reach ~1e3
    // times the result).
    for (const t of c.t) {
      const cpu = ev.evaluate(t);
      const u = timeUniforms(layout, t);
      for (let v = 0; v < clip.nVertices; v++) {
        const g = emulate(layout, u, v);
        let mag = termMagnitude(layout, u, v);
        if (layout.rigid) mag = mag.map(() => Math.max(...mag)); // the rotation mixes the coordinates
        for (let w = 0; w < 3; w++) {
          const tol = 1e-6 * c.diagonal + 4 * 2 ** -24 * mag[w];
          assert.ok(
            Math.abs(g[w] - cpu[v * 3 + w]) <= tol,
            `t = ${t}, v = ${v}: ${g[w]} vs ${cpu[v * 3 + w]}`,
          );
        }
      }
    }
  });
}

test('frame-rotated normals follow the deformed surface', () => {
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
    const attrs = meshAttributes({
      vertexMap: map,
      positions: rest,
      normals: restNormals,
      index: clip.faces,
    });
    for (const t of [0.3, 0.8]) {
      const pos = ev.evaluate(t);
      const got = frameNormals(pos, attrs, restNormals, new Float32Array(pos.length));
      const want = computeNormals(pos, clip.faces);
      let sum = 0;
      for (let i = 0; i < pos.length; i += 3)
        sum += got[i] * want[i] + got[i + 1] * want[i + 1] + got[i + 2] * want[i + 2];
      // coarse test meshes (42 / ~200 vertices): one triangle's frame vs the area-weighted mean of the ring
      assert.ok(sum / clip.nVertices > 0.97, `${c.name} t=${t}: mean cos ${sum / clip.nVertices}`);
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
      assert.match(shader.vertexShader, /transformed = pdePosition;/);
      assert.ok(shader.uniforms.pdeFieldTex.value instanceof THREE.DataTexture);
      assert.ok(shader.uniforms.pdeCurveTex.value instanceof THREE.DataTexture);
      assert.match(m.customProgramCacheKey(), /pdeanim:dynamic-pde:fields:true/);
    }
    assert.equal(player.gpu, true);
    assert.equal(player.uniforms.pdeEnabled.value, true);
    player.detach();
    assert.equal(mesh.material, original);
    assert.equal(mesh.geometry.getAttribute('pdeVertex'), undefined);
  }
});

test('setTime drives the uniforms; the CPU fallback writes the evaluated positions and normals', () => {
  for (const c of [
    man.cases.find((x) => x.motion === 'rigid' && x.looping),
    man.cases.find((x) => x.kind === 'cyclic-spine'),
  ]) {
    const clip = loadCase(c);
    const mesh = meshOf(clip, THREE.MeshStandardMaterial);
    const player = attachClip(mesh, clip);
    player.setTime(0.4);
    const table = player.textures.curve ? Float32Array.from(player.textures.curve.image.data) : null;
    const version = player.textures.curve?.version;
    const u = timeUniforms(player.layout, 0.4);
    assert.equal(player.uniforms.pdeSeg.value, u.seg);
    assert.equal(player.uniforms.pdeSinWt.value, u.sw);
    if (table) {
      assert.deepEqual(Float32Array.from(player.textures.curve.image.data), table);
      player.setTime(0.4); // the same t: no new upload
      assert.equal(player.textures.curve.version, version);
      player.setTime(0.45);
      assert.ok(player.textures.curve.version > version);
    }
    assert.equal(player.useGPU(false), false);
    player.setTime(0.4);
    const cpu = createEvaluator(clip).evaluate(0.4);
    assert.deepEqual(Array.from(mesh.geometry.getAttribute('position').array), Array.from(cpu));
    const n = mesh.geometry.getAttribute('normal').array;
    for (let i = 0; i < n.length; i += 3)
      assert.ok(Math.abs(Math.hypot(n[i], n[i + 1], n[i + 2]) - 1) < 1e-5);
    player.useGPU(true);
    assert.deepEqual(Array.from(mesh.geometry.getAttribute('position').array), Array.from(clip.rest));
    player.detach();
  }
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
  const pos = g.getAttribute('position').array;
  for (let k = 0; k < corners.length; k++) {
    for (let w = 0; w < 3; w++) assert.equal(pos[k * 3 + w], cpu[corners[k] * 3 + w]);
  }
  assert.deepEqual(
    Array.from(player.attributes.pdeVertex.filter((_, i) => i % 3 === 0)),
    Array.from(corners),
  );
});

test('mode auto picks fields within the budget and coefficients above it', () => {
  const clip = loadCase(man.cases.find((x) => x.name === 'fit-displacement-chord'));
  assert.equal(gpuLayout(clip).mode, 'fields');
  assert.ok(gpuLayout(clip).textures.field);
  const small = gpuLayout(clip, { fieldsBudget: 100 });
  assert.equal(small.mode, 'coefficients');
  assert.ok(small.textures.knot && !small.textures.field);
  assert.match(glslHeader(gpuLayout(clip)), /#define PDEANIM_FIELDS/);
  assert.doesNotMatch(glslHeader(small), /#define PDEANIM_FIELDS/);
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
  assert.deepEqual(Float32Array.from(mesh.geometry.getAttribute('normal').array), rest);
  assert.throws(
    () => attachClip(meshOf(clip, THREE.MeshBasicMaterial), clip, { normals: 'smooth' }),
    RangeError,
  );
});

test('the GLSL header declares what the patched chunks use', () => {
  const clip = loadCase(man.cases.find((x) => x.kind === 'cyclic-spine'));
  const header = glslHeader(gpuLayout(clip));
  assert.match(header, /#define PDEANIM_CYCLIC/);
  for (const name of ['pdeVertex', 'pdeNormalFrame', 'pdeVertexTex', 'pdeSinWt', 'pdeCompute']) {
    assert.ok(header.includes(name), name);
  }
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
    const pos = mesh.geometry.getAttribute('position');
    assert.equal(pos.normalized, false);
    for (let i = 0; i < pos.count; i++) {
      const p = new THREE.Vector3(pos.getX(i), pos.getY(i), pos.getZ(i)).applyMatrix4(rel);
      const v = bounds[k] + i;
      // float32 local coordinates through two affine maps: 1e-6 of the diagonal is ~10x the rounding
      assert.ok(
        p.distanceTo(new THREE.Vector3().fromArray(cpu, v * 3)) < 1e-6 * c.diagonal,
        `mesh ${k} v ${v}`,
      );
    }
    // the GPU uniforms carry the same map
    const e = player.players[k].uniforms.pdeClipToLocal.value.clone().multiply(rel).elements;
    new THREE.Matrix4().elements.forEach((x, i) => assert.ok(Math.abs(e[i] - x) < 1e-9));
  });
  player.useGPU(true);
  assert.equal(player.gpu, true);
  player.detach();
  assert.ok(meshes[0].geometry.getAttribute('position').normalized); // the quantised attribute is back
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
  const nrm = mesh.geometry.getAttribute('normal');
  const want = computeNormals(createEvaluator(clip).evaluate(0.55), clip.faces);
  let sum = 0;
  for (let i = 0; i < nrm.count; i++) {
    const n = new THREE.Vector3(nrm.getX(i), nrm.getY(i), nrm.getZ(i)).applyMatrix3(nm).normalize();
    sum += n.dot(new THREE.Vector3().fromArray(want, i * 3));
  }
  // as in the clip-space test above: one triangle's frame against the ring average on a 42-vertex sphere
  assert.ok(sum / nrm.count > 0.97, `mean cos ${sum / nrm.count}`);
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

test('the per-curve table equals every item time pair and is rewritten only when the state moves', () => {
  // version 4 fixtures with tangents carry four knot weights per item (tested in its own test below)
  for (const c of man.cases.filter((x) => x.kind === 'dynamic-pde' && x.format_version < 4)) {
    const clip = loadCase(c);
    const ev = createEvaluator(clip);
    const layout = gpuLayout(clip, { evaluator: ev }); // shared with the CPU path, as attachClip does
    const ref = createEvaluator(clip);
    const C = clip.nCurves;
    const K = layout.curveTexels * 4;
    const d = layout.textures.curve.data;
    let prev = null;
    for (const t of [...c.t, ...c.t.map((x) => x + 1)]) {
      const u = timeUniforms(layout, t);
      ev.evaluate(t + 0.3); // the CPU path moving the shared evaluator must not disturb the table
      const s = ref.prepare(t); // the per-item evaluation (float64), rounded to float32 like the texture
      assert.equal(u.seg, s);
      for (let cw = 0; cw < C * 3; cw++) {
        const o = Math.floor(cw / 3) * K + (cw % 3);
        assert.equal(d[o], Math.fround(ref.phi0[cw]), `${c.name} t = ${t}`);
        assert.equal(d[o + 4], Math.fround(ref.phi1[cw]), `${c.name} t = ${t}`);
      }
      if (layout.rigid) {
        for (let k = 0; k < C; k++) {
          for (let i = 0; i < 3; i++) {
            assert.equal(d[k * K + 8 + i * 4], Math.fround(ref.rot[k * 9 + i * 3]));
            assert.equal(d[k * K + 11 + i * 4], Math.fround(ref.trans[k * 3 + i]));
          }
        }
      }
      const loc = ref.locate(t);
      const key = `${loc[0]} ${loc[1]} ${layout.rigid ? loc[2] : ''}`;
      assert.equal(u.changed, key !== prev, `${c.name} t = ${t}`);
      prev = key;
    }
  }
});

test('a t with the same segment and local time uploads nothing', () => {
  const c = man.cases.find((x) => x.name === 'fit-displacement-chord');
  const clip = loadCase(c);
  const player = attachClip(meshOf(clip, THREE.MeshStandardMaterial), clip);
  player.setTime(1.5);
  const version = player.textures.curve.version;
  player.setTime(2.5); // past the end of a clip that does not loop: clamped to the same state
  assert.equal(player.textures.curve.version, version);
  player.setTime(0.5);
  assert.ok(player.textures.curve.version > version);
  player.detach();
});

/**
 * The per-curve table of clips with time tangents holds each item the CPU evaluator's four weights: the
 * segment's cubic weights (weightsOf: Catmull-Rom's on four knots in version 4, the spline's on T_s, P_s,
 * P_s+1, T_s+1 in version 5) or 0, phi0, phi1, 0 off the cubic, then the rigid rows.
 */
function checkWeightTable(cases, weightsOf, spline) {
  for (const c of cases) {
    const clip = loadCase(c);
    const ev = createEvaluator(clip);
    const layout = gpuLayout(clip, { evaluator: ev }); // shared with the CPU path, as attachClip does
    assert.equal(layout.tangents, true);
    assert.equal(layout.spline, spline);
    assert.equal(layout.weightTexels, 4);
    assert.equal(layout.curveTexels, layout.rigid ? 7 : 4);
    assert.equal(layout.nSegments, clip.nSegments);
    const ref = createEvaluator(clip);
    const C = clip.nCurves;
    const K = layout.curveTexels * 4;
    const d = layout.textures.curve.data;
    let cubicItems = 0;
    for (const t of c.t) {
      const u = timeUniforms(layout, t);
      ev.evaluate(t + 0.3); // the CPU path moving the shared evaluator must not disturb the table
      const s = ref.prepare(t);
      assert.equal(u.seg, s);
      const cubic = weightsOf(clip.segmentT, s, ref.loc[1], new Float64Array(4)).map(Math.fround);
      for (let cw = 0; cw < C * 3; cw++) {
        const o = Math.floor(cw / 3) * K + (cw % 3);
        const table = [0, 1, 2, 3].map((j) => d[o + j * 4]);
        assert.deepEqual(table, Array.from(ref.weights.subarray(cw * 4, cw * 4 + 4), Math.fround));
        if (ref.cubic[s * C * 3 + cw] === 1) {
          cubicItems++;
          assert.deepEqual(table, Array.from(cubic), `${c.name} t = ${t}`);
        } else {
          assert.deepEqual(table, [0, Math.fround(ref.phi0[cw]), Math.fround(ref.phi1[cw]), 0]);
        }
      }
      if (layout.rigid) {
        for (let k = 0; k < C; k++) {
          for (let i = 0; i < 3; i++) {
            assert.equal(d[k * K + 16 + i * 4], Math.fround(ref.rot[k * 9 + i * 3]));
            assert.equal(d[k * K + 19 + i * 4], Math.fround(ref.trans[k * 3 + i]));
          }
        }
      }
    }
    assert.ok(cubicItems > 0, c.name);
  }
}

test('version 4: the per-curve table holds each item four knot weights (the CPU ones), then rigid rows', () => {
  checkWeightTable(v4, hermiteWeights, false);
});

test('version 4: GLSL and three.js materials get the tangents layout; other clips keep theirs', () => {
  for (const motion of ['rigid', 'displacement']) {
    const c = v4.find((x) => x.motion === motion);
    const clip = loadCase(c);
    const plainClip = loadCase(c.fixture);
    const rigid = motion === 'rigid';
    const layout = gpuLayout(clip);
    const header = glslHeader(layout);
    assert.match(header, /#define PDEANIM_TANGENTS/);
    assert.match(header, new RegExp(`#define PDEANIM_CURVE_TEXELS ${rigid ? 7 : 4}\\n`));
    assert.match(header, /#define PDEANIM_WEIGHT_TEXELS 4\n/);
    assert.match(header, /uniform int pdeSegments;/);
    // without tangents (versions 1-3, or version 4 with tangents all 0): 2 texels (5 rigid), no tangents
    const plain = gpuLayout(plainClip);
    assert.equal(plain.tangents, false);
    assert.equal(plain.curveTexels, rigid ? 5 : 2);
    assert.doesNotMatch(glslHeader(plain), /#define PDEANIM_TANGENTS/);
    assert.match(glslHeader(plain), new RegExp(`#define PDEANIM_CURVE_TEXELS ${rigid ? 5 : 2}\\n`));
    const zero = gpuLayout(decodeClip(c.topology, coefficientsV4(c.original)));
    assert.equal(zero.tangents, false);
    assert.equal(zero.curveTexels, rigid ? 5 : 2);
    // three.js: the segment count as a uniform, a program cache key of its own
    const mesh = meshOf(clip, THREE.MeshStandardMaterial);
    const player = attachClip(mesh, clip);
    assert.equal(player.uniforms.pdeSegments.value, clip.nSegments);
    const shader = { vertexShader: THREE.ShaderLib.standard.vertexShader, fragmentShader: '', uniforms: {} };
    mesh.material.onBeforeCompile(shader, null);
    assert.match(shader.vertexShader, /#define PDEANIM_TANGENTS/);
    assert.equal(shader.uniforms.pdeSegments.value, clip.nSegments);
    assert.match(mesh.material.customProgramCacheKey(), /pdeanim:dynamic-pde:fields:\w+:frame:\d+:\w+:tangents$/);
    const other = attachClip(meshOf(plainClip, THREE.MeshStandardMaterial), plainClip);
    assert.doesNotMatch(other.mesh.material.customProgramCacheKey(), /tangents/);
    // the GPU path and the CPU fallback agree on the positions it shows
    agreesWithCpu(player, clip, 0.43, c.diagonal);
    player.detach();
    other.detach();
  }
});

test('version 5: the table holds each item the spline weights on T_s, P_s, P_s+1, T_s+1 (the CPU ones)', () => {
  checkWeightTable(v5, splineWeights, true);
});

test('version 5: a tangent texture in the layout of the field or knot texture, the spline of its data', () => {
  for (const c of v5) {
    const clip = loadCase(c);
    const { nVertices: V, nCurves: C, nSegments: S } = clip;
    // mode "fields": per (knot, vertex) the evaluator's float32 tangent fields T xyz
    const fields = gpuLayout(clip, { width: 64, mode: 'fields' });
    const T = fields.evaluator.tangentFields;
    assert.equal(fields.textures.tangent.width, fields.textures.field.width);
    assert.equal(fields.textures.tangent.height, fields.textures.field.height);
    for (let i = 0; i < (S + 1) * V; i++) {
      assert.deepEqual(fetch(fields.textures.tangent, i), [...T.subarray(i * 3, i * 3 + 3), 0], c.name);
    }
    // mode "coefficients": per (knot, curve, coordinate) the spline's tangents of the 4 knot coefficients
    const coef = gpuLayout(clip, { width: 64, mode: 'coefficients' });
    const want = naturalSplineTangents(clip.segmentT, clip.knots, C * 12, new Float32Array(clip.knots.length));
    assert.equal(coef.textures.tangent.height, coef.textures.knot.height);
    assert.deepEqual(coef.textures.tangent.data.subarray(0, want.length), want, c.name);
    assert.ok(coef.maxHeight >= coef.textures.tangent.height);
    // version 4 and plain clips have none
    assert.equal(gpuLayout(loadCase(c.fixture)).textures.tangent, undefined);
    // mode auto counts the tangent texture: fields while both fit the budget
    const bytes = (S + 1) * V * 16;
    assert.equal(gpuLayout(clip, { fieldsBudget: 2 * bytes }).mode, 'fields');
    assert.equal(gpuLayout(clip, { fieldsBudget: 2 * bytes - 1 }).mode, 'coefficients');
    const c4 = v4.find((x) => x.fixture.name === c.fixture.name);
    assert.equal(gpuLayout(loadCase(c4), { fieldsBudget: bytes }).mode, 'fields');
  }
  for (const c of v4) assert.equal(gpuLayout(loadCase(c)).textures.tangent, undefined);
});

test('version 5: GLSL and three.js materials get the spline layout, another program than version 4', () => {
  for (const motion of ['rigid', 'displacement']) {
    const c = v5.find((x) => x.motion === motion);
    const c4 = v4.find((x) => x.fixture.name === c.fixture.name);
    const clip = loadCase(c);
    const clip4 = loadCase(c4);
    const rigid = motion === 'rigid';
    for (const mode of ['fields', 'coefficients']) {
      const header = glslHeader(gpuLayout(clip, { mode }));
      assert.match(header, /#define PDEANIM_TANGENTS\n#define PDEANIM_SPLINE\n/);
      assert.match(header, new RegExp(`#define PDEANIM_CURVE_TEXELS ${rigid ? 7 : 4}\\n`));
      assert.match(header, /#define PDEANIM_WEIGHT_TEXELS 4\n/);
      assert.match(header, /uniform highp sampler2D pdeTangentTex;\n#define PDEANIM_OUTER_TEX pdeTangentTex/);
      // version 4: the same weights layout, the knot or field texture for all four terms
      const header4 = glslHeader(gpuLayout(clip4, { mode }));
      assert.match(header4, /#define PDEANIM_TANGENTS\n/);
      assert.doesNotMatch(header4, /#define PDEANIM_SPLINE/);
    }
    // version 5 with tangents all 0: the plain layout
    const zeroCoef = coefficientsV4(c.original, { version: 5, segmentT: c.segmentT });
    const zero = gpuLayout(decodeClip(c.topology, zeroCoef));
    assert.equal(zero.tangents, false);
    assert.equal(zero.spline, false);
    assert.equal(zero.textures.tangent, undefined);
    // three.js: the tangent texture as a uniform, a program cache key of its own
    const mesh = meshOf(clip, THREE.MeshStandardMaterial);
    const player = attachClip(mesh, clip);
    assert.equal(player.uniforms.pdeTangentTex.value, player.textures.tangent);
    assert.ok(player.textures.tangent.isDataTexture);
    const shader = { vertexShader: THREE.ShaderLib.standard.vertexShader, fragmentShader: '', uniforms: {} };
    mesh.material.onBeforeCompile(shader, null);
    assert.match(shader.vertexShader, /#define PDEANIM_SPLINE/);
    assert.equal(shader.uniforms.pdeTangentTex.value, player.textures.tangent);
    const key = mesh.material.customProgramCacheKey();
    assert.match(key, /pdeanim:dynamic-pde:fields:\w+:frame:\d+:\w+:tangents:spline$/);
    const other = attachClip(meshOf(clip4, THREE.MeshStandardMaterial), clip4);
    const key4 = other.mesh.material.customProgramCacheKey();
    assert.match(key4, /:tangents$/);
    assert.notEqual(key, key4);
    assert.equal(other.uniforms.pdeTangentTex.value, null);
    // the evaluation pass gets the tangent texture too
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
    const passMesh = meshOf(clip, THREE.MeshStandardMaterial);
    const passed = attachClip(passMesh, clip, { renderer });
    assert.equal(passed.pass, true);
    passed.setTime(0.2);
    passMesh.onBeforeRender(renderer, null, null, passMesh.geometry, passMesh.material, null);
    const quad = scene.children[0].material;
    assert.equal(quad.uniforms.pdeTangentTex.value, passed.textures.tangent);
    assert.ok(quad.uniforms.pdeTangentTex.value.isDataTexture);
    assert.match(quad.fragmentShader, /#define PDEANIM_SPLINE/);
    // the GPU path and the CPU fallback agree on the positions it shows
    agreesWithCpu(player, clip, 0.43, c.diagonal);
    player.detach();
    other.detach();
    passed.detach();
  }
});
