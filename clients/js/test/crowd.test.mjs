// Many players of one clip: one data texture per clip whatever the number of players (reference-counted,
// freed with the last one), each player its own time (per-frame table, uniforms) and patched materials,
// clone() of a playing mesh or scene, and instanced crowds (InstancedMesh, a time offset per instance: one
// per-frame table per distinct offset, in one texture). Positions are checked through a float32 emulation of
// the shader's reads (as gpu.test.mjs does) against the CPU evaluator.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import * as THREE from 'three';
import { createEvaluator, decodeClipFile } from '../src/index.js';
import { gpuLayout, gpuTables, timeUniforms } from '../src/gpu.js';
import { rigidTimePair } from '../src/basis.js';
import { rodrigues } from '../src/dynamic.js';
import { ClipPlayer, ClipResources, attachClip, attachClipToScene } from '../src/three.js';
import { webglBackend } from '../src/webgl.js';
import { FIXTURES, manifest, readBytes } from './helpers.mjs';

const man = manifest();
const f = Math.fround;
const byName = (name) => man.cases.find((c) => c.name === name);

function loadCase(c) {
  return decodeClipFile(readBytes(join(FIXTURES, c.clip)));
}

function geometryOf(clip) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(Float32Array.from(clip.rest), 3));
  g.setIndex(new THREE.BufferAttribute(Uint32Array.from(clip.faces), 1));
  return g;
}

function meshOf(clip) {
  return new THREE.Mesh(geometryOf(clip), new THREE.MeshStandardMaterial({ color: 0x336699 }));
}

/** Texel i of a float RGBA texture (data, rows of width), from texel base on (a crowd's slot). */
function fetch(data, width, i) {
  const o = (Math.floor(i / width) * width + (i % width)) * 4;
  return [...data.subarray(o, o + 4)];
}

function dot4(a, b) {
  return f(f(f(f(a[0] * b[0]) + f(a[1] * b[1])) + f(a[2] * b[2])) + f(a[3] * b[3]));
}

/**
 * The shader's pdeEval(v) in float32 for a dynamic clip without bones, reading the player's textures as the
 * GPU does: the shared vertex texture, and the per-frame texture from texel base (slot * pdeSlotTexels); in
 * the clip's crowd form (players at distinct times) the shared knot table and the player's time row (slot).
 */
function emulate(player, v, base = 0) {
  if (player.crowd) return emulateCrowd(player, v, base / player.uniforms.pdeSlotTexels.value);
  const L = player.layout;
  const vertex = player.textures.vertex.image;
  const frame = player.textures.frame.image;
  const fr = (i) => fetch(frame.data, frame.width, i + base);
  const g = L.gpuIndex[v];
  if (g < L.nDirect) return fr(g).slice(0, 3);
  const r = (g - L.nDirect) * 4;
  const head = fetch(vertex.data, vertex.width, r);
  const c = L.nDirect + Math.round(head[0]) * L.curveTexels;
  let p = [0, 1, 2].map((w) => f(head[1 + w] + dot4(fr(c + w), fetch(vertex.data, vertex.width, r + 1 + w))));
  if (L.rigid) {
    const rows = [0, 1, 2].map((i) => fr(c + L.coefficientTexels + i));
    p = rows.map((row) => f(dot4([row[0], row[1], row[2], 0], [...p, 0]) + row[3]));
  }
  return p;
}

