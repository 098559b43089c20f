// The GPU path without a browser: a line-by-line JS emulation of the vertex shader (src/gpu.js), fed the
// same textures, attributes and uniforms, agrees with the CPU evaluator on every fixture (those with items on
// the natural spline: four weights per item and a tangent texture); normals follow the surface; the three.js
// integration patches every built-in material and its CPU fallback works.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import * as THREE from 'three';
import {
  TIME_PDE,
  TIME_SPLINE,
  computeNormals,
  createEvaluator,
  decodeClip,
  decodeClipFile,
} from '../src/index.js';
import { naturalSplineTangents, splineWeights } from '../src/dynamic.js';
import { frameNormals, glslHeader, gpuLayout, meshAttributes, timeUniforms } from '../src/gpu.js';
import { attachClip, attachClipToScene } from '../src/three.js';
import { FIXTURES, fixtureParts, manifest, readBytes, retimed } from './helpers.mjs';

const man = manifest();
// the fixtures with items on the natural spline (rigid, looping and knot-basis ones among them)
const splineCases = man.cases.filter((x) => x.spline_items > 0);

/**
 * The four weighted terms' (knot, texture) of a clip with spline items: T_s and T_s+1 from the tangent
 * texture around P_s, P_s+1 from the field or knot texture.
 */
