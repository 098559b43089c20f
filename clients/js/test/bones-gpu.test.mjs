// The GPU path of clips with bones (format 1.1) without a browser: a JS emulation of the shader's float32
// arithmetic (src/glsl.js pdeSkin / pdeEval), fed the same textures and uniforms, agrees with the CPU
// evaluator; a clip whose residual is zero has no residual tables; the shader variant and the player's
// program key say which layout they draw; ClipPlayer plays bone clips on the GPU and the CPU fallback.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import * as THREE from 'three';
import { join } from 'node:path';
import { createEvaluator, decodeClip, decodeClipFile } from '../src/index.js';
import { gpuLayout, gpuTables, textureBytes, timeUniforms } from '../src/gpu.js';
import { glslHeader } from '../src/glsl.js';
import { attachClip } from '../src/three.js';
import { FIXTURES, fixtureParts, manifest, withoutStream, readBytes, sampleTimes, takenTimes } from './helpers.mjs';
import { boneClipParts } from './bonehelpers.mjs';

// streamable clips (format 1.2) decode window by window: test/stream.test.mjs checks their tables
const man = withoutStream(manifest());
const byName = (name) => man.cases.find((c) => c.name === name);
const f = Math.fround;

function fetch(tex, i) {
  const w = tex.width;
  const o = (Math.floor(i / w) * w + (i % w)) * 4;
  return [...tex.data.subarray(o, o + 4)];
}

function dot4(a, b) {
  return f(f(f(f(a[0] * b[0]) + f(a[1] * b[1])) + f(a[2] * b[2])) + f(a[3] * b[3]));
}

/**
 * The shader's pdeEval(v) of a dynamic clip with bones, in float32 arithmetic (uniforms pdeBones = boneTexel,
 * pdeSkinOnly = skinOnly, pdeSkinTexel = skinTexel).
 */
function emulate(layout, v) {
  const T = layout.textures;
  const g = layout.gpuIndex[v];
  if (g < layout.nDirect) return fetch(T.frame, g).slice(0, 3);
  const skinOnly = g >= layout.skinOnly; // a curve without residual: 3 texels, skinning alone
  const stride = skinOnly ? 3 : layout.vertexTexels;
  const r = skinOnly ? layout.skinTexel + (g - layout.skinOnly) * 3 : (g - layout.nDirect) * stride;
  const head = fetch(T.vertex, r);
  const index = fetch(T.vertex, r + stride - 2);
  const weight = fetch(T.vertex, r + stride - 1);
  const x = [head[1], head[2], head[3], 1];
  let p = [0, 0, 0];
  for (let k = 0; k < 4; k++) {
    if (weight[k] === 0) continue;
    const b = layout.boneTexel + Math.round(index[k]) * 3;
    p = p.map((acc, i) => f(acc + f(weight[k] * dot4(fetch(T.frame, b + i), x))));
  }
  if (skinOnly) return p;
  const c = layout.nDirect + Math.round(head[0]) * layout.curveTexels;
  return p.map((acc, w) => f(acc + dot4(fetch(T.frame, c + w), fetch(T.vertex, r + 1 + w))));
}

const CASES = [
  ['fit-displacement-chord', { K: 2 }],
  ['fit-displacement-chord-loop', { K: 4, B: 5 }],
  ['synthetic-displacement-chord-spline', { K: 3, Sb: 6, angle: 3 }],
  ['synthetic-blend-displacement-paper-basis', { K: 2, zeroCurve: (c) => c % 3 === 1 }], // knot basis, some curves 0
];