/** pdeEval(v) of the crowd form (glsl.js PDEANIM_KNOTS) in float32: time row of slot `slot`. */
function emulateCrowd(player, v, slot) {
  const L = player.layout;
  const { table, row } = player.resources.crowd;
  const vertex = player.textures.vertex.image;
  const atlas = player.textures.frame.image;
  const base = player.uniforms.pdeFrameOffset.value + slot * row.texels;
  const fr = (i) => fetch(atlas.data, atlas.width, i + base);
  const knot = (i) => fetch(table.data, table.width, i);
  const g = L.gpuIndex[v];
  // direct vertices: their records in the knot table
  const direct = g < L.nDirect;
  const record = (i) => (direct ? knot(i) : fetch(vertex.data, vertex.width, i));
  const r = direct ? table.directTexel + g * 4 : (g - L.nDirect) * 4;
  const head = record(r);
  const cg = Math.round(head[0]);
  const seg = Math.round(fr(row.timeTexel)[0]);
  const cw = fr(row.timeTexel + 1);
  // (muTexel -1: every item on the spline, no indices)
  const mu = table.muTexel < 0 ? [-1, -1, -1, -1] : knot(table.muTexel + seg * table.curves + cg);
  const mad = (ws, rows) => [0, 1, 2, 3].map((k) => rows.reduce((acc, x, i) => f(acc + f(ws[i] * x[k])), 0));
  const coefficients = (w) => {
    const a = (seg * table.curves + cg) * 3 + w;
    const b = a + table.curves * 3;
    if (mu[w] < -0.5) {
      const rows = [knot(table.tangentTexel + a), knot(a), knot(b), knot(table.tangentTexel + b)];
      return mad(cw, rows);
    }
    const j = Math.round(mu[w]);
    const pair = fr(row.timeTexel + 2 + (j >> 1));
    return mad(j % 2 === 0 ? pair.slice(0, 2) : pair.slice(2, 4), [knot(a), knot(b)]);
  };
  const p = [0, 1, 2].map((w) => f(head[1 + w] + dot4(coefficients(w), record(r + 1 + w))));
  return L.rigid ? rigidMotion(table, fr(row.rigidTexel), knot, cg, p) : p;
}

/** glsl.js pdeRigid (float64 here): p moved by GPU curve c's rigid motion at the row's rigid segment and time. */
function rigidMotion(table, at, knot, c, p) {
  const s = Math.round(at[0]);
  const tau = at[1];
  const mu = knot(table.rigidMuTexel + s * table.curves + c);
  const pr = rigidTimePair(tau, mu[0], [0, 0]);
  const pt = rigidTimePair(tau, mu[1], [0, 0]);
  const k0 = table.rigidKnotTexel + (s * table.curves + c) * 2;
  const k1 = k0 + table.curves * 2;
  const r = [0, 1, 2].map((w) => pr[0] * knot(k0)[w] + pr[1] * knot(k1)[w]);
  const t = [0, 1, 2].map((w) => pt[0] * knot(k0 + 1)[w] + pt[1] * knot(k1 + 1)[w]);
  const R = rodrigues(r[0], r[1], r[2], new Float64Array(9));
  return [0, 1, 2].map((i) => R[i * 3] * p[0] + R[i * 3 + 1] * p[1] + R[i * 3 + 2] * p[2] + t[i]);
}

/** The largest deviation of the emulated shader (slot base) from the CPU evaluator at t. */
function deviation(player, clip, t, base = 0) {
  const cpu = createEvaluator(clip).evaluate(t);
  let worst = 0;
  for (let v = 0; v < clip.nVertices; v++) {
    const g = emulate(player, v, base);
    for (let w = 0; w < 3; w++) worst = Math.max(worst, Math.abs(g[w] - cpu[v * 3 + w]));
  }
  return worst;
}

