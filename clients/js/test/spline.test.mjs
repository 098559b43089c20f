// Format version 5 (docs/format.md §3.11): natural-spline time tangents. Besides the version 5 conformance
// fixtures (conformance.test.mjs), the clips here are the version 2 and 3 fixtures re-encoded as version 5
// (test/helpers.mjs, with the synthetic fixtures' repeated segment boundary moved: version 5 with tangents
// needs strictly increasing ones). The tangent solve must equal a dense Gaussian elimination of the spline's system and give a C2
// spline with zero second derivative at the ends; the CPU evaluator must equal a naive float64 evaluation of
// the Hermite form with those tangents; version 4 clips keep their Catmull-Rom cubic.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import {
  createEvaluator,
  decodeClip,
  decodeClipFile,
  hermiteWeights,
} from '../src/index.js';
import { naturalSplineTangents, splineWeights } from '../src/dynamic.js';
import {
  FIXTURES,
  coefficientsV4,
  manifest,
  naiveEvaluate,
  readBytes,
  versionFiveCases,
  versionFourCases,
  worstDeviation,
} from './helpers.mjs';

const man = manifest();
const cases = versionFiveCases();
const v4cases = versionFourCases();

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
 * The natural spline's tangents T_0..T_S of knot values P (S+1) at times t from the full (S+1) x (S+1)
 * system of §3.11, by Gaussian elimination with partial pivoting on the dense matrix (float64).
 */
function denseTangents(t, P) {
  const S = t.length - 1;
  const n = S + 1;
  const A = Array.from({ length: n }, () => new Float64Array(n + 1)); // augmented rows
  const d = (j) => (P[j + 1] - P[j]) / (t[j + 1] - t[j]);
  A[0][0] = 2;
  A[0][1] = 1;
  A[0][n] = 3 * d(0);
  for (let j = 1; j < S; j++) {
    const dl = t[j] - t[j - 1];
    const dr = t[j + 1] - t[j];
    A[j][j - 1] = dr;
    A[j][j] = 2 * (dl + dr);
    A[j][j + 1] = dl;
    A[j][n] = 3 * (dr * d(j - 1) + dl * d(j));
  }
  A[S][S - 1] += 1; // (with S = 1 row 0 and row S share no entry: += keeps both rows' terms)
  A[S][S] += 2;
  A[S][n] = 3 * d(S - 1);
  for (let k = 0; k < n; k++) {
    let best = k;
    for (let i = k + 1; i < n; i++) if (Math.abs(A[i][k]) > Math.abs(A[best][k])) best = i;
    [A[k], A[best]] = [A[best], A[k]];
    for (let i = k + 1; i < n; i++) {
      const f = A[i][k] / A[k][k];
      for (let j = k; j <= n; j++) A[i][j] -= f * A[k][j];
    }
  }
  const T = new Float64Array(n);
  for (let k = n - 1; k >= 0; k--) {
    let acc = A[k][n];
    for (let j = k + 1; j < n; j++) acc -= A[k][j] * T[j];
    T[k] = acc / A[k][k];
  }
  return T;
}

/**
 * Second derivatives in t of the Hermite cubic of segment j at its start and end (values P, tangents T).
 */
function secondDerivatives(t, P, T, j) {
  const h = t[j + 1] - t[j];
  const slope = (P[j + 1] - P[j]) / h;
  return [(6 * slope - 4 * T[j] - 2 * T[j + 1]) / h, (-6 * slope + 2 * T[j] + 4 * T[j + 1]) / h];
}