for (const [name, options] of CASES) {
  for (const residual of [true, false]) {
    test(`bones ${JSON.stringify(options)} (residual ${residual}): the emulated float32 shader matches the CPU evaluator to 1e-6 of the diagonal: ${name}`, () => {
      const c = byName(name);
      const { topology, coefficients } = boneClipParts(c, { ...options, residual });
      const clip = decodeClip(topology, coefficients);
      const layout = gpuLayout(clip, { width: 64 }); // narrow: the 2D texel addressing is exercised
      assert.equal(layout.bones, true);
      assert.equal(layout.residual, residual);
      if (!residual) assert.equal(layout.skinOnly, 0, 'every vertex is skin-only');
      if (residual && options.zeroCurve) assert.ok(layout.skinOnly < clip.nVertices && layout.skinOnly > layout.nDirect);
      if (residual && !options.zeroCurve) assert.equal(layout.skinOnly, clip.nVertices);
      // the fitted fixtures have short curves: direct vertices, skinned on the CPU, are covered
      if (residual && name.startsWith('fit-')) assert.ok(layout.nDirect > 0);
      const ev = createEvaluator(clip);
      let worst = 0;
      for (const t of takenTimes(sampleTimes(clip.bones.segmentT, clip.looping), clip.looping)) {
        const cpu = ev.evaluate(t);
        timeUniforms(layout, t);
        for (let v = 0; v < clip.nVertices; v++) {
          const g = emulate(layout, v);
          for (let w = 0; w < 3; w++) worst = Math.max(worst, Math.abs(g[w] - cpu[v * 3 + w]));
        }
      }
      assert.ok(worst <= 1e-6 * c.diagonal, `${name}: ${worst / c.diagonal} of the diagonal`);
    });
  }
}

for (const c of man.cases.filter((x) => x.bones)) {
  test(`bone fixture ${c.name}: the emulated float32 shader matches the CPU evaluator to 1e-6 of the diagonal`, () => {
    const clip = decodeClipFile(readBytes(join(FIXTURES, c.clip)));
    const layout = gpuLayout(clip, { width: 64 });
    assert.equal(layout.residual, !c.bones.residual_zero);
    assert.equal(layout.vertexTexels, 6);
    if (c.bones.residual_zero) assert.equal(layout.skinOnly, 0);
    const ev = createEvaluator(clip);
    let worst = 0;
    for (const t of takenTimes(c.t, c.looping)) {
      const cpu = ev.evaluate(t);
      timeUniforms(layout, t);
      for (let v = 0; v < clip.nVertices; v++) {
        const g = emulate(layout, v);
        for (let w = 0; w < 3; w++) worst = Math.max(worst, Math.abs(g[w] - cpu[v * 3 + w]));
      }
    }
    assert.ok(worst <= 1e-6 * c.diagonal, `${c.name}: ${worst / c.diagonal} of the diagonal`);
  });
}