test('players of one clip share its data texture; each has its own time row and time', () => {
  const c = byName('fit-rigid-chord-smooth-spline');
  const clip = loadCase(c);
  const a = attachClip(meshOf(clip), clip, { crowdForm: 'always' });
  assert.equal(a.crowd, false, 'one player alone: its own per-frame table');
  const alone = a.frames.bytes;
  const b = attachClip(meshOf(clip), clip);
  assert.equal(a.resources, b.resources);
  assert.ok(a.crowd && b.crowd, "a second player at another time turns the clip into its crowd form");
  assert.equal(a.textures.vertex, b.textures.vertex);
  // one atlas of time rows for both; each its own row (and uniforms)
  assert.equal(a.textures.frame, b.textures.frame);
  assert.notEqual(a.uniforms.pdeFrameOffset, b.uniforms.pdeFrameOffset);
  assert.notEqual(a.uniforms.pdeFrameOffset.value, b.uniforms.pdeFrameOffset.value);
  assert.equal(a.uniforms.pdeVertexTex, b.uniforms.pdeVertexTex);
  assert.equal(a.uniforms.pdeKnotTex, b.uniforms.pdeKnotTex);
  assert.ok(b.frames.bytes < alone, `a time row (${b.frames.bytes} bytes) is smaller than a table (${alone})`);
  a.setTime(0.2);
  b.setTime(0.9);
  assert.ok(deviation(a, clip, 0.2) <= 1e-6 * c.diagonal);
  assert.ok(deviation(b, clip, 0.9) <= 1e-6 * c.diagonal);
  assert.ok(deviation(a, clip, 0.9) > 1e-3 * c.diagonal, 'a shows its own time, not b');
  // the second player adds its per-frame table and its mesh's attributes, not the data texture
  assert.equal(b.gpuBytes - b.attributeBytes, a.resources.sharedBytes + b.frames.bytes);
  assert.equal(a.resources.textureBytes, a.resources.sharedBytes + b.frames.bytes);
  // freed with the last player; a later player makes the clip's texture again
  let disposed = 0;
  a.textures.vertex.addEventListener('dispose', () => disposed++);
  a.detach();
  assert.equal(disposed, 0);
  b.detach();
  assert.equal(disposed, 1);
  const c2 = attachClip(meshOf(clip), clip);
  assert.notEqual(c2.resources, a.resources);
  assert.equal(c2.resources.users, 1);
  c2.detach();
});

test('another texture width (another renderer limit) gets its own resources', () => {
  const clip = loadCase(byName('fit-displacement-chord'));
  const a = attachClip(meshOf(clip), clip);
  const b = attachClip(meshOf(clip), clip, { maxTextureSize: 16 });
  const c = attachClip(meshOf(clip), clip, { maxTextureSize: 16 });
  assert.notEqual(a.resources, b.resources);
  assert.equal(b.resources, c.resources);
  assert.equal(b.resources.users, 2);
  for (const p of [a, b, c]) p.detach();
});

test('clone() of a playing mesh: its own time, uniforms and materials, the clip texture and attributes shared', () => {
  const c = byName('fit-displacement-chord-smooth-spline');
  const clip = loadCase(c);
  const mesh = meshOf(clip);
  const original = mesh.material;
  const player = attachClip(mesh, clip, { influence: 0.5 });
  player.setTime(0.3);
  const copy = player.clone();
  assert.notEqual(copy.mesh, mesh);
  assert.notEqual(copy.mesh.material, mesh.material);
  assert.notEqual(copy.mesh.customDepthMaterial, mesh.customDepthMaterial);
  assert.equal(copy.influence, 0.5);
  assert.equal(copy.time, 0.3);
  assert.equal(copy.textures.vertex, player.textures.vertex);
  assert.equal(copy.mesh.geometry, mesh.geometry); // Object3D.clone shares it: so do the attributes
  copy.setTime(0.8);
  assert.equal(player.time, 0.3);
  assert.ok(deviation(player, clip, 0.3) <= 1e-6 * c.diagonal);
  assert.ok(deviation(copy, clip, 0.8) <= 1e-6 * c.diagonal);
  // the patched materials compile with each player's own uniforms
  const shaderOf = (m) => {
    const s = { uniforms: {}, vertexShader: THREE.ShaderLib.standard.vertexShader };
    m.onBeforeCompile(s);
    return s;
  };
  assert.equal(shaderOf(mesh.material).uniforms.pdeFrameTex, player.uniforms.pdeFrameTex);
  assert.equal(shaderOf(copy.mesh.material).uniforms.pdeFrameTex, copy.uniforms.pdeFrameTex);
  player.detach();
  assert.equal(mesh.material, original);
  assert.ok(copy.mesh.geometry.getAttribute('pdeVertex'), 'the clone still plays after the original detached');
  copy.detach();
  assert.equal(copy.mesh.geometry.getAttribute('pdeVertex'), undefined);
  assert.equal(copy.mesh.material, original);
});

