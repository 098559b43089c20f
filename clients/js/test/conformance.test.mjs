// Every conformance fixture written by the Python library evaluates to the same positions in JS.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import {
  FORMAT_VERSION,
  TIME_SPLINE,
  createEvaluator,
  decodeClip,
  decodeClipFile,
  loadClipFile,
  splitClipFile,
} from '../src/index.js';
import { FIXTURES, caseTolerance, expected, manifest, readBytes } from './helpers.mjs';

const man = manifest();

test('the fixture set covers every kind, motion, parameterisation, looping mode and feature', () => {
  const cases = man.cases;
  assert.ok(cases.length >= 10);
  const kinds = new Set(cases.map((c) => c.kind));
  assert.deepEqual([...kinds].sort(), ['cyclic-spine', 'dynamic-pde']);
  const dyn = cases.filter((c) => c.kind === 'dynamic-pde');
  assert.deepEqual([...new Set(dyn.map((c) => c.motion))].sort(), ['absolute', 'displacement', 'rigid']);
  assert.deepEqual([...new Set(dyn.map((c) => c.param_mode))].sort(), ['chord', 'paper']);
  assert.ok(dyn.some((c) => c.looping) && dyn.some((c) => !c.looping));
  // 1.0, but the bone layer's (format 1.1, required "bones"; test/bones.test.mjs covers them)
  // (and the streamable layout's, format 1.2 with "stream" in required: test/stream.test.mjs covers it too)
  const version = (c) => (c.stream ? '1.2' : c.bones ? '1.1' : FORMAT_VERSION);
  assert.ok(cases.every((c) => c.format_version === version(c)), 'fixtures are 1.0, bones 1.1 or stream 1.2');
  // every optional feature of the layout, alone and together, each in looping and open clips where the
  // writer allows it: a fixture the tests below rely on must exist (a vanished file fails here)
  const basis = dyn.filter((c) => c.knot_rank > 0);
  const spline = dyn.filter((c) => c.spline_items > 0);
  assert.ok(basis.some((c) => c.looping) && basis.some((c) => !c.looping), 'knot basis fixtures');
  assert.ok(spline.some((c) => c.motion === 'rigid') && spline.some((c) => c.looping), 'spline fixtures');
  assert.ok(dyn.some((c) => c.knot_rank > 0 && c.spline_items > 0), 'basis and spline together');
  assert.ok(dyn.some((c) => c.knot_rank === 0 && c.spline_items === 0), 'neither');
});

test('fixtures decode to their manifest features: knot rank below S + 1, time models 0/1', () => {
  for (const c of man.cases.filter((x) => x.kind === 'dynamic-pde')) {
    const { topology, coefficients } = splitClipFile(readBytes(join(FIXTURES, c.clip)));
    const clip = decodeClip(topology, coefficients);
    if (c.stream) {
      // the streamable layout: its windows as the manifest lists them (their data decode when evaluated)
      assert.ok(clip.windowed && clip.nWindows === c.stream.n_windows, c.name);
      assert.deepEqual(clip.index.map((w) => [w.a, w.b]), c.stream.knots, c.name);
      assert.deepEqual(clip.index.map((w) => [w.t0, w.t1]), c.stream.t, c.name);
      assert.equal(clip.header.knot_rank, c.knot_rank, c.name);
      continue;
    }
    assert.equal(clip.topologyHeader.format_version, FORMAT_VERSION, c.name);
    const r = clip.header.knot_rank;
    assert.equal(r, c.knot_rank, c.name);
    assert.ok(Number.isInteger(r) && r >= 0 && r < clip.nSegments + 1, c.name);
    assert.ok([1, 2].includes(clip.header.knot_differences), c.name);
    if (r > 0 && c.looping) {
      // a looping clip's basis has equal first and last columns: its first and last knots are equal
      const n = clip.nCurves * 12;
      assert.deepEqual(clip.knots.subarray(0, n), clip.knots.subarray(clip.nSegments * n), c.name);
    }
    const splineItems = clip.timeModel ? clip.timeModel.reduce((a, x) => a + (x === TIME_SPLINE), 0) : 0;
    assert.equal(splineItems, c.spline_items, c.name);
    if (splineItems) {
      assert.ok(clip.timeModel.every((x) => x === 0 || x === 1), c.name);
      assert.ok(clip.segmentT.every((x, j) => j === 0 || x > clip.segmentT[j - 1]), c.name);
    }
  }
});

for (const c of man.cases) {
  test(`fixture ${c.name} matches the Python evaluator to 1e-6 of the diagonal plus 2^-20 of its coordinates`, async () => {
    const clip = await loadClipFile(readBytes(join(FIXTURES, c.clip)));
    assert.equal(clip.kind, c.kind);
    assert.equal(clip.nVertices, c.n_vertices);
    assert.equal(clip.looping, c.looping);
    if (c.kind === 'dynamic-pde') assert.equal(clip.header.format_version, c.format_version);
    const ev = createEvaluator(clip);
    const want = expected(c);
    const N = c.n_vertices * 3;
    assert.equal(want.length, c.t.length * N);
    const out = new Float32Array(N);
    const tol = caseTolerance(c, want); // format §6: grows with the coordinates (float32 rounding)
    c.t.forEach((t, k) => {
      if (!c.looping && !(t >= 0 && t <= 1)) {
        // open clips take t in [0, 1] only, as `pdeanim frame` and the HTTP frame route
        assert.throws(() => ev.evaluate(t, out), /must lie in \[0, 1\] for this clip \(it does not loop\)/);
        return;
      }
      ev.evaluate(t, out);
      let worst = 0;
      for (let i = 0; i < N; i++) worst = Math.max(worst, Math.abs(out[i] - want[k * N + i]));
      assert.ok(worst <= tol, `t = ${t}: max deviation ${worst} > ${tol}`);
    });
  });
}

test('decoding the two parts equals decoding the CLIP file', () => {
  const c = man.cases.find((x) => x.motion === 'rigid');
  const bytes = readBytes(join(FIXTURES, c.clip));
  const { topology, coefficients } = splitClipFile(bytes);
  const a = createEvaluator(decodeClip(topology.slice(), coefficients.slice())).evaluate(0.61);
  const b = createEvaluator(decodeClipFile(bytes)).evaluate(0.61);
  assert.deepEqual(a, b);
});

test('looping clips repeat with period 1; open clips refuse t outside [0, 1] (RangeError)', () => {
  for (const c of man.cases) {
    const ev = createEvaluator(decodeClipFile(readBytes(join(FIXTURES, c.clip))));
    const diff = (x, y) => Math.max(...ev.evaluate(x).map((v, i) => Math.abs(v - ev.evaluate(y)[i])));
    if (c.looping) assert.ok(diff(0.2, 3.2) <= 1e-6 * c.diagonal, c.name);
    else {
      for (const t of [-2, -1e-9, 1 + 1e-9, 7]) assert.throws(() => ev.evaluate(t), RangeError, c.name);
      assert.equal(ev.evaluate(0).length, c.n_vertices * 3);
      assert.equal(ev.evaluate(1).length, c.n_vertices * 3);
    }
  }
});