test('bones without a residual cost no residual tables: rest, indices and weights per vertex, B bone rows per frame', () => {
  const c = byName('fit-displacement-chord');
  const withRes = boneClipParts(c, { B: 3, residual: true });
  const noRes = boneClipParts(c, { B: 3, residual: false });
  const a = gpuTables(decodeClip(withRes.topology, withRes.coefficients));
  const b = gpuTables(decodeClip(noRes.topology, noRes.coefficients));
  assert.equal(b.nDirect, 0);
  assert.equal(b.skinOnly, 0);
  assert.equal(b.skinTexel, 0);
  assert.equal(b.boneTexel, 0);
  assert.equal(b.tangents, null);
  assert.equal(b.spline, false);
  assert.ok(b.textures.vertex.width * b.textures.vertex.height >= c.n_vertices * 3);
  assert.ok(b.textures.vertex.width * b.textures.vertex.height < c.n_vertices * 3 * 2 + 64);
  assert.ok(b.textures.frame.width * b.textures.frame.height < 3 * 3 + 64);
  assert.equal(a.vertexTexels, 6);
  assert.equal(a.skinOnly, c.n_vertices);
  assert.ok(textureBytes(b) < textureBytes(a), `${textureBytes(b)} vs ${textureBytes(a)} bytes`);
  // one shader for bone clips with and without residual (the uniforms say where the skin-only vertices are)
  assert.equal(glslHeader(a), glslHeader({ ...b, width: a.width }));
  assert.match(glslHeader(b), /#define PDEANIM_BONES/);
});

test('curves without residual in a bone clip cost no residual tables: their vertices are skin-only', () => {
  const c = byName('fit-displacement-chord-loop');
  const parts = fixtureParts(c);
  const half = boneClipParts(c, { B: 3, zeroCurve: (cv) => cv % 2 === 0 });
  const clip = decodeClip(half.topology, half.coefficients);
  const full = gpuTables(decodeClip(parts.topology, boneClipParts(c, { B: 3 }).coefficients));
  const t = gpuTables(clip);
  const zeroVertices = Array.from(clip.curveOf).filter((cv) => cv % 2 === 0).length;
  assert.equal(clip.nVertices - t.skinOnly, zeroVertices);
  // curves without residual have no GPU curve (no coefficients in the frame table) and no direct vertices
  for (let cv = 0; cv < clip.nCurves; cv++) if (cv % 2 === 0) assert.equal(t.gpuCurve[cv], -1);
  assert.ok(t.boneTexel < full.boneTexel);
  const vertexTexels = (tab) => tab.skinTexel + (clip.nVertices - tab.skinOnly) * 3;
  assert.equal(vertexTexels(t), (t.skinOnly - t.nDirect) * 6 + zeroVertices * 3);
  assert.ok(vertexTexels(t) < vertexTexels(full));
});

test('1.0 clips keep their GPU layout: 4 texels per vertex, no bone defines', () => {
  for (const x of man.cases.filter((y) => y.kind === 'dynamic-pde').slice(0, 4)) {
    const parts = fixtureParts(x);
    const layout = gpuTables(decodeClip(parts.topology, parts.coefficients));
    assert.equal(layout.bones, false);
    assert.equal(layout.vertexTexels, 4);
    assert.equal(layout.residual, true);
    const h = glslHeader(layout);
    assert.doesNotMatch(h, /#define PDEANIM_BONES/);
    assert.match(h, /#define PDEANIM_VERTEX_TEXELS 4/);
  }
});

test('ClipPlayer plays a bone clip: GPU uniforms and per-frame bone rows, CPU fallback positions, program keys', () => {
  const c = byName('fit-displacement-chord-loop');
  for (const residual of [true, false]) {
    const { topology, coefficients } = boneClipParts(c, { K: 4, B: 5, residual });
    const clip = decodeClip(topology, coefficients);
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(Float32Array.from(clip.rest), 3));
    geometry.setIndex(Array.from(clip.faces));
    const mesh = new THREE.Mesh(geometry, new THREE.MeshStandardMaterial());
    const player = attachClip(mesh, clip);
    assert.equal(player.uniforms.pdeBones.value, player.layout.boneTexel);
    assert.match(player.programKey, /:bones:/);
    assert.equal(player.uniforms.pdeSkinOnly.value, player.layout.skinOnly);
    assert.equal(player.uniforms.pdeSkinTexel.value, player.layout.skinTexel);
    player.setTime(0.3);
    const frame = player.layout.textures.frame.data;
    const rows = player.evaluator.bones.affine();
    for (let i = 0; i < rows.length; i++) assert.equal(frame[player.layout.boneTexel * 4 + i], f(rows[i]));
    player.useGPU(false);
    player.setTime(0.3);
    const want = createEvaluator(clip).evaluate(0.3);
    const got = geometry.getAttribute('pdeCpuPosition').array;
    for (let i = 0; i < want.length; i++) assert.ok(Math.abs(got[i] - want[i]) <= 1e-6 * c.diagonal);
    player.detach();
  }
});

test('a bone clip and its GPU tables survive a structured clone (what a Web Worker sends back)', () => {
  const c = byName('fit-displacement-chord');
  const { topology, coefficients } = boneClipParts(c, { K: 4, B: 5 });
  const clip = decodeClip(topology, coefficients);
  clip.gpuTables = gpuTables(clip, { width: 128 });
  const copy = structuredClone(clip);
  assert.deepEqual(copy.bones, clip.bones);
  const layout = gpuLayout(copy, { tables: copy.gpuTables });
  assert.equal(layout.textures, copy.gpuTables.textures);
  assert.equal(layout.vertexTexels, 6);
  const ev = createEvaluator(copy, copy.gpuTables.timeIndex);
  assert.deepEqual(Array.from(ev.evaluate(0.6)), Array.from(createEvaluator(clip).evaluate(0.6)));
  timeUniforms(layout, 0.6);
  const rows = ev.bones.affine();
  const frame = layout.textures.frame.data;
  for (let i = 0; i < rows.length; i++) assert.equal(frame[layout.boneTexel * 4 + i], Math.fround(rows[i]));
});
