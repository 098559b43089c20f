// The natural-spline time model (docs/format.md §3.5.2, `time_model` 1). The tangent solve must equal a dense
// Gaussian elimination of the spline's system and give a C2 spline with zero second derivative at the ends.
// On the fixtures with spline items, and on variants of the fixtures with other items on the spline, the CPU
// evaluator must equal a naive float64 evaluation of the Hermite form, pass through the knots, and leave the
// items off the spline bit for bit as they are in the same clip without spline items.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { TIME_PDE, TIME_SPLINE, createEvaluator, decodeClip, decodeContainer } from '../src/index.js';
import { naturalSplineTangents, splineWeights } from '../src/dynamic.js';
import {
  caseTolerance,
  denseSplineTangents,
  fixtureParts,
  manifest,
  naiveEvaluate,
  retimed,
  sampleTimes,
  takenTimes,
  withoutStream,
  worstDeviation,
} from './helpers.mjs';

// streamable clips (format 1.2) decode window by window: test/stream.test.mjs checks their tables
const man = withoutStream(manifest());
const dynamic = man.cases.filter((c) => c.kind === 'dynamic-pde' && !c.bones); // bones: test/bones.test.mjs

/**
 * Clips with spline items: the fixtures written with some (as written, name = the fixture's), and every
 * fixture whose boundaries increase strictly with a mix of time models of its own (name '<fixture>-mixed':
 * every item of some curves on the spline, one coordinate of others, none of the rest; spline items next to
 * time pairs in rigid, looping and knot-basis clips): [{name, fixture, topology, coefficients, diagonal,
 * looping, t}], t being the fixture's own times and sampleTimes() of its boundaries.
 */
function splineCases() {
  const out = [];
  for (const c of dynamic) {
    const { topology, coefficients } = fixtureParts(c);
    const segT = decodeClip(topology, coefficients).segmentT; // stored, or derived from the frame times
    const base = { fixture: c, topology, diagonal: c.diagonal, looping: c.looping };
    const t = [...takenTimes(c.t, c.looping), ...sampleTimes(segT, c.looping)];
    if (c.spline_items > 0) out.push({ ...base, name: c.name, coefficients, t });
    if (segT.every((x, j) => j === 0 || x > segT[j - 1]) && segT.length > 2) {
      const timeModel = (cc, w) => (cc % 3 === 0 ? 1 : cc % 3 === 1 ? Number(w === 1) : 0);
      out.push({ ...base, name: `${c.name}-mixed`, coefficients: retimed(coefficients, { timeModel }), t });
    }
  }
  return out;
}

const cases = splineCases();

/** A case's clip with every item on the paper's time pairs (the spline items' constants stay 0: linear). */
function withoutSpline(c) {
  return decodeClip(c.topology, retimed(c.coefficients, { timeModel: () => TIME_PDE }));
}

/** A deterministic pseudo-random generator (mulberry32) of floats in [0, 1). */
function random(seed) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

/** Strictly increasing boundaries 0 = t_0 < ... < t_S = 1 with uneven segments (ratios up to ~50). */
function boundaries(S, rnd) {
  const len = Array.from({ length: S }, () => 0.02 + rnd());
  const total = len.reduce((a, b) => a + b, 0);
  const t = [0];
  for (let j = 0; j < S; j++) t.push(t[j] + len[j] / total);
  t[S] = 1;
  return t;
}

/**
 * Second derivatives in t of the Hermite cubic of segment j at its start and end (values P, tangents T).
 */
function secondDerivatives(t, P, T, j) {
  const h = t[j + 1] - t[j];
  const slope = (P[j + 1] - P[j]) / h;
  return [(6 * slope - 4 * T[j] - 2 * T[j + 1]) / h, (-6 * slope + 2 * T[j] + 4 * T[j + 1]) / h];
}

test('the tangent solve equals a dense elimination of the system of §3.5.2, for every column at once', () => {
  const rnd = random(5);
  for (const S of [1, 2, 3, 4, 7, 12, 40]) {
    for (const t of [Array.from({ length: S + 1 }, (_, j) => j / S), boundaries(S, rnd)]) {
      const cols = 5;
      const values = Float64Array.from({ length: (S + 1) * cols }, () => 10 * (rnd() - 0.5));
      for (let j = 0; j <= S; j++) values[j * cols + 4] = 3.25; // a constant column
      const T = naturalSplineTangents(t, values, cols);
      for (let k = 0; k < cols; k++) {
        const P = Array.from({ length: S + 1 }, (_, j) => values[j * cols + k]);
        const want = denseSplineTangents(t, P);
        const scale = Math.max(1, ...want.map(Math.abs));
        for (let j = 0; j <= S; j++) {
          assert.ok(Math.abs(T[j * cols + k] - want[j]) <= 1e-12 * scale, `S = ${S} column ${k} knot ${j}`);
        }
      }
      // a constant track has zero tangents
      for (let j = 0; j <= S; j++) assert.equal(T[j * cols + 4], 0);
    }
  }
});