test("attachClip on a three.js clone of a playing mesh patches the mesh's own material, not the patched one", () => {
  const c = byName('fit-displacement-chord');
  const clip = loadCase(c);
  const mesh = meshOf(clip);
  const original = mesh.material;
  const a = attachClip(mesh, clip);
  const cloned = mesh.clone(); // shares the patched material and the geometry
  const b = attachClip(cloned, clip);
  assert.notEqual(cloned.material, mesh.material);
  a.setTime(0.1);
  b.setTime(0.7);
  assert.ok(deviation(a, clip, 0.1) <= 1e-6 * c.diagonal);
  assert.ok(deviation(b, clip, 0.7) <= 1e-6 * c.diagonal);
  b.detach();
  assert.equal(cloned.material, mesh.material); // what it had before
  a.detach();
  assert.equal(mesh.material, original);
});

test('a player switching to the CPU on a geometry that others play gets its own copy of it', () => {
  const clip = loadCase(byName('fit-displacement-chord'));
  const mesh = meshOf(clip);
  const a = attachClip(mesh, clip);
  const b = a.clone();
  const shared = mesh.geometry;
  b.useGPU(false);
  b.setTime(0.5);
  assert.notEqual(b.mesh.geometry, shared);
  assert.ok(b.mesh.geometry.getAttribute('pdeCpuPosition'));
  assert.equal(shared.getAttribute('pdeCpuPosition'), undefined);
  b.detach();
  assert.equal(b.mesh.geometry, shared);
  assert.ok(shared.getAttribute('pdeVertex'), "a's attributes are kept");
  a.detach();
  assert.equal(shared.getAttribute('pdeVertex'), undefined);
});

test('ScenePlayer.clone(): another root with its own time; one per-frame table per scene player', () => {
  const c = byName('fit-displacement-chord-loop');
  const clip = loadCase(c);
  const root = new THREE.Group();
  root.add(meshOf(clip));
  const a = attachClipToScene(root, clip);
  const b = a.clone();
  assert.notEqual(b.root, root);
  assert.equal(b.resources, a.resources);
  assert.notEqual(b.frames, a.frames);
  a.setTime(0.25);
  b.setTime(0.75);
  assert.ok(deviation(a.players[0], clip, 0.25) <= 1e-6 * c.diagonal);
  assert.ok(deviation(b.players[0], clip, 0.75) <= 1e-6 * c.diagonal);
  // what the second scene adds on the GPU: its per-frame table (the attributes are shared with a's meshes)
  assert.equal(b.gpuBytes - a.gpuBytes, 0);
  assert.equal(b.resources.users, 4); // two scene players and their two meshes
  a.detach();
  b.detach();
  assert.equal(b.resources.users, 0);
});