test('the tangent solve equals a dense elimination of the system of §3.11, for every column at once', () => {
  const rnd = random(5);
  for (const S of [1, 2, 3, 4, 7, 12, 40]) {
    for (const t of [Array.from({ length: S + 1 }, (_, j) => j / S), boundaries(S, rnd)]) {
      const cols = 5;
      const values = Float64Array.from({ length: (S + 1) * cols }, () => 10 * (rnd() - 0.5));
      for (let j = 0; j <= S; j++) values[j * cols + 4] = 3.25; // a constant column
      const T = naturalSplineTangents(t, values, cols);
      for (let k = 0; k < cols; k++) {
        const P = Array.from({ length: S + 1 }, (_, j) => values[j * cols + k]);
        const want = denseTangents(t, P);
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
    for (let j = 0; j < S; j++) curvature = Math.max(curvature, ...secondDerivatives(t, P, T, j).map(Math.abs));
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

test('the four weights of version 5: Δ h10, h00, h01, Δ h11 in float64, rounded to float32', () => {
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
  const c = cases[0];
  const ev = createEvaluator(decodeClip(c.topology, c.coefficients));
  assert.equal(ev.natural, true);
  for (const t of [0.05, 0.4, 0.93]) {
    ev.prepare(t);
    const [s, tt] = ev.loc;
    const ref = splineWeights(ev.clip.segmentT, s, tt, new Float64Array(4));
    assert.deepEqual(Array.from(ev.cubicWeights), Array.from(ref, Math.fround));
  }
});

test('version 5 clips are read: knots as version 4 (rank 0 or a basis), tangents 0/1, natural splines', () => {
  assert.ok(cases.length >= 10);
  for (const c of cases) {
    const clip = decodeClip(c.topology, c.coefficients);
    const v4 = decodeClip(c.topology, coefficientsV4(c.original, { tangents: () => 1, segmentT: c.segmentT }));
    assert.equal(clip.header.format_version, 5, c.name);
    assert.equal(clip.tangentSpline, 'natural', c.name);
    assert.equal(v4.tangentSpline, 'catmull-rom', c.name);
    assert.deepEqual(clip.knots, v4.knots, c.name); // bit for bit the knots of version 4 (so of 2 or 3)
    assert.equal(clip.header.knot_rank, decodeClip(c.topology, c.original).header.knot_rank ?? 0, c.name);
    assert.ok(clip.tangents.some((x) => x === 1) && clip.tangents.some((x) => x === 0), c.name);
    assert.ok(clip.segmentT.every((x, j) => j === 0 || x > clip.segmentT[j - 1]), c.name);
  }
  assert.ok(cases.some((c) => decodeClip(c.topology, c.coefficients).header.knot_rank === 0));
  assert.ok(cases.some((c) => decodeClip(c.topology, c.coefficients).header.knot_rank >= 1));
  // older versions: no tangents, no spline
  for (const c of man.cases.filter((x) => x.kind === 'dynamic-pde' && x.format_version < 4)) {
    assert.equal(decodeClipFile(readBytes(join(FIXTURES, c.clip))).tangentSpline, null, c.name);
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
      const T = denseTangents(clip.segmentT, P);
      const scale = Math.max(1e-30, ...T.map(Math.abs));
      T.forEach((x, j) => assert.ok(Math.abs(ev.tangentFields[j * N + i] - x) <= 1e-6 * scale, `${c.name}`));
    }
  }
});

for (const c of cases) {
  test(`version 5 CPU evaluation equals the naive float64 Hermite form: ${c.name}`, () => {
    const clip = decodeClip(c.topology, c.coefficients);
    const ev = createEvaluator(clip);
    assert.ok(ev.cubic !== null && ev.natural);
    const tol = 1e-6 * c.diagonal;
    let cubicFrames = 0;
    for (const t of c.t) {
      const got = ev.evaluate(t);
      const want = naiveEvaluate(clip, t, denseTangents);
      const worst = worstDeviation(got, want);
      assert.ok(worst <= tol, `t = ${t}: max deviation ${worst} > ${tol}`);
      if (ev.cubicSegment[ev.loc[0]]) cubicFrames++;
    }
    assert.ok(cubicFrames > c.t.length / 2, `${cubicFrames} of ${c.t.length} frames use the cubic`);
  });
}

test('the natural spline passes through the knots: at every boundary it equals the straight line', () => {
  for (const c of cases) {
    const clip = decodeClip(c.topology, c.coefficients);
    const S = clip.nSegments;
    const linear = (s, cc) => S < 2 || s !== cc % S;
    const lines = createEvaluator(
      decodeClip(c.topology, coefficientsV4(c.original, { linear, segmentT: c.segmentT })),
    );
    const ev = createEvaluator(clip);
    for (const t of clip.segmentT) {
      const worst = worstDeviation(ev.evaluate(t), lines.evaluate(t));
      assert.ok(worst <= 1e-6 * c.diagonal, `${c.name} t = ${t}: ${worst}`);
    }
  }
});

test('with one segment the natural spline is the straight line', () => {
  const c = cases.find((x) => decodeClip(x.topology, x.original).nSegments === 1);
  const all = decodeClip(c.topology, coefficientsV4(c.original, { version: 5, tangents: () => 1 }));
  const ev = createEvaluator(all);
  assert.ok(ev.natural && ev.cubic.every((x) => x === 1)); // every item is linear in this clip
  const before = createEvaluator(decodeClip(c.topology, c.original));
  for (const t of c.t) {
    assert.ok(worstDeviation(ev.evaluate(t), before.evaluate(t)) <= 1e-6 * c.diagonal, `t = ${t}`);
  }
  // both tangents are the chord
  const N = all.nVertices * 3;
  const delta = all.segmentT[1] - all.segmentT[0];
  for (let i = 0; i < N; i++) {
    const chord = Math.fround((ev.fields[N + i] - ev.fields[i]) / delta);
    assert.equal(ev.tangentFields[i], chord);
    assert.equal(ev.tangentFields[N + i], chord);
  }
});

test('tangents all 0 in version 5 give the positions of the original clip, bit for bit', () => {
  for (const c of cases) {
    const zero = coefficientsV4(c.original, { version: 5, tangents: () => 0, segmentT: c.segmentT });
    const strict = coefficientsV4(c.original, { tangents: () => 0, segmentT: c.segmentT });
    const a = createEvaluator(decodeClip(c.topology, zero));
    const b = createEvaluator(decodeClip(c.topology, strict));
    assert.equal(a.cubic, null, c.name); // the plain path
    assert.equal(a.tangentFields, null, c.name);
    for (const t of c.t) assert.deepEqual(a.evaluate(t), b.evaluate(t), `${c.name} t = ${t}`);
  }
});

test('version 5 and version 4 differ where the motion curves; version 4 keeps its Catmull-Rom cubic', () => {
  let differ = 0;
  for (const c of cases) {
    const S = decodeClip(c.topology, c.original).nSegments;
    const tangents = (cc, w) => (cc % 3 === 0 ? 1 : cc % 3 === 1 ? Number(w === 1) : 0);
    const linear = (s, cc) => s !== cc % S;
    const v4coef = coefficientsV4(c.original, { tangents, linear, segmentT: c.segmentT });
    const v4clip = decodeClip(c.topology, v4coef);
    const v4 = createEvaluator(v4clip);
    const v5 = createEvaluator(decodeClip(c.topology, c.coefficients));
    assert.equal(v4.natural, false, c.name);
    assert.equal(v4.tangentFields, null, c.name);
    let worst = 0;
    for (const t of c.t) {
      const a = v4.evaluate(t);
      worst = Math.max(worst, worstDeviation(a, v5.evaluate(t)));
      // version 4: the Catmull-Rom weights on knots lo(s), s, s+1, hi(s+1), as before
      const ref = hermiteWeights(v4clip.segmentT, v4.loc[0], v4.loc[1], new Float64Array(4));
      assert.deepEqual(Array.from(v4.cubicWeights), Array.from(ref, Math.fround));
    }
    // S >= 3: the spline's tangents reach beyond the neighbouring knots (S = 2: they can agree)
    if (S >= 3 && worst > 1e-4 * c.diagonal) differ++;
  }
  const longer = cases.filter((c) => decodeClip(c.topology, c.original).nSegments >= 3).length;
  assert.ok(differ >= longer - 1, `${differ} of ${longer}`);
  // the version 4 clips of tangents.test.mjs keep their layout: no tangent fields, Catmull-Rom weights
  for (const c of v4cases) {
    const ev = createEvaluator(decodeClip(c.topology, c.coefficients));
    assert.equal(ev.natural, false);
    assert.equal(ev.tangentFields, null);
  }
});

test('version 5: looping clips repeat with period 1; open clips refuse t outside [0, 1]', () => {
  for (const c of cases) {
    const ev = createEvaluator(decodeClip(c.topology, c.coefficients));
    const diff = (x, y) => worstDeviation(ev.evaluate(x), ev.evaluate(y));
    if (c.looping) assert.ok(diff(0.2, 3.2) <= 1e-6 * c.diagonal, c.name);
    else {
      assert.throws(() => ev.evaluate(-2), RangeError, c.name);
      assert.throws(() => ev.evaluate(7), RangeError, c.name);
    }
  }
});