test('the spline is C2 at every interior knot, with zero second derivative at both ends (natural)', () => {
  const rnd = random(17);
  for (const S of [2, 3, 5, 11, 30]) {
    const t = boundaries(S, rnd);
    const P = Float64Array.from({ length: S + 1 }, () => rnd() - 0.5);
    const T = naturalSplineTangents(t, P, 1);
    let curvature = 0;
    for (let j = 0; j < S; j++) {
      curvature = Math.max(curvature, ...secondDerivatives(t, P, T, j).map(Math.abs));
    }
    const tol = 1e-10 * Math.max(1, curvature);
    assert.ok(Math.abs(secondDerivatives(t, P, T, 0)[0]) <= tol, `S = ${S}: start`);
    assert.ok(Math.abs(secondDerivatives(t, P, T, S - 1)[1]) <= tol, `S = ${S}: end`);
    for (let j = 1; j < S; j++) {
      const left = secondDerivatives(t, P, T, j - 1)[1];
      const right = secondDerivatives(t, P, T, j)[0];
      assert.ok(Math.abs(left - right) <= tol, `S = ${S} knot ${j}: ${left} vs ${right}`);
    }
    // a cubic polynomial with zero second derivative at both ends is a line: reproduced exactly
    const line = Float64Array.from(t, (x) => 0.5 - 2 * x);
    naturalSplineTangents(t, line, 1).forEach((x) => assert.ok(Math.abs(x + 2) < 1e-12, `${x}`));
  }
});

test('with one segment both tangents are the chord; float32 output is the float64 solve rounded', () => {
  const T = naturalSplineTangents([0.25, 0.75], Float32Array.from([1, -2, 3, 0.5, 0, 3]), 3);
  assert.deepEqual(Array.from(T), [-1, 4, 0, -1, 4, 0]);
  const rnd = random(3);
  const t = boundaries(6, rnd);
  const values = Float32Array.from({ length: 7 * 9 }, () => rnd() - 0.5);
  const wide = naturalSplineTangents(t, values, 9);
  const narrow = naturalSplineTangents(t, values, 9, new Float32Array(values.length));
  assert.deepEqual(narrow, Float32Array.from(wide));
  assert.throws(() => naturalSplineTangents([0], new Float64Array(1), 1), RangeError);
  assert.throws(() => naturalSplineTangents([0, 1], new Float64Array(3), 1), RangeError);
});

test('the solve in blocks of columns equals the column-by-column solve, bit for bit', () => {
  // (S+1) x cols above the 2^20 values of a block: several blocks, the last one partial
  const rnd = random(11);
  const t = boundaries(4, rnd);
  const cols = (1 << 18) + 3;
  const values = new Float32Array(5 * cols);
  for (let i = 0; i < values.length; i++) values[i] = rnd() - 0.5;
  const all = naturalSplineTangents(t, values, cols, new Float32Array(values.length));
  for (const k of [0, 1, 209714, 209715, 209716, cols - 1]) {
    const column = Float32Array.from({ length: 5 }, (_, j) => values[j * cols + k]);
    const one = naturalSplineTangents(t, column, 1);
    for (let j = 0; j < 5; j++) assert.equal(all[j * cols + k], Math.fround(one[j]), `column ${k} knot ${j}`);
  }
});

test('the four weights: Δ h10, h00, h01, Δ h11 in float64, rounded to float32 by the evaluator', () => {
  const segT = [0, 0.25, 0.5, 0.6, 1];
  const tau = 0.3;
  const w = splineWeights(segT, 1, tau, new Float64Array(4));
  const d = 0.25;
  const want = [
    d * tau * (1 - tau) ** 2,
    (1 + 2 * tau) * (1 - tau) ** 2,
    tau * tau * (3 - 2 * tau),
    d * tau * tau * (tau - 1),
  ];
  want.forEach((x, i) => assert.ok(Math.abs(w[i] - x) < 1e-16, `${i}: ${w[i]} vs ${x}`));
  // the knots' weights sum to 1 (a constant track stays constant); the ends give the knots
  assert.ok(Math.abs(w[1] + w[2] - 1) < 1e-15);
  const plus = (x) => x + 0; // -0 as 0
  assert.deepEqual(splineWeights(segT, 2, 0, [0, 0, 0, 0]).map(plus), [0, 1, 0, 0]);
  assert.deepEqual(splineWeights(segT, 2, 1, [0, 0, 0, 0]).map(plus), [0, 0, 1, 0]);
  for (const c of cases.slice(0, 3)) {
    const ev = createEvaluator(decodeClip(c.topology, c.coefficients));
    for (const t of [0.05, 0.4, 0.93]) {
      ev.prepare(t);
      const [s, tt] = ev.loc;
      const ref = splineWeights(ev.clip.segmentT, s, tt, new Float64Array(4));
      assert.deepEqual(Array.from(ev.cubicWeights), Array.from(ref, Math.fround));
    }
  }
});