test('InstancedMesh with timeOffsets: one time row per distinct offset, each instance reads its own', () => {
  for (const name of ['fit-rigid-paper-loop', 'fit-displacement-chord']) {
    const c = byName(name);
    const clip = loadCase(c);
    const n = 6;
    const mesh = new THREE.InstancedMesh(geometryOf(clip), new THREE.MeshStandardMaterial(), n);
    const offsets = [0, 0.25, 0.5, 0.25, 0.75, 0];
    const player = attachClip(mesh, clip, { timeOffsets: offsets, crowdForm: 'always' });
    assert.equal(player.frames.offsets.length, 4);
    assert.ok(player.crowd, 'offsets: the crowd form');
    assert.equal(player.pass, false);
    assert.match(player.programKey, /:slots:/);
    const slot = mesh.geometry.getAttribute('pdeSlot');
    assert.ok(slot.isInstancedBufferAttribute);
    assert.deepEqual([...slot.array], [0, 1, 2, 1, 3, 0]);
    const t = 0.6;
    player.setTime(t);
    const stride = player.uniforms.pdeSlotTexels.value;
    for (let i = 0; i < n; i++) {
      let ti = t + offsets[i];
      ti = clip.looping ? ti - Math.floor(ti) : Math.min(ti, 1);
      const dev = deviation(player, clip, ti, slot.array[i] * stride);
      assert.ok(dev <= 1e-6 * c.diagonal, `${name} instance ${i}: ${dev / c.diagonal}`);
      // the slot's time row holds the segment of its time
      const { row } = player.resources.crowd;
      const k = (player.uniforms.pdeFrameOffset.value + slot.array[i] * stride + row.timeTexel) * 4;
      assert.equal(player.textures.frame.image.data[k], createEvaluator(clip).locate(ti)[0]);
    }
    const s = { uniforms: {}, vertexShader: THREE.ShaderLib.standard.vertexShader };
    mesh.material.onBeforeCompile(s);
    assert.match(s.vertexShader, /#define PDEANIM_SLOTS/);
    assert.match(s.vertexShader, /in float pdeSlot;/);
    player.detach();
    assert.equal(mesh.geometry.getAttribute('pdeSlot'), undefined);
    // crowdForm 'never': a per-frame table per slot, each instance reading its own
    const other = new THREE.InstancedMesh(geometryOf(clip), new THREE.MeshStandardMaterial(), n);
    const tables = attachClip(other, clip, { timeOffsets: offsets, crowdForm: 'never' });
    assert.equal(tables.crowd, false);
    tables.setTime(t);
    const each = tables.uniforms.pdeSlotTexels.value;
    for (let i = 0; i < n; i++) {
      let ti = t + offsets[i];
      ti = clip.looping ? ti - Math.floor(ti) : Math.min(ti, 1);
      const dev = deviation(tables, clip, ti, slot.array[i] * each);
      assert.ok(dev <= 1e-6 * c.diagonal, `${name} 'never' instance ${i}: ${dev / c.diagonal}`);
    }
    tables.detach();
  }
});

test('cyclic clips in a crowd: each slot holds the sine and cosine of its swim phase', () => {
  const clip = loadCase(byName('cyclic-eel-standing-rotate'));
  const mesh = new THREE.InstancedMesh(geometryOf(clip), new THREE.MeshBasicMaterial(), 3);
  const player = attachClip(mesh, clip, { timeOffsets: [0, 0.5, 0.1] });
  player.setTime(0.3);
  const data = player.textures.frame.image.data;
  for (const [k, o] of [0, 0.5, 0.1].entries()) {
    const u = timeUniforms(gpuLayout(clip), 0.3 + o);
    assert.equal(data[k * 4], f(u.sw));
    assert.equal(data[k * 4 + 1], f(u.cw));
  }
  player.detach();
});

test('timeOffsets are refused with a reason where they cannot play', () => {
  const clip = loadCase(byName('fit-displacement-chord'));
  const inst = () => new THREE.InstancedMesh(geometryOf(clip), new THREE.MeshBasicMaterial(), 2);
  assert.throws(() => attachClip(meshOf(clip), clip, { timeOffsets: [0] }), /needs an InstancedMesh/);
  assert.throws(() => attachClip(inst(), clip, { timeOffsets: [0] }), /must hold 2 finite numbers/);
  assert.throws(() => attachClip(inst(), clip, { timeOffsets: [0, NaN] }), RangeError);
  assert.throws(() => attachClip(inst(), clip, { timeOffsets: [0, 1], gpu: false }), /GPU only/);
  const player = attachClip(inst(), clip, { timeOffsets: [0, 0.5] });
  assert.throws(() => player.useGPU(false), /GPU only/);
  player.detach();
  const many = Array.from({ length: 300 }, (_, i) => i / 300);
  const big = new THREE.InstancedMesh(geometryOf(clip), new THREE.MeshBasicMaterial(), 300);
  assert.throws(() => attachClip(big, clip, { timeOffsets: many, maxTextureSize: 16 }), /300 distinct time offsets/);
  assert.equal(ClipResources.acquire(clip, { maxTextureSize: 16 }).users, 1, 'the refused attach left no user');
});

test('players at distinct times: the clip tables once, each extra player a time row, freed with the last', () => {
  const c = byName('fit-displacement-chord-smooth-pde'); // 12 segments of the paper's time pairs
  const clip = loadCase(c);
  const first = attachClip(meshOf(clip), clip, { crowdForm: 'always' });
  const alone = { bytes: first.gpuBytes, table: first.frames.bytes };
  const players = [first, ...Array.from({ length: 39 }, () => first.clone())];
  const res = first.resources;
  const { row, table } = res.crowd;
  assert.equal(res.tables.size, 40);
  // one vertex texture, one knot table, one atlas of time rows for all; a row each
  assert.equal(new Set(players.map((p) => p.textures.vertex)).size, 1);
  assert.equal(new Set(players.map((p) => p.textures.frame)).size, 1);
  assert.equal(new Set(players.map((p) => p.uniforms.pdeKnotTex.value)).size, 1);
  assert.equal(new Set(players.map((p) => p.uniforms.pdeFrameOffset.value)).size, 40);
  assert.equal(new Set(players.map((p) => p.programKey)).size, 1, 'one program for every player');
  for (const p of players) assert.equal(p.frames.bytes, row.texels * 16);
  assert.ok(row.texels * 16 < alone.table, `a time row ${row.texels * 16} bytes, a table ${alone.table}`);
  // the knot table is the clip's (its knots, once): (S + 1) knots and S segments per curve (the GPU curves
  // and the direct ones), then the direct vertices' records
  const L = first.layout;
  assert.equal(table.curves, new Set(L.direct.curve).size + L.gpuCurve.filter((x) => x >= 0).length);
  const S = clip.nSegments;
  assert.equal(table.texels, (S + 1) * table.curves * 3 + S * table.curves + L.nDirect * 4);
  assert.equal(row.texels, 2 + Math.ceil(L.evaluator.uPhi0.length / 2), 'a row: segment, weights, time pairs');
  assert.equal(res.sharedBytes, alone.bytes - alone.table - first.attributeBytes + table.data.byteLength);
  // the atlas grows by doubling: at most twice the rows in use, plus a row of padding
  assert.ok(res.atlasBytes <= 2 * 40 * row.texels * 16 + first.layout.width * 16);
  players.forEach((p, i) => p.setTime(i / 39));
  for (let i = 0; i < 40; i += 3) {
    const dev = deviation(players[i], clip, i / 39);
    assert.ok(dev <= 1e-6 * c.diagonal, `player ${i}: ${dev / c.diagonal}`);
  }
  // a t with the same segment and local time writes nothing: the atlas is uploaded once per frame at most
  const version = first.textures.frame.version;
  players.forEach((p, i) => p.setTime(i / 39));
  assert.equal(first.textures.frame.version, version);
  let disposed = 0;
  for (const tex of [first.textures.vertex, res.crowd.texture, first.textures.frame]) {
    tex.addEventListener('dispose', () => disposed++);
  }
  for (const p of players.slice(1)) p.detach();
  assert.equal(disposed, 0);
  assert.equal(res.crowd.atlas.slots.filter((o) => o !== null).length, 1, 'the detached players freed their rows');
  first.setTime(0.55);
  assert.ok(deviation(first, clip, 0.55) <= 1e-6 * c.diagonal);
  first.detach();
  assert.equal(disposed, 3);
});

test('a second player turns the first into the crowd form: its materials recompile, the pass goes, its time stays', () => {
  const c = byName('fit-displacement-chord');
  const clip = loadCase(c);
  const mesh = meshOf(clip);
  const a = attachClip(mesh, clip, { pass: true, crowdForm: 'always' });
  assert.equal(a.pass, true);
  assert.equal(a.crowd, false);
  a.setTime(0.35);
  const shaderOf = (m) => {
    const s = { uniforms: {}, vertexShader: THREE.ShaderLib.standard.vertexShader };
    m.onBeforeCompile(s);
    return s;
  };
  assert.doesNotMatch(shaderOf(mesh.material).vertexShader, /#define PDEANIM_KNOTS/);
  const versions = [mesh.material.version, mesh.customDepthMaterial.version];
  const b = a.clone();
  assert.ok(a.crowd && b.crowd);
  assert.equal(a.pass, false, 'the vertex shader evaluates in the crowd form (no per-player pass texture)');
  assert.equal(a.frames.pass, null);
  assert.ok(mesh.material.version > versions[0] && mesh.customDepthMaterial.version > versions[1]);
  assert.match(a.programKey, /:crowd\d+:/);
  const s = shaderOf(mesh.material);
  assert.match(s.vertexShader, /#define PDEANIM_KNOTS/);
  assert.doesNotMatch(s.vertexShader, /#define PDEANIM_PASS/);
  assert.equal(s.uniforms.pdeKnotTex.value, a.resources.crowd.texture);
  assert.equal(s.uniforms.pdeFrameTex.value, a.resources.crowd.atlas.texture);
  // the first player's time was written into its row when it switched
  assert.ok(deviation(a, clip, 0.35) <= 1e-6 * c.diagonal);
  assert.ok(deviation(b, clip, 0.35) <= 1e-6 * c.diagonal, 'the clone starts at its original time');
  b.setTime(0.9);
  assert.ok(deviation(a, clip, 0.35) <= 1e-6 * c.diagonal, "the clone's time does not move the original");
  a.detach();
  assert.equal(b.resources.tables.size, 1);
  b.setTime(0.1);
  assert.ok(deviation(b, clip, 0.1) <= 1e-6 * c.diagonal, 'the clone plays on after the original detached');
  b.detach();
});

test('the crowd form keeps the per-frame state of bone clips and rigid clips in each player\'s row', () => {
  for (const name of ['bones-fit-k4-residual', 'bones-synthetic-k3-zero-loop', 'fit-rigid-paper-loop']) {
    const clip = decodeClipFile(readBytes(join(FIXTURES, `${name}.clip`)));
    const a = attachClip(meshOf(clip), clip, { crowdForm: 'always' });
    const b = a.clone();
    assert.ok(a.crowd && b.crowd, name);
    const { row } = a.resources.crowd;
    a.setTime(0.2);
    b.setTime(0.8);
    const atlas = a.textures.frame.image.data;
    if (clip.bones) {
      assert.equal(a.uniforms.pdeBones.value, row.boneTexel);
      for (const [p, t] of [[a, 0.2], [b, 0.8]]) {
        const ev = createEvaluator(clip);
        ev.prepare(t);
        const rows = ev.bones.affine();
        const o = (p.uniforms.pdeFrameOffset.value + row.boneTexel) * 4;
        for (let i = 0; i < rows.length; i++) assert.equal(atlas[o + i], f(rows[i]), `${name} bone value ${i}`);
      }
    } else {
      // direct vertices (every vertex of this clip): positions at each player's time
      for (const [p, t] of [[a, 0.2], [b, 0.8]]) assert.ok(deviation(p, clip, t) <= 1e-6 * byName(name).diagonal, name);
    }
    a.detach();
    b.detach();
  }
});

test("a backend whose shaders do not read the crowd form keeps per-frame tables beside a crowd", () => {
  const c = byName('fit-displacement-chord-loop');
  const clip = loadCase(c);
  const plain = { ...webglBackend, crowd: false };
  const a = new ClipPlayer(meshOf(clip), clip, {}, plain);
  const b = new ClipPlayer(meshOf(clip), clip, {}, plain);
  assert.equal(a.resources, b.resources);
  assert.ok(!a.crowd && !b.crowd && a.resources.crowd === null);
  const x = attachClip(meshOf(clip), clip, { crowdForm: 'always' });
  const y = x.clone();
  assert.ok(x.crowd && y.crowd, 'the WebGL players take the crowd form');
  assert.ok(!a.crowd && !b.crowd, 'the others keep their tables');
  assert.doesNotMatch(a.programKey, /:crowd/);
  for (const [p, t] of [[a, 0.1], [b, 0.6], [x, 0.3], [y, 0.85]]) {
    p.setTime(t);
    assert.ok(deviation(p, clip, t) <= 1e-6 * c.diagonal, `${t}`);
  }
  for (const p of [a, b, x, y]) p.detach();
});

test('rigid clips with GPU curves: the crowd form moves each curve in the shader; a row of a few texels', () => {
  for (const name of ['fit-rigid-paper-loop', 'fit-rigid-chord-smooth-spline', 'synthetic-blend-rigid-chord-loop-basis']) {
    const c = byName(name);
    const clip = loadCase(c);
    // no direct curves (the fixtures' curves are short): every curve's rigid motion is the shader's
    const tables = gpuTables(clip, { directMax: 0 });
    assert.equal(tables.nDirect, 0);
    const a = attachClip(meshOf(clip), clip, { tables, crowdForm: 'always' });
    a.setTime(0.3);
    assert.ok(deviation(a, clip, 0.3) <= 1e-6 * c.diagonal, `${name} alone`);
    const b = a.clone();
    assert.ok(a.crowd && b.crowd);
    const { row } = a.resources.crowd;
    assert.equal(row.boneTexel - row.rigidTexel, 1, 'one rigid texel (segment, time) per row, not 3 per curve');
    for (const [p, t] of [[a, 0.3], [b, 0.3], [b, 0.77], [a, 0.05], [a, 1]]) {
      if (t === 1 && clip.looping) continue;
      p.setTime(t);
      const dev = deviation(p, clip, t);
      assert.ok(dev <= 1e-6 * c.diagonal, `${name} at ${t}: ${dev / c.diagonal}`);
    }
    a.detach();
    b.detach();
  }
});

test('setTime after detach does not throw in the crowd form (the clip resources are freed)', () => {
  const clip = loadCase(byName('fit-displacement-chord'));
  const a = attachClip(meshOf(clip), clip);
  const b = a.clone();
  a.detach();
  b.detach();
  assert.equal(b.resources.crowd, null);
  assert.doesNotThrow(() => b.setTime(0.4));
  assert.equal(b.textures.frame, undefined);
});

test("crowdForm 'auto' (default) and 'bytes': distinct times keep per-frame tables until the crowd form pays", () => {
  const c = byName('fit-displacement-chord'); // a knot table of 12 per-frame tables' bytes
  const clip = loadCase(c);
  for (const [form, ratio] of [['auto', 2], ['bytes', 1]]) {
    const first = attachClip(meshOf(clip), clip, form === 'auto' ? {} : { crowdForm: form });
    const res = first.resources;
    assert.equal(res.crowdForm, form);
    const players = [first];
    while (res.crowd === null) {
      const before = res.formBytes(1);
      players.push(first.clone());
      // the crowd form once it takes at most `ratio` times the tables' bytes, at every count of players
      assert.equal(res.crowd !== null, before.crowd <= ratio * before.tables, `${form}: ${players.length} players`);
      assert.ok(players.length < 40, 'the crowd form pays at some count');
    }
    assert.ok(players.length > 2, 'two players keep their tables (the knot table costs more)');
    assert.ok(players.every((p) => p.crowd));
    players.forEach((p, i) => p.setTime((i * 0.37) % 1));
    for (const [i, p] of players.entries()) assert.ok(deviation(p, clip, (i * 0.37) % 1) <= 1e-6 * c.diagonal, `${i}`);
    for (const p of players) p.detach();
  }
  // 'never': per-frame tables whatever the count; distinct times right there too
  const a = attachClip(meshOf(clip), clip, { crowdForm: 'never' });
  const many = [a, ...Array.from({ length: 20 }, () => a.clone())];
  assert.ok(many.every((p) => !p.crowd));
  many.forEach((p, i) => p.setTime((i * 0.37) % 1));
  for (const [i, p] of many.entries()) assert.ok(deviation(p, clip, (i * 0.37) % 1) <= 1e-6 * c.diagonal, `never ${i}`);
  for (const p of many) p.detach();
  assert.throws(() => attachClip(meshOf(clip), clip, { crowdForm: 'sometimes' }), /crowdForm must be/);
});

test('a clip whose items are all on the spline has no time-pair indices in its knot table', () => {
  const c = byName('fit-displacement-chord-windows-basis');
  const clip = loadCase(c);
  const a = attachClip(meshOf(clip), clip, { crowdForm: 'always' });
  const b = a.clone();
  const { table } = a.resources.crowd;
  assert.equal(table.muTexel, -1);
  assert.equal(a.uniforms.pdeMuTexel.value, -1);
  assert.equal(table.rigidKnotTexel, table.tangentTexel * 2, 'knots and tangents only');
  a.setTime(0.2);
  b.setTime(0.7);
  assert.ok(deviation(a, clip, 0.2) <= 1e-6 * c.diagonal);
  assert.ok(deviation(b, clip, 0.7) <= 1e-6 * c.diagonal);
  a.detach();
  b.detach();
});
