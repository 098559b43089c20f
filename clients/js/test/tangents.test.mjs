// Format version 4 (docs/format.md §3.10): Catmull-Rom time tangents. Until the Python side writes version 4
// fixtures, the clips are the version 2 and 3 fixtures re-encoded as version 4 (test/helpers.mjs). The CPU
// evaluator must equal a naive float64 evaluation of the Hermite form (tangents T_j, not the expanded
// weights); tangents 0 must change nothing, bit for bit; version 1-3 clips keep the plain path.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import {
  createEvaluator,
  decodeClip,
  decodeClipFile,
  decodeContainer,
  hermiteWeights,
  splitClipFile,
} from '../src/index.js';
import {
  FIXTURES,
  centralTangents,
  coefficientsV4,
  encodeContainer,
  manifest,
  naiveEvaluate,
  readBytes,
  versionFourCases,
  worstDeviation,
} from './helpers.mjs';

const man = manifest();
const cases = versionFourCases();

test('version 4 clips are read: knot_rank 0 decodes as version 2, 1..S+1 as version 3; tangents 0/1', () => {
  assert.ok(cases.length >= 10);
  for (const c of cases) {
    const clip = decodeClip(c.topology, c.coefficients);
    const before = decodeClip(c.topology, c.original);
    assert.equal(clip.header.format_version, 4, c.name);
    assert.equal(clip.header.knot_rank, before.header.knot_rank ?? 0, c.name);
    assert.deepEqual(clip.knots, before.knots, c.name); // bit for bit the knots of version 2 or 3
    assert.deepEqual(Array.from(clip.tangents), Array.from({ length: clip.nCurves * 3 }, (_, i) => {
      const cc = Math.floor(i / 3);
      return cc % 3 === 0 ? 1 : cc % 3 === 1 ? Number(i % 3 === 1) : 0;
    }));
    assert.equal(before.tangents, null, c.name); // versions 1-3: no tangents
  }
  // both kinds of basis occur: rank 0 (from version 2) and rank >= 1 (from version 3)
  assert.ok(cases.some((c) => decodeClip(c.topology, c.coefficients).header.knot_rank === 0));
  assert.ok(cases.some((c) => decodeClip(c.topology, c.coefficients).header.knot_rank >= 1));
});

for (const c of cases) {
  test(`version 4 CPU evaluation equals the naive float64 Hermite form: ${c.name}`, () => {
    const clip = decodeClip(c.topology, c.coefficients);
    const ev = createEvaluator(clip);
    assert.ok(ev.cubic !== null);
    const tol = 1e-6 * c.diagonal;
    let cubicFrames = 0;
    for (const t of c.t) {
      const got = ev.evaluate(t);
      const want = naiveEvaluate(clip, t, centralTangents);
      const worst = worstDeviation(got, want);
      assert.ok(worst <= tol, `t = ${t}: max deviation ${worst} > ${tol}`);
      if (ev.cubicSegment[ev.loc[0]]) cubicFrames++;
    }
    assert.ok(cubicFrames > c.t.length / 2, `${cubicFrames} of ${c.t.length} frames use the cubic`);
  });
}

test('the cubic differs from the straight line where the motion curves (the tests above see it)', () => {
  // the same clips with tangents 0 (and the same linear constants) move along the chords instead
  let curved = 0;
  for (const c of cases) {
    const { topology, coefficients } = splitClipFile(readBytes(join(FIXTURES, c.fixture.clip)));
    const S = decodeClip(topology, coefficients).nSegments;
    if (S < 2) continue;
    const linear = (s, cc) => s !== cc % S;
    const lines = decodeClip(topology, coefficientsV4(coefficients, { linear }));
    const cubic = decodeClip(c.topology, c.coefficients);
    const a = createEvaluator(lines);
    const b = createEvaluator(cubic);
    let worst = 0;
    for (const t of c.t) worst = Math.max(worst, worstDeviation(a.evaluate(t), b.evaluate(t)));
    if (worst > 1e-3 * c.diagonal) curved++;
  }
  assert.ok(curved >= cases.length - 2, `${curved} of ${cases.length}`);
});

