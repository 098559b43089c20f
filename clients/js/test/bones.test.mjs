// The bone layer (format 1.1, feature "bones") in the JS reader: the `required` rule, the bone arrays'
// rejections, and the CPU evaluator against a float64 evaluation written from docs/format.md, on clips made
// from the 1.0 fixtures by adding a bone layer (with and without a residual).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import {
  ClipFormatError,
  SUPPORTED_FEATURES,
  boundingBoxDiagonal,
  createEvaluator,
  decodeClip,
  decodeClipFile,
} from '../src/index.js';
import { spawnSync } from 'node:child_process';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { FIXTURES, edited, expected, fixtureParts, manifest, withoutStream, readBytes, refused, sampleTimes, takenTimes } from './helpers.mjs';
import { boneClipParts, naiveBoneEvaluate, restOf, withBones } from './bonehelpers.mjs';

// streamable clips (format 1.2) decode window by window: test/stream.test.mjs checks their tables
const man = withoutStream(manifest());
const byName = (name) => man.cases.find((c) => c.name === name);
// displacement fixtures: spline items, looping, knots on a shared basis, knot windows, order-2 differences
const CASES = [ // (bone layers added here to 1.0 fixtures; the Python-written bone fixtures are at the end)
  ['fit-displacement-chord', { K: 2 }],
  ['fit-displacement-chord-loop', { K: 4, B: 5 }],
  ['synthetic-blend-displacement-paper-basis', { K: 3, Sb: 1 }],
  ['fit-displacement-chord-windows', { K: 1, B: 1 }],
  ['synthetic-displacement-chord-spline', { K: 2, Sb: 6, angle: 3 }],
];

function worstAgainstNaive(clip, coefficients, times) {
  const ev = createEvaluator(clip);
  let worst = 0;
  let moved = 0;
  for (const t of times) {
    const got = ev.evaluate(t);
    const want = naiveBoneEvaluate(clip, coefficients, t);
    for (let i = 0; i < want.length; i++) {
      worst = Math.max(worst, Math.abs(got[i] - want[i]));
      moved = Math.max(moved, Math.abs(want[i] - clip.rest[i]));
    }
  }
  return { worst, moved };
}

for (const [name, options] of CASES) {
  for (const residual of [true, false]) {
    test(`bones (${JSON.stringify(options)}, residual ${residual}): the CPU evaluator is the spec's float64 evaluation to 1e-6 of the diagonal: ${name}`, () => {
      const c = byName(name);
      const { topology, coefficients } = boneClipParts(c, { ...options, residual });
      const clip = decodeClip(topology, coefficients);
      assert.ok(clip.bones, 'the bone layer is decoded');
      assert.equal(clip.bones.residual, residual);
      const diagonal = boundingBoxDiagonal(clip.rest);
      const times = takenTimes(sampleTimes(Array.from(clip.bones.segmentT), clip.looping), clip.looping);
      const { worst, moved } = worstAgainstNaive(clip, coefficients, times.concat(sampleTimes(clip.segmentT, clip.looping)).filter((t) => clip.looping || (t >= 0 && t <= 1)));
      assert.ok(moved > 0.05 * diagonal, `the bones move the mesh (${moved / diagonal} of the diagonal)`);
      assert.ok(worst <= 1e-6 * diagonal, `${name}: ${worst / diagonal} of the diagonal`);
    });
  }
}

test('bones without a residual: the frame is the skinned base and the knot fields are never made', () => {
  const c = byName('fit-displacement-chord');
  const withRes = boneClipParts(c, { residual: true });
  const noRes = boneClipParts(c, { residual: false });
  const a = createEvaluator(decodeClip(withRes.topology, withRes.coefficients));
  const clipB = decodeClip(noRes.topology, noRes.coefficients);
  const b = createEvaluator(clipB);
  for (const t of [0, 0.123, 0.5, 0.97, 1]) {
    a.evaluate(t);
    const got = b.evaluate(t);
    // the same bones: the same skinned base, bit for bit, whatever the residual
    assert.deepEqual(Array.from(got), Array.from(a.base));
    const naive = naiveBoneEvaluate(clipB, noRes.coefficients, t);
    assert.ok(got.every((x, i) => Math.abs(x - naive[i]) <= 1e-6 * c.diagonal));
  }
  assert.equal(b._fields, null, 'no knot fields for a clip without residual');
});