function splineTerms(layout, seg) {
  const T = layout.textures;
  const main = layout.mode === 'fields' ? T.field : T.knot;
  return [
    [seg, T.tangent],
    [seg, main],
    [seg + 1, main],
    [seg + 1, T.tangent],
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
  if (layout.spline) {
    // four weights per item on T_s, P_s, P_s+1, T_s+1, summed ((l + 0) + 1) + h, then + base
    const terms = splineTerms(layout, u.seg);
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
  if (layout.spline) {
    const terms = splineTerms(layout, u.seg);
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

/** A fixture's clip. */
function loadCase(c) {
  return decodeClipFile(readBytes(join(FIXTURES, c.clip)));
}

/** A fixture's clip with every item on the paper's time pairs (its spline items' constants 0: linear). */
function withoutSpline(c) {
  const { topology, coefficients } = fixtureParts(c);
  return decodeClip(topology, retimed(coefficients, { timeModel: () => TIME_PDE }));
}

for (const [c, mode] of man.cases.flatMap((x) =>
  x.kind === 'dynamic-pde'
    ? [
        [x, 'fields'],
        [x, 'coefficients'],
      ]
    : [[x, 'auto']],
)) {
  test(`emulated shader (${mode}) matches the CPU evaluator: ${c.name}`, () => {
    const clip = loadCase(c);
    // clips with spline items: the table carries four weights per item, on T_s, P_s, P_s+1, T_s+1, with a
    // tangent texture
    assert.equal(gpuLayout(clip).spline, c.spline_items > 0, c.name);
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
    man.cases.find((x) => x.motion === 'rigid' && x.looping && x.spline_items === 0),
    man.cases.find((x) => x.motion === 'rigid' && x.spline_items > 0),
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
  // clips with spline items carry four weights per item (tested in its own test below)
  const plainCases = man.cases.filter((x) => x.kind === 'dynamic-pde' && x.spline_items === 0);
  assert.ok(plainCases.length >= 5);
  for (const c of plainCases) {
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
 * The per-curve table of clips with spline items holds each item the CPU evaluator's four weights: the
 * segment's spline weights on T_s, P_s, P_s+1, T_s+1 for items on the spline, 0, phi0, phi1, 0 for the
 * others, then the rigid rows; it is rewritten only when the state moves.
 */
test('spline clips: the table holds each item its four weights (the CPU ones), then the rigid rows', () => {
  assert.ok(splineCases.some((c) => c.motion === 'rigid') && splineCases.some((c) => c.motion !== 'rigid'));
  for (const c of splineCases) {
    const clip = loadCase(c);
    const ev = createEvaluator(clip);
    const layout = gpuLayout(clip, { evaluator: ev }); // shared with the CPU path, as attachClip does
    assert.equal(layout.spline, true);
    assert.equal('tangents' in layout, false);
    assert.equal(layout.weightTexels, 4);
    assert.equal(layout.curveTexels, layout.rigid ? 7 : 4);
    assert.equal(layout.nSegments, clip.nSegments);
    const ref = createEvaluator(clip);
    const C = clip.nCurves;
    const K = layout.curveTexels * 4;
    const d = layout.textures.curve.data;
    let splineItems = 0;
    let prev = null;
    for (const t of [...c.t, ...c.t.map((x) => x + 1)]) {
      const u = timeUniforms(layout, t);
      ev.evaluate(t + 0.3); // the CPU path moving the shared evaluator must not disturb the table
      const s = ref.prepare(t);
      assert.equal(u.seg, s);
      const cubic = splineWeights(clip.segmentT, s, ref.loc[1], new Float64Array(4)).map(Math.fround);
      for (let cw = 0; cw < C * 3; cw++) {
        const o = Math.floor(cw / 3) * K + (cw % 3);
        const table = [0, 1, 2, 3].map((j) => d[o + j * 4]);
        assert.deepEqual(table, Array.from(ref.weights.subarray(cw * 4, cw * 4 + 4), Math.fround));
        if (clip.timeModel[cw] === TIME_SPLINE) {
          splineItems++;
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
      const loc = ref.locate(t);
      const key = `${loc[0]} ${loc[1]} ${layout.rigid ? loc[2] : ''}`;
      assert.equal(u.changed, key !== prev, `${c.name} t = ${t}`);
      prev = key;
    }
    assert.ok(splineItems > 0, c.name);
  }
});

test('spline clips: a tangent texture in the layout of the field or knot texture, of the same data', () => {
  for (const c of splineCases) {
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
    const want = new Float32Array(clip.knots.length);
    naturalSplineTangents(clip.segmentT, clip.knots, C * 12, want);
    assert.equal(coef.textures.tangent.height, coef.textures.knot.height);
    assert.deepEqual(coef.textures.tangent.data.subarray(0, want.length), want, c.name);
    assert.ok(coef.maxHeight >= coef.textures.tangent.height);
    // the same clip without spline items has none
    const plain = withoutSpline(c);
    assert.equal(gpuLayout(plain).textures.tangent, undefined);
    // mode auto counts the tangent texture: fields while both fit the budget
    const bytes = (S + 1) * V * 16;
    assert.equal(gpuLayout(clip, { fieldsBudget: 2 * bytes }).mode, 'fields');
    assert.equal(gpuLayout(clip, { fieldsBudget: 2 * bytes - 1 }).mode, 'coefficients');
    assert.equal(gpuLayout(plain, { fieldsBudget: bytes }).mode, 'fields');
    assert.equal(gpuLayout(plain, { fieldsBudget: bytes - 1 }).mode, 'coefficients');
  }
  for (const c of man.cases.filter((x) => !(x.spline_items > 0))) {
    assert.equal(gpuLayout(loadCase(c)).textures.tangent, undefined, c.name);
  }
});

test('spline clips: GLSL and three.js materials get the spline layout; other clips keep theirs', () => {
  for (const motion of ['rigid', 'displacement']) {
    const c = splineCases.find((x) => x.motion === motion);
    const clip = loadCase(c);
    const plainClip = withoutSpline(c);
    const rigid = motion === 'rigid';
    for (const mode of ['fields', 'coefficients']) {
      const header = glslHeader(gpuLayout(clip, { mode }));
      assert.match(header, /#define PDEANIM_SPLINE\n/);
      assert.match(header, new RegExp(`#define PDEANIM_CURVE_TEXELS ${rigid ? 7 : 4}\\n`));
      assert.match(header, /#define PDEANIM_WEIGHT_TEXELS 4\n/);
      assert.match(header, /#ifdef PDEANIM_SPLINE\nuniform highp sampler2D pdeTangentTex;\n#endif/);
      // the Catmull-Rom branch of earlier drafts is gone: no segment count, no define of its own
      assert.doesNotMatch(header, /PDEANIM_TANGENTS|pdeSegments|PDEANIM_OUTER_TEX/);
      // without spline items: 2 texels (5 rigid), no spline define
      const plain = glslHeader(gpuLayout(plainClip, { mode }));
      assert.doesNotMatch(plain, /#define PDEANIM_SPLINE/);
      assert.match(plain, new RegExp(`#define PDEANIM_CURVE_TEXELS ${rigid ? 5 : 2}\\n`));
      assert.match(plain, /#define PDEANIM_WEIGHT_TEXELS 2\n/);
    }
    const plainLayout = gpuLayout(plainClip);
    assert.equal(plainLayout.spline, false);
    assert.equal(plainLayout.curveTexels, rigid ? 5 : 2);
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
    assert.match(key, /pdeanim:dynamic-pde:fields:\w+:frame:\d+:\w+:spline$/);
    const other = attachClip(meshOf(plainClip, THREE.MeshStandardMaterial), plainClip);
    const plainKey = other.mesh.material.customProgramCacheKey();
    assert.match(plainKey, /pdeanim:dynamic-pde:fields:\w+:frame:\d+:\w+$/);
    assert.equal(key, `${plainKey}:spline`);
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
    // the GPU path and the CPU fallback agree on the positions it shows, with and without spline items
    agreesWithCpu(player, clip, 0.43, c.diagonal);
    agreesWithCpu(other, plainClip, 0.43, c.diagonal);
    player.detach();
    other.detach();
    passed.detach();
  }
});