test('tangents all 0 in version 4 give the positions of the original clip, bit for bit', () => {
  for (const c of cases) {
    const zero = coefficientsV4(c.original, { tangents: () => 0 });
    const clip = decodeClip(c.topology, zero);
    const before = decodeClip(c.topology, c.original);
    const a = createEvaluator(clip);
    const b = createEvaluator(before);
    assert.equal(a.cubic, null, c.name); // the plain path
    for (const t of c.t) assert.deepEqual(a.evaluate(t), b.evaluate(t), `${c.name} t = ${t}`);
  }
});

test('tangents on items without linear segments change nothing, bit for bit', () => {
  // every item with tangents, no constant zeroed: only the items that are linear already take the cubic
  for (const c of cases) {
    const all = coefficientsV4(c.original, { tangents: () => 1 });
    const clip = decodeClip(c.topology, all);
    const ev = createEvaluator(clip);
    const before = createEvaluator(decodeClip(c.topology, c.original));
    const C = clip.nCurves;
    for (const t of c.t) {
      const s = ev.locate(t)[0];
      const got = ev.evaluate(t);
      const want = before.evaluate(t);
      for (let v = 0; v < clip.nVertices; v++) {
        for (let w = 0; w < 3; w++) {
          const i = (s * C + clip.curveOf[v]) * 3 + w;
          if (ev.cubic[i] === 1 || clip.rigid) continue; // (rigid: the rotation mixes the coordinates)
          assert.equal(got[v * 3 + w], want[v * 3 + w], `${c.name} t = ${t} v = ${v}`);
        }
      }
    }
  }
});

test('versions 1 to 3 keep the plain path (no tangents), and an array named tangents there is ignored', () => {
  for (const c of man.cases.filter((x) => x.kind === 'dynamic-pde' && x.format_version < 4)) {
    const clip = decodeClipFile(readBytes(join(FIXTURES, c.clip)));
    assert.equal(clip.tangents, null);
    assert.equal(createEvaluator(clip).cubic, null);
  }
  const c = man.cases.find((x) => x.format_version === 3);
  const { topology, coefficients } = splitClipFile(readBytes(join(FIXTURES, c.clip)));
  const { header, arrays } = decodeContainer(coefficients.slice());
  const C = header.n_curves;
  arrays.tangents = { dtype: '<u1', shape: [C, 3], data: new Uint8Array(C * 3).fill(1) };
  const clip = decodeClip(topology, encodeContainer(header, arrays));
  assert.equal(clip.tangents, null);
  const want = createEvaluator(decodeClip(topology, coefficients)).evaluate(0.37);
  assert.deepEqual(createEvaluator(clip).evaluate(0.37), want);
});

test('with one segment both tangents are the chord: the cubic is the straight line', () => {
  const c = cases.find((x) => decodeClip(x.topology, x.original).nSegments === 1);
  const all = decodeClip(c.topology, coefficientsV4(c.original, { tangents: () => 1 }));
  const ev = createEvaluator(all);
  assert.ok(ev.cubic.every((x) => x === 1)); // every item is linear in this clip
  const before = createEvaluator(decodeClip(c.topology, c.original));
  for (const t of c.t) {
    assert.ok(worstDeviation(ev.evaluate(t), before.evaluate(t)) <= 1e-6 * c.diagonal, `t = ${t}`);
  }
});