test('spline items: time_model 1 in every segment with m = 0; the knots do not depend on it', () => {
  const written = cases.filter((c) => c.name === c.fixture.name);
  assert.ok(written.length >= 5);
  // the written ones cover rigid and looping clips, and both knot encodings
  assert.ok(written.some((c) => c.fixture.motion === 'rigid') && written.some((c) => c.looping));
  assert.ok(written.some((c) => c.fixture.knot_rank === 0) && written.some((c) => c.fixture.knot_rank > 0));
  assert.ok(cases.length >= 2 * written.length);
  for (const c of cases) {
    const clip = decodeClip(c.topology, c.coefficients);
    const C = clip.nCurves;
    assert.equal(clip.timeModel.length, C * 3, c.name);
    assert.ok(clip.timeModel.every((x) => x === TIME_PDE || x === TIME_SPLINE), c.name);
    assert.ok(clip.timeModel.includes(TIME_SPLINE), c.name);
    // (a written fixture may have every item on the spline; the '-mixed' ones have both)
    if (c.name !== c.fixture.name) assert.ok(clip.timeModel.includes(TIME_PDE), c.name);
    for (let i = 0; i < clip.m.length; i++) {
      if (clip.timeModel[i % (C * 3)] === TIME_SPLINE) assert.equal(clip.m[i], 0, c.name);
    }
    assert.ok(clip.segmentT.every((x, j) => j === 0 || x > clip.segmentT[j - 1]), c.name);
    const ev = createEvaluator(clip);
    assert.equal(ev.spline, clip.timeModel, c.name);
    // the same part with every item on the paper's time pairs: bit for bit the same knots
    const paper = withoutSpline(c);
    assert.deepEqual(paper.knots, clip.knots, c.name);
    assert.equal(paper.timeModel, null, c.name);
  }
  // fixtures without spline items: no time model on the clip, the plain path
  for (const c of dynamic.filter((x) => x.spline_items === 0)) {
    const { topology, coefficients } = fixtureParts(c);
    const clip = decodeClip(topology, coefficients);
    assert.equal(clip.timeModel, null, c.name);
    const ev = createEvaluator(clip);
    assert.equal(ev.spline, null, c.name);
    assert.equal(ev.tangentFields, null, c.name);
  }
});

test('the evaluator solves the tangent fields once: the float32 knot fields, in float64, rounded', () => {
  for (const c of cases) {
    const clip = decodeClip(c.topology, c.coefficients);
    const ev = createEvaluator(clip);
    const N = clip.nVertices * 3;
    assert.equal(ev.tangentFields.length, ev.fields.length, c.name);
    const want = naturalSplineTangents(clip.segmentT, ev.fields, N);
    assert.deepEqual(ev.tangentFields, Float32Array.from(want), c.name);
    // and the tangents of the dense system, per value (a few values: the dense solve is slow)
    for (const i of [0, 7, N - 1]) {
      const P = Array.from({ length: clip.nSegments + 1 }, (_, j) => ev.fields[j * N + i]);
      const T = denseSplineTangents(clip.segmentT, P);
      const scale = Math.max(1e-30, ...T.map(Math.abs));
      T.forEach((x, j) => assert.ok(Math.abs(ev.tangentFields[j * N + i] - x) <= 1e-6 * scale, `${c.name}`));
    }
  }
});

for (const c of cases) {
  test(`CPU evaluation equals the naive float64 Hermite form: ${c.name}`, () => {
    const clip = decodeClip(c.topology, c.coefficients);
    const ev = createEvaluator(clip);
    assert.notEqual(ev.spline, null);
    for (const t of c.t) {
      const want = naiveEvaluate(clip, t);
      const tol = caseTolerance(c, want); // 1e-6 of the diagonal, plus float32 rounding of far coordinates
      const worst = worstDeviation(ev.evaluate(t), want);
      assert.ok(worst <= tol, `t = ${t}: max deviation ${worst} > ${tol}`);
    }
  });
}