test('the skinned base is float32 of the float64 sum in the stored influence order', () => {
  const c = byName('fit-displacement-chord-loop');
  const { topology, coefficients } = boneClipParts(c, { K: 4, B: 5, residual: false });
  const clip = decodeClip(topology, coefficients);
  const ev = createEvaluator(clip);
  const out = ev.evaluate(0.37);
  const pose = ev.bones;
  const { index, weight, pivot } = clip.bones;
  for (let v = 0; v < clip.nVertices; v++) {
    const acc = [0, 0, 0];
    for (let k = 0; k < 4; k++) {
      const b = index[v * 4 + k];
      const d = [0, 1, 2].map((j) => clip.rest[v * 3 + j] - pivot[b * 3 + j]);
      for (let i = 0; i < 3; i++) {
        const R = pose.rot.subarray(b * 9 + i * 3, b * 9 + i * 3 + 3);
        acc[i] += weight[v * 4 + k] * (R[0] * d[0] + R[1] * d[1] + R[2] * d[2] + pivot[b * 3 + i] + pose.trans[b * 3 + i]);
      }
    }
    for (let i = 0; i < 3; i++) assert.equal(out[v * 3 + i], Math.fround(acc[i]));
  }
});

test('the required rule: "bones" is supported; unknown features are refused naming them and the supported set', () => {
  assert.deepEqual([...SUPPORTED_FEATURES], ['bones', 'stream']);
  const c = byName('fit-displacement-chord');
  const { topology, coefficients } = fixtureParts(c);
  const bones = boneClipParts(c);
  const require = (bytes, required) => edited(bytes, ({ header }) => Object.assign(header, { format_version: '1.1', required }));
  const msg = /the coefficients part requires format feature\(s\) "wings" that this reader lacks \(it supports: bones, stream\)/;
  refused(() => decodeClip(topology, require(bones.coefficients, ['bones', 'wings'])), msg);
  refused(() => decodeClip(topology, require(coefficients, ['wings'])), msg);
  refused(() => decodeClip(require(topology, ['x-topo']), coefficients), /topology part requires format feature\(s\) "x-topo"/);
  for (const bad of ['bones', [1], { bones: true }, null]) {
    if (bad === null) continue; // null reads as absent
    refused(() => decodeClip(topology, require(coefficients, bad)), /'required' must be a list of feature names/);
  }
  // a CLIP file's own header is checked too
  const file = edited(bones.file, ({ header }) => Object.assign(header, { required: ['bones', 'lasers'] }));
  refused(() => decodeClipFile(file), /clip-file part requires format feature\(s\) "lasers"/);
  assert.ok(decodeClipFile(bones.file).bones);
});

test('required absent, or [] in a 1.1 part without bones: the clip reads and evaluates exactly as the 1.0 one', () => {
  for (const c of man.cases.filter((x) => x.kind === 'dynamic-pde').slice(0, 6)) {
    const { topology, coefficients } = fixtureParts(c);
    const plain = decodeClip(topology, coefficients);
    assert.equal(plain.bones, null);
    const v11 = edited(coefficients, ({ header }) => Object.assign(header, { format_version: '1.1', required: [] }));
    const a = createEvaluator(plain);
    const b = createEvaluator(decodeClip(topology, v11));
    for (const t of takenTimes(c.t, c.looping)) assert.deepEqual(Array.from(b.evaluate(t)), Array.from(a.evaluate(t)));
  }
});

test('bone arrays without "bones" in required are ignored, as any extra arrays of a minor version', () => {
  const c = byName('fit-displacement-chord');
  const parts = fixtureParts(c);
  const untagged = edited(withBones(parts.coefficients, restOf(parts)), ({ header }) => delete header.required);
  const clip = decodeClip(parts.topology, untagged);
  assert.equal(clip.bones, null);
  const want = createEvaluator(decodeClip(parts.topology, parts.coefficients)).evaluate(0.4);
  assert.deepEqual(Array.from(createEvaluator(clip).evaluate(0.4)), Array.from(want));
});