test('zero-length segments: tangents across them, and a last segment of zero length at t = 1', () => {
  // boundaries 0, 0.3, 0.3, 1, 1 on the synthetic clips (S = 4): T_1 and T_2 span the empty segment 1,
  // T_4 = (P_4 - P_3) / 0 is 0, and t = 1 falls in the empty segment 3 at tau = 0 (its first knot)
  const c = cases.find((x) => x.name === 'synthetic-displacement-paper-v4');
  const segT = Float64Array.from([0, 0.3, 0.3, 1, 1]);
  const coef = coefficientsV4(c.original, {
    tangents: () => 1,
    linear: () => true,
    edit: ({ arrays }) => {
      arrays.segment_t = { ...arrays.segment_t, data: segT };
    },
  });
  const clip = decodeClip(c.topology, coef);
  const ev = createEvaluator(clip);
  assert.ok(ev.cubic.every((x) => x === 1));
  for (const t of [0, 0.1, 0.3 - 1e-12, 0.3, 0.31, 0.6, 0.999999, 1]) {
    const worst = worstDeviation(ev.evaluate(t), naiveEvaluate(clip, t, centralTangents));
    assert.ok(worst <= 1e-6 * c.diagonal, `t = ${t}: ${worst}`);
  }
  // at t = 1: the knot P_3 (the cubic passes through its knots), the same as the straight line
  const lines = createEvaluator(decodeClip(c.topology, coefficientsV4(c.original, {
    linear: () => true,
    edit: ({ arrays }) => {
      arrays.segment_t = { ...arrays.segment_t, data: segT };
    },
  })));
  assert.deepEqual(ev.locate(1).slice(0, 2), [3, 0]);
  assert.ok(worstDeviation(ev.evaluate(1), lines.evaluate(1)) <= 1e-6 * c.diagonal);
});

test('the cubic passes through the knots: at every boundary it equals the straight line', () => {
  for (const c of cases) {
    const clip = decodeClip(c.topology, c.coefficients);
    const S = clip.nSegments;
    const linear = (s, cc) => S < 2 || s !== cc % S;
    const lines = createEvaluator(decodeClip(c.topology, coefficientsV4(c.original, { linear })));
    const ev = createEvaluator(clip);
    for (const t of clip.segmentT) {
      const worst = worstDeviation(ev.evaluate(t), lines.evaluate(t));
      assert.ok(worst <= 1e-6 * c.diagonal, `${c.name} t = ${t}: ${worst}`);
    }
  }
});

test('the four weights: float64 as in §3.10, rounded to float32 by the evaluator, ends not folded', () => {
  const segT = [0, 0.25, 0.5, 0.6, 1];
  const w = hermiteWeights(segT, 1, 0.3, new Float64Array(4));
  const tau = 0.3;
  const d = 0.25;
  const a = d / (0.5 - 0);
  const b = d / (0.6 - 0.25);
  const h10 = tau * (1 - tau) ** 2;
  const h11 = tau * tau * (tau - 1);
  const want = [-a * h10, (1 + 2 * tau) * (1 - tau) ** 2 - b * h11, tau * tau * (3 - 2 * tau) + a * h10, b * h11];
  want.forEach((x, i) => assert.ok(Math.abs(w[i] - x) < 1e-15, `${i}: ${w[i]} vs ${x}`));
  // they sum to 1 (a constant track stays constant) and give the knot values at the ends
  assert.ok(Math.abs(w.reduce((x, y) => x + y, 0) - 1) < 1e-15);
  const plus = (x) => x + 0; // -0 as 0
  assert.deepEqual(hermiteWeights(segT, 2, 0, [0, 0, 0, 0]).map(plus), [0, 1, 0, 0]);
  assert.deepEqual(hermiteWeights(segT, 2, 1, [0, 0, 0, 0]).map(plus), [0, 0, 1, 0]);
  // first segment: lo(0) = 0 = s keeps its own weight (-a h10, a = 1); last: hi(S) = S = s + 1 likewise
  const first = hermiteWeights(segT, 0, 0.5, [0, 0, 0, 0]);
  assert.equal(first[0], -0.125);
  const last = hermiteWeights(segT, 3, 0.5, [0, 0, 0, 0]);
  assert.equal(last[3], (0.4 / 0.4) * 0.25 * -0.5);
  // the evaluator keeps them rounded to float32
  const c = cases[0];
  const ev = createEvaluator(decodeClip(c.topology, c.coefficients));
  ev.prepare(0.4);
  const [s, t] = ev.loc;
  const ref = hermiteWeights(ev.clip.segmentT, s, t, new Float64Array(4));
  assert.deepEqual(Array.from(ev.cubicWeights), Array.from(ref, Math.fround));
});