test('the natural spline passes through the knots: at every boundary it equals the time pairs', () => {
  for (const c of cases) {
    const clip = decodeClip(c.topology, c.coefficients);
    const pairs = createEvaluator(withoutSpline(c));
    const ev = createEvaluator(clip);
    for (const t of clip.segmentT) {
      const worst = worstDeviation(ev.evaluate(t), pairs.evaluate(t));
      assert.ok(worst <= 1e-6 * c.diagonal, `${c.name} t = ${t}: ${worst}`);
    }
  }
});

test('the spline differs from the straight line where the motion curves (the tests above see it)', () => {
  // the same clips with the spline items on linear time pairs move along the chords instead
  let curved = 0;
  for (const c of cases) {
    const lines = createEvaluator(withoutSpline(c));
    const ev = createEvaluator(decodeClip(c.topology, c.coefficients));
    let worst = 0;
    for (const t of c.t) worst = Math.max(worst, worstDeviation(ev.evaluate(t), lines.evaluate(t)));
    if (worst > 1e-3 * c.diagonal) curved++;
  }
  assert.ok(curved >= cases.length - 2, `${curved} of ${cases.length}`);
});

test('items off the spline evaluate bit for bit as in the same clip without spline items', () => {
  let rigidCompared = 0;
  for (const c of cases) {
    const clip = decodeClip(c.topology, c.coefficients);
    const ev = createEvaluator(clip);
    const plain = createEvaluator(withoutSpline(c));
    const off = (cc, w) => clip.timeModel[cc * 3 + w] === TIME_PDE;
    let compared = 0;
    for (const t of c.t) {
      const got = ev.evaluate(t);
      const want = plain.evaluate(t);
      for (let v = 0; v < clip.nVertices; v++) {
        const cc = clip.curveOf[v];
        // (rigid: the rotation mixes the coordinates, so all three of the curve's items must be off)
        const curveOff = off(cc, 0) && off(cc, 1) && off(cc, 2);
        for (let w = 0; w < 3; w++) {
          if (clip.rigid ? !curveOff : !off(cc, w)) continue;
          assert.equal(got[v * 3 + w], want[v * 3 + w], `${c.name} t = ${t} v = ${v}`);
          compared++;
        }
      }
    }
    const someOff = clip.timeModel.includes(TIME_PDE);
    if (!clip.rigid && someOff) assert.ok(compared > 0, c.name);
    if (clip.rigid) rigidCompared += compared;
  }
  assert.ok(rigidCompared > 0, 'no rigid clip has a curve off the spline');
});

test('with one segment the natural spline is the straight line: both tangents are the chord', () => {
  const segments = (x) => decodeContainer(fixtureParts(x).coefficients.slice()).header.n_segments;
  const c = dynamic.find((x) => segments(x) === 1);
  const { topology, coefficients } = fixtureParts(c);
  const all = decodeClip(topology, retimed(coefficients, { timeModel: () => TIME_SPLINE }));
  const ev = createEvaluator(all);
  assert.ok(all.timeModel.every((x) => x === TIME_SPLINE));
  const lines = createEvaluator(decodeClip(topology, retimed(coefficients, { linear: () => true })));
  assert.equal(lines.spline, null);
  for (const t of [...takenTimes(c.t, c.looping), ...sampleTimes(all.segmentT, c.looping)]) {
    assert.ok(worstDeviation(ev.evaluate(t), lines.evaluate(t)) <= 1e-6 * c.diagonal, `t = ${t}`);
  }
  const N = all.nVertices * 3;
  const delta = all.segmentT[1] - all.segmentT[0];
  for (let i = 0; i < N; i++) {
    const chord = Math.fround((ev.fields[N + i] - ev.fields[i]) / delta);
    assert.equal(ev.tangentFields[i], chord);
    assert.equal(ev.tangentFields[N + i], chord);
  }
});

test('spline clips: looping ones repeat with period 1; open ones refuse t outside [0, 1] (RangeError)', () => {
  for (const c of cases) {
    const ev = createEvaluator(decodeClip(c.topology, c.coefficients));
    assert.notEqual(ev.spline, null, c.name);
    if (c.looping) assert.ok(worstDeviation(ev.evaluate(0.2), ev.evaluate(3.2)) <= 1e-6 * c.diagonal, c.name);
    else {
      for (const t of [-2, -1e-9, 1 + 1e-9, 7]) assert.throws(() => ev.evaluate(t), RangeError, c.name);
      assert.equal(ev.evaluate(1).length, c.fixture.n_vertices * 3, c.name);
    }
  }
});