test('bone arrays with bad counts, shapes, dtypes, indices, weights, steps, constants or values are rejected', () => {
  const c = byName('fit-displacement-chord');
  const parts = fixtureParts(c);
  const rest = restOf(parts);
  const good = withBones(parts.coefficients, rest, { B: 3, K: 2, Sb: 4 });
  assert.ok(decodeClip(parts.topology, good).bones);
  const bad = (edit) => () => decodeClip(parts.topology, edited(good, edit));
  const setArray = (name, f) => ({ arrays }) => {
    const data = arrays[name].data.slice();
    f(data);
    arrays[name] = { ...arrays[name], data };
  };
  const cases = [
    [({ header }) => (header.n_bones = 0), /'n_bones' must be an integer in 1\.\.65536, got 0/],
    [({ header }) => (header.bone_knot_differences = 3), /'bone_knot_differences' must be an integer in 1\.\.2, got 3/],
    [({ header }) => delete header.bone_knot_differences, /'bone_knot_differences' must be an integer in 1\.\.2, got null/],
    [({ header }) => (header.n_bones = 2.5), /'n_bones' must be an integer/],
    [({ header }) => (header.bone_influences = 5), /'bone_influences' must be an integer in 1\.\.4, got 5/],
    [({ header }) => delete header.bone_influences, /'bone_influences' must be an integer in 1\.\.4, got null/],
    [({ arrays }) => delete arrays.bone_knots, /have no 'bone_knots' array/],
    [({ arrays }) => delete arrays.bone_segment_t, /have no 'bone_segment_t' array/],
    [({ arrays }) => (arrays.bone_pivot = { ...arrays.bone_pivot, shape: [1, 9] }), /'bone_pivot' has shape \[1,9\], expected \[3,3\]/],
    [({ arrays }) => (arrays.bone_index = { ...arrays.bone_index, dtype: '<i2', data: Int16Array.from(arrays.bone_index.data) }), /'bone_index' has dtype <i2, expected <u2/],
    [({ arrays }) => (arrays.bone_weight = { ...arrays.bone_weight, shape: [1, c.n_vertices] }), /'bone_weight' has shape/],
    [setArray('bone_index', (d) => (d[5] = 3)), /bone_index holds bone 3, the clip has 3 bones/],
    [setArray('bone_weight', (d) => d.fill(4096, 4, 5)), /bone_weight row 4 sums to \d+, above 2\^bone_weight_bits - 1 = 4095/],
    [({ header }) => delete header.bone_weight_bits, /'bone_weight_bits' must be an integer in 1\.\.16, got null/],
    [({ header }) => (header.bone_weight_bits = 17), /'bone_weight_bits' must be an integer in 1\.\.16, got 17/],
    [setArray('bone_step', (d) => (d[2] = 0)), /bone_step must be positive/],
    [setArray('bone_step', (d) => (d[2] = -1)), /bone_step must be positive/],
    [setArray('bone_step', (d) => (d[2] = Infinity)), /'bone_step' has non-finite values/],
    [setArray('bone_m', (d) => (d[0] = -Math.PI)), /bone trig time constants must be above -pi/],
    [setArray('bone_m', (d) => (d[1] = 0.5)), /bone channels on the natural spline must have time constant 0/],
    [setArray('bone_m', (d) => (d[0] = NaN)), /'bone_m' has non-finite values/],
    [setArray('bone_time_model', (d) => (d[0] = 2)), /bone_time_model must be 0 \(paper\) or 1 \(natural spline\), got 2/],
    [setArray('bone_pivot', (d) => (d[4] = NaN)), /'bone_pivot' has non-finite values/],
    [setArray('bone_segment_t', (d) => (d[2] = d[1])), /bone_segment_t must rise strictly from 0 to 1/],
    [setArray('bone_segment_t', (d) => (d[4] = 0.9)), /bone_segment_t must rise strictly from 0 to 1/],
    [({ arrays }) => (arrays.bone_segment_t = { dtype: '<f8', shape: [1], data: new Float64Array([0]) }), /bone_segment_t must rise strictly/],
    [setArray('bone_step', (d) => (d[0] = 3e38)), /bone knots decode to non-finite values/],
  ];
  for (const [edit, want] of cases) refused(bad(edit), want);
});

test('bones need motion "displacement" and a dynamic-pde clip', () => {
  const rigid = man.cases.find((x) => x.motion === 'rigid');
  const parts = fixtureParts(rigid);
  const coefficients = withBones(parts.coefficients, restOf(parts));
  refused(() => decodeClip(parts.topology, coefficients), /bones need motion "displacement", this clip's is "rigid"/);
  const cyclic = man.cases.find((x) => x.kind === 'cyclic-spine');
  const cp = fixtureParts(cyclic);
  const tagged = edited(cp.coefficients, ({ header }) => Object.assign(header, { format_version: '1.1', required: ['bones'] }));
  refused(() => decodeClip(cp.topology, tagged), /only defined for dynamic-pde clips/);
  assert.ok(new ClipFormatError('x') instanceof Error);
});

// ---- the conformance fixtures with a bone layer (written by the Python library)

const boneFixtures = man.cases.filter((x) => x.bones);

test('the fixtures cover bone layers with K = 1..4, spline and pair channels, zero and fitted residuals, looping', () => {
  assert.ok(boneFixtures.length >= 4);
  assert.deepEqual([...new Set(boneFixtures.map((x) => x.bones.influences))].sort(), [1, 2, 3, 4]);
  assert.ok(boneFixtures.some((x) => x.bones.residual_zero) && boneFixtures.some((x) => !x.bones.residual_zero));
  assert.ok(boneFixtures.some((x) => x.looping));
  assert.ok(boneFixtures.some((x) => x.bones.bone_knot_differences === 2));
  assert.ok(boneFixtures.every((x) => x.bones.spline_channels > 0 && x.bones.pair_channels > 0));
  assert.ok(man.refused?.length >= 1);
});

for (const c of boneFixtures) {
  test(`bone fixture ${c.name}: decodes to its manifest features and evaluates as the Python evaluator`, () => {
    const clip = decodeClipFile(readBytes(join(FIXTURES, c.clip)));
    const b = clip.bones;
    assert.equal(b.nBones, c.bones.n_bones);
    assert.equal(b.influences, c.bones.influences);
    assert.equal(b.segmentT.length - 1, c.bones.bone_segments);
    assert.equal(b.timeModel.filter((x) => x === 1).length, c.bones.spline_channels);
    assert.equal(b.timeModel.filter((x) => x === 0).length, c.bones.pair_channels);
    assert.equal(clip.header.bone_knot_differences, c.bones.bone_knot_differences);
    assert.equal(b.residual, !c.bones.residual_zero);
    const ev = createEvaluator(clip);
    const want = expected(c);
    const N = c.n_vertices * 3;
    const { coefficients } = fixtureParts(c);
    let differ = 0;
    takenTimes(c.t, c.looping).forEach((t) => {
      const k = c.t.indexOf(t);
      const got = ev.evaluate(t);
      for (let i = 0; i < N; i++) differ += got[i] !== want[k * N + i];
      // the spec read independently: float64 throughout, to the format's tolerance
      const naive = naiveBoneEvaluate(clip, coefficients, t);
      for (let i = 0; i < N; i++) assert.ok(Math.abs(naive[i] - want[k * N + i]) <= 1e-6 * c.diagonal, `${c.name} t = ${t}`);
    });
    // the skinned base is the Python evaluator's bit for bit; the residual's float32 sums may differ by an
    // ulp as in the 1.0 fixtures (the conformance test holds them to 1e-6 of the diagonal)
    if (c.bones.residual_zero) assert.equal(differ, 0, `${c.name}: ${differ} values differ from the Python evaluator`);
  });
}

test('the refused fixtures: a clip requiring an unknown feature is refused with a message naming it', () => {
  for (const r of man.refused) {
    const names = [r.names].flat();
    const bytes = readBytes(join(FIXTURES, r.clip));
    assert.throws(() => decodeClipFile(bytes), (e) => {
      assert.ok(e instanceof ClipFormatError);
      for (const n of names) assert.match(e.message, new RegExp(`"${n}"`));
      assert.match(e.message, /it supports: bones/);
      return true;
    });
  }
});

test('pdeanim-eval plays a bone fixture and exits 2 naming the feature of a clip it cannot read', () => {
  const bin = join(FIXTURES, '..', '..', 'bin', 'pdeanim-eval.mjs');
  const tmp = mkdtempSync(join(tmpdir(), 'pdeanim-bones-'));
  try {
    const c = boneFixtures.find((x) => !x.bones.residual_zero);
    const out = join(tmp, 'f.bin');
    const ok = spawnSync(process.execPath, [bin, join(FIXTURES, c.clip), '--t', '0,0.5,1', '--out', out], { encoding: 'utf8' });
    assert.equal(ok.status, 0, ok.stderr);
    const got = new Float32Array(readBytes(out).buffer);
    const ev = createEvaluator(decodeClipFile(readBytes(join(FIXTURES, c.clip))));
    assert.deepEqual(Array.from(got), [0, 0.5, 1].flatMap((t) => Array.from(ev.evaluate(t))));
    const bad = spawnSync(process.execPath, [bin, join(FIXTURES, man.refused[0].clip), '--t', '0', '--out', out], { encoding: 'utf8' });
    assert.equal(bad.status, 2);
    assert.match(bad.stderr, new RegExp(`requires format feature\\(s\\) "${man.refused[0].names}"`));
  } finally {
    rmSync(tmp, { recursive: true, force: true });
  }
});
