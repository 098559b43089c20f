// Knots (docs/format.md §3.4): plain time tracks (knot_rank 0) and knots on a shared time basis (rank >= 1)
// decode bit for bit as the specification sums them, and every rule on the knot header fields and arrays is
// enforced with a reason.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { createEvaluator, decodeClip, decodeContainer } from '../src/index.js';
import { edited, fixtureParts, manifest, withoutStream, refused } from './helpers.mjs';

// streamable clips (format 1.2) decode window by window: test/stream.test.mjs checks their tables
const man = withoutStream(manifest());
const dynamicCase = (pred) => man.cases.find((c) => c.kind === 'dynamic-pde' && pred(c));
// plain knots on the paper's time pairs, knots on a basis, plain knots with spline items
const parts = fixtureParts(
  dynamicCase((c) => c.motion === 'displacement' && c.knot_rank === 0 && c.spline_items === 0),
);
const basisParts = fixtureParts(dynamicCase((c) => c.knot_rank > 0 && c.spline_items === 0));
const splineParts = fixtureParts(dynamicCase((c) => c.knot_rank === 0 && c.spline_items > 0));

/** The integers of plain (not differenced) zigzag codes. */
const plain = (codes) => Array.from(codes, (z) => (z >>> 1) ^ -(z & 1));
/** Plain zigzag codes of integers. */
const codesOf = (vals) => Uint32Array.from(vals, (q) => ((q << 1) ^ (q >> 31)) >>> 0);

/**
 * The integers q[s * T + t] (S+1 = n knots of T tracks) of knot tracks (T, n) of zigzag differences of order
 * `order`, decoded here independently of the client.
 */
function trackIntegers(codes, T, n, order) {
  const z = plain(codes);
  const q = new Array(n * T);
  for (let t = 0; t < T; t++) {
    let first = 0;
    let v = 0;
    for (let s = 0; s < n; s++) {
      if (order === 1) v += z[t * n + s];
      else v += first += z[t * n + s];
      q[s * T + t] = v;
    }
  }
  return q;
}

/** Knot tracks (T, n) of zigzag differences of order `order` of the integers p[s * T + t]. */
function tracksOf(p, T, n, order) {
  const d = new Array(T * n);
  for (let t = 0; t < T; t++) {
    for (let s = 0; s < n; s++) {
      const at = (k) => (k < 0 ? 0 : p[k * T + t]);
      d[t * n + s] = order === 1 ? at(s) - at(s - 1) : at(s) - 2 * at(s - 1) + at(s - 2);
    }
  }
  return codesOf(d);
}

test('plain knots (rank 0) are float32(p * h) of tracks of order 1 or 2 differences, bit for bit', () => {
  const cases = man.cases.filter((c) => c.knot_rank === 0);
  const orders = new Set();
  for (const c of cases) {
    const p = fixtureParts(c);
    const { header, arrays } = decodeContainer(p.coefficients.slice());
    const clip = decodeClip(p.topology, p.coefficients);
    const n = clip.nSegments + 1;
    const T = clip.nCurves * 12;
    orders.add(header.knot_differences);
    assert.equal(arrays.knot_weights, undefined);
    assert.equal(arrays.knot_basis, undefined);
    const q = trackIntegers(arrays.knots.data, T, n, header.knot_differences);
    const step = arrays.knot_step.data;
    const bounds = arrays.knot_windows ? Array.from(arrays.knot_windows.data) : [0, n];
    for (let i = 0; i < n * T; i++) {
      const win = bounds.findLastIndex((b) => b <= Math.floor(i / T)); // this knot's window of steps
      assert.equal(clip.knots[i], Math.fround(q[i] * step[win * (T >> 2) + ((i % T) >> 2)]), c.name);
    }
  }
  assert.deepEqual([...orders].sort(), [1, 2]);
});

const windowsParts = fixtureParts(dynamicCase((c) => c.name.endsWith('-windows')));

test('knot steps per window: each knot takes its window\'s step; the windows rise from 0 to S + 1', () => {
  const { header, arrays } = decodeContainer(windowsParts.coefficients.slice());
  const n = header.n_segments + 1;
  const C = header.n_curves;
  const bounds = Array.from(arrays.knot_windows.data);
  assert.ok(bounds.length >= 3 && bounds[0] === 0 && bounds.at(-1) === n);
  assert.deepEqual(arrays.knot_step.shape, [bounds.length - 1, C, 3]);
  const clip = decodeClip(windowsParts.topology, windowsParts.coefficients);
  // one window with the first window's steps decodes the first window's knots alike, the others not
  const one = edited(windowsParts.coefficients, ({ arrays: a }) => {
    delete a.knot_windows;
    a.knot_step = { dtype: '<f4', shape: [C, 3], data: a.knot_step.data.slice(0, C * 3) };
  });
  const first = decodeClip(windowsParts.topology, one).knots;
  const T = C * 12;
  assert.deepEqual(first.subarray(0, bounds[1] * T), clip.knots.subarray(0, bounds[1] * T));
  const W = bounds.length - 1;
  const with_ = (windows, shape = [W, C, 3], extra = {}) =>
    edited(windowsParts.coefficients, ({ header: h, arrays: a }) => {
      a.knot_windows = { dtype: '<u4', shape: [windows.length], data: Uint32Array.from(windows) };
      a.knot_step = { ...a.knot_step, shape, data: a.knot_step.data.slice(0, shape.reduce((x, y) => x * y)) };
      Object.assign(h, extra.header ?? {});
      Object.assign(a, extra.arrays ?? {});
    });
  const rising = `coefficients knot_windows must rise strictly from 0 to ${n}`;
  const flipped = [...bounds];
  [flipped[1], flipped[2]] = [flipped[2], flipped[1]];
  refused(() => decodeClip(windowsParts.topology, with_(flipped)), rising);
  refused(() => decodeClip(windowsParts.topology, with_([1, ...bounds.slice(1)])), rising);
  refused(() => decodeClip(windowsParts.topology, with_([...bounds.slice(0, -1), n - 1])), rising);
  refused(() => decodeClip(windowsParts.topology, with_(bounds, [C, 3])), /'knot_step' has shape/);
  refused(() => decodeClip(windowsParts.topology, with_([0, bounds[1], n])), /'knot_step' has shape/);
  const basis = {
    header: { knot_rank: 1 },
    arrays: {
      knot_weights: { dtype: '<u4', shape: [1, C, 3, 4], data: new Uint32Array(T) },
      knot_basis: { dtype: '<f4', shape: [1, n], data: new Float32Array(n) },
    },
  };
  refused(() => decodeClip(windowsParts.topology, with_(bounds, [W, C, 3], basis)), /need knot_rank 0/);
});

test('knots on a basis are the weights on it, summed in order, plus the residual, bit for bit', () => {
  const cases = man.cases.filter((x) => x.knot_rank > 0);
  assert.ok(cases.length >= 2);
  for (const c of cases) {
    const p3 = fixtureParts(c);
    const { header, arrays } = decodeContainer(p3.coefficients.slice());
    const clip = decodeClip(p3.topology, p3.coefficients);
    const r = header.knot_rank;
    assert.equal(r, c.knot_rank);
    const S = clip.nSegments;
    const n = S + 1;
    const T = clip.nCurves * 12;
    assert.ok(r >= 1 && r < n);
    assert.deepEqual(arrays.knots.shape, [clip.nCurves, 3, 4, n]);
    const q = plain(arrays.knot_weights.data);
    const p = trackIntegers(arrays.knots.data, T, n, header.knot_differences);
    const step = arrays.knot_step.data;
    const basis = arrays.knot_basis.data;
    for (let s = 0; s <= S; s++) {
      for (let i = 0; i < T; i++) {
        let acc = 0;
        for (let j = 0; j < r; j++) acc += q[j * T + i] * step[i >> 2] * basis[j * n + s];
        acc += p[s * T + i] * step[i >> 2];
        assert.equal(clip.knots[s * T + i], Math.fround(acc), c.name);
      }
    }
  }
});

/**
 * A coefficients part on a knot basis: weights (r, C, 3, 4) of the integers q, basis (r, S+1), residual
 * integers p (S+1, C, 3, 4; zeros unless given) coded with `order` (default 1) differences, steps as given.
 */
function withBasis(bytes, { rank, q, basis, step, residual, order = 1 }) {
  return edited(bytes, ({ header, arrays }) => {
    const C = arrays.knot_step.shape[0];
    const n = basis.length / rank;
    const T = C * 12;
    header.knot_rank = rank;
    header.knot_differences = order;
    arrays.knots = {
      dtype: '<u4',
      shape: [C, 3, 4, n],
      data: tracksOf(residual ?? new Array(n * T).fill(0), T, n, order),
    };
    arrays.knot_weights = { dtype: '<u4', shape: [rank, C, 3, 4], data: codesOf(q) };
    arrays.knot_basis = { dtype: '<f4', shape: [rank, n], data: Float32Array.from(basis) };
    if (step) {
      arrays.knot_step = { ...arrays.knot_step, data: Float32Array.from(arrays.knot_step.data, step) };
    }
  });
}

test('a full-rank identity basis decodes to the plain knots (knot_rank may be S + 1)', () => {
  const { header, arrays } = decodeContainer(parts.coefficients.slice());
  const S = header.n_segments;
  const n = S + 1;
  const T = arrays.knot_step.shape[0] * 12;
  // the rank 0 integers q[track, s] (running sums of order knot_differences along s) as weights q[s, track]
  const q = trackIntegers(arrays.knots.data, T, n, header.knot_differences);
  const eye = Array.from({ length: n * n }, (_, i) => (Math.floor(i / n) === i % n ? 1 : 0));
  const want = decodeClip(parts.topology, parts.coefficients);
  const a = createEvaluator(want).evaluate(0.42);
  const zeros = new Array(n * T).fill(0);
  for (const order of [1, 2]) {
    // all in the weights (zero residual), all in the residual (zero weights), or split between them
    const half = q.map((v) => Math.trunc(v / 2));
    for (const [weights, residual] of [
      [q, zeros],
      [zeros, q],
      [half, q.map((v, i) => v - half[i])],
    ]) {
      const v3 = withBasis(parts.coefficients, { rank: n, q: weights, basis: eye, residual, order });
      const got = decodeClip(parts.topology, v3);
      assert.equal(got.header.knot_rank, n);
      assert.deepEqual(got.knots, want.knots);
      assert.deepEqual(createEvaluator(got).evaluate(0.42), a);
    }
  }
});

test('zero weights on any basis give the plain knots: the residual tracks are the plain tracks', () => {
  const want = decodeClip(parts.topology, parts.coefficients);
  const c = edited(parts.coefficients, ({ header, arrays }) => {
    const C = arrays.knot_step.shape[0];
    header.knot_rank = 2; // knot_differences and knots stay those of rank 0
    arrays.knot_weights = { dtype: '<u4', shape: [2, C, 3, 4], data: new Uint32Array(2 * C * 12) };
    arrays.knot_basis = {
      dtype: '<f4',
      shape: [2, header.n_segments + 1],
      data: Float32Array.from({ length: 2 * (header.n_segments + 1) }, (_, i) => 0.25 * i - 1),
    };
  });
  assert.deepEqual(decodeClip(parts.topology, c).knots, want.knots);
});

test('the knot basis is summed from j = 0 upwards in doubles, then rounded to float32', () => {
  // per track the products 1, 2^53 and -2^53: (0 + 1 + 2^53) rounds to 2^53 (ties to even), so the
  // ascending sum is 0; summed from j = r - 1 downwards it is 1
  const { header, arrays } = decodeContainer(basisParts.coefficients.slice());
  const S = header.n_segments;
  const T = arrays.knot_step.shape[0] * 12;
  const q = [...new Array(T).fill(1), ...new Array(T).fill(2 ** 22), ...new Array(T).fill(-(2 ** 22))];
  const basis = [...new Array(S + 1).fill(1), ...new Array(2 * (S + 1)).fill(2 ** 31)];
  const c = withBasis(basisParts.coefficients, { rank: 3, q, basis, step: () => 1 });
  const clip = decodeClip(basisParts.topology, c);
  assert.ok(clip.knots.every((k) => Object.is(k, 0)));
  // the total is rounded once, to float32: 1 + 3 * 2^-25 is more than half a float32 ulp above 1, so it
  // rounds up to 1 + 2^-23 (a float32 accumulator would stay at 1)
  const once = withBasis(basisParts.coefficients, {
    rank: 4,
    q: new Array(4 * T).fill(1),
    basis: [...new Array(S + 1).fill(1), ...new Array(3 * (S + 1)).fill(2 ** -25)],
    step: () => 1,
  });
  assert.ok(decodeClip(basisParts.topology, once).knots.every((k) => k === 1 + 2 ** -23));
});

test('the residual p * h is added after the basis sum, in doubles', () => {
  const { header, arrays } = decodeContainer(basisParts.coefficients.slice());
  const S = header.n_segments;
  const n = S + 1;
  const T = arrays.knot_step.shape[0] * 12;
  // basis products 2^53 then -2^53, residual 1: after the basis sum, (0 + 2^53 - 2^53) + 1 = 1; added first,
  // (0 + 1 + 2^53) would round to 2^53 (ties to even) and the total would be 0
  const q = [...new Array(T).fill(2 ** 22), ...new Array(T).fill(-(2 ** 22))];
  const basis = new Array(2 * n).fill(2 ** 31);
  for (const order of [1, 2]) {
    const residual = new Array(n * T).fill(1);
    const c = withBasis(basisParts.coefficients, { rank: 2, q, basis, step: () => 1, residual, order });
    assert.ok(decodeClip(basisParts.topology, c).knots.every((k) => k === 1));
  }
  // a residual that varies along the tracks (differences of order 1 and 2), on steps of 2^-3 and a basis
  // part of weights 3 on a ramp: knots = float32((3 h) * ramp[s] + p[s, t] h)
  const h = 2 ** -3;
  const ramp = Array.from({ length: n }, (_, s) => 0.1 * s - 0.35);
  const residual = Array.from({ length: n * T }, (_, i) => ((i * 7919) % 23) - 11);
  for (const order of [1, 2]) {
    const q3 = new Array(T).fill(3);
    const options = { rank: 1, q: q3, basis: ramp, step: () => h, residual, order };
    const c = withBasis(basisParts.coefficients, options);
    const { knots } = decodeClip(basisParts.topology, c);
    for (let s = 0; s < n; s++) {
      for (let t = 0; t < T; t++) {
        const want = Math.fround(3 * h * Math.fround(ramp[s]) + residual[s * T + t] * h);
        assert.equal(knots[s * T + t], want);
      }
    }
  }
});

test('a bad knot_rank, basis arrays at rank 0 or missing at rank >= 1, bad knot arrays are rejected', () => {
  for (const p of [parts, basisParts, splineParts]) {
    const bad = (coef, pattern) => refused(() => decodeClip(p.topology, coef), pattern);
    const { header } = decodeContainer(p.coefficients.slice());
    const S = header.n_segments;
    const C = decodeClip(p.topology, p.coefficients).nCurves;
    const r = header.knot_rank;
    const edit = (change) => edited(p.coefficients, change);
    const array = (name, change) =>
      edit(({ arrays }) => {
        arrays[name] = change(arrays[name]);
      });
    // knot_rank: not an integer in 0..S+1 (missing too)
    for (const rank of [-1, S + 2, 0.5, 1.5, '0', '1', null, true, false, [0], undefined]) {
      const c = edit(({ header: h }) => {
        if (rank === undefined) delete h.knot_rank;
        else h.knot_rank = rank;
      });
      bad(c, `coefficients knot_rank must be an integer in 0..${S + 1}, got ${JSON.stringify(rank)}`);
    }
    if (r === 0) {
      // rank 0 with either basis array present (even of a consistent shape) is refused
      for (const name of ['knot_weights', 'knot_basis']) {
        const c = edit(({ arrays }) => {
          arrays[name] =
            name === 'knot_weights'
              ? { dtype: '<u4', shape: [0, C, 3, 4], data: new Uint32Array(0) }
              : { dtype: '<f4', shape: [0, S + 1], data: new Float32Array(0) };
        });
        bad(c, `coefficients with knot_rank 0 must not hold '${name}'`);
      }
      // a rank >= 1 on a part without the basis: its arrays are missing
      const rank1 = edit(({ header: h }) => {
        h.knot_rank = 1;
      });
      bad(rank1, "coefficients part has no 'knot_weights' array");
      const weightsOnly = edit(({ header: h, arrays }) => {
        h.knot_rank = 1;
        arrays.knot_weights = { dtype: '<u4', shape: [1, C, 3, 4], data: new Uint32Array(C * 12) };
      });
      bad(weightsOnly, "coefficients part has no 'knot_basis' array");
    } else {
      // rank 0 on a part with a basis: the arrays of the basis are present
      const rank0 = edit(({ header: h }) => {
        h.knot_rank = 0;
      });
      bad(rank0, "coefficients with knot_rank 0 must not hold 'knot_weights'");
      const rank0Basis = edit(({ header: h, arrays }) => {
        h.knot_rank = 0;
        delete arrays.knot_weights;
      });
      bad(rank0Basis, "coefficients with knot_rank 0 must not hold 'knot_basis'");
      // another valid rank than the arrays': their shapes disagree
      const other = edit(({ header: h }) => {
        h.knot_rank = r === 1 ? 2 : r - 1;
      });
      bad(other, /array 'knot_weights' has shape/);
      for (const name of ['knot_weights', 'knot_basis']) {
        const missing = edit(({ arrays }) => {
          delete arrays[name];
        });
        bad(missing, `coefficients part has no '${name}' array`);
      }
      // shapes: the axes in another order, a flat array, a row too many
      const moved = array('knot_weights', (a) => ({ ...a, shape: [a.shape[1], 3, 4, a.shape[0]] }));
      bad(moved, /array 'knot_weights' has shape/);
      bad(array('knot_weights', (a) => ({ ...a, shape: [a.data.length] })), /array 'knot_weights' has shape/);
      const swapped = array('knot_basis', (a) => ({ ...a, shape: [a.shape[1], a.shape[0]] }));
      bad(swapped, /array 'knot_basis' has shape/);
      const extraRow = array('knot_basis', (a) => ({
        ...a,
        shape: [a.shape[0] + 1, a.shape[1]],
        data: new Float32Array(a.data.length + a.shape[1]),
      }));
      bad(extraRow, /array 'knot_basis' has shape/);
      for (const [name, dtype, Type, want] of [
        ['knot_weights', '<i4', Int32Array, '<u4'],
        ['knot_weights', '<f4', Float32Array, '<u4'],
        ['knot_basis', '<f8', Float64Array, '<f4'],
      ]) {
        const c = array(name, (a) => ({ ...a, dtype, data: Type.from(a.data) }));
        bad(c, `coefficients array '${name}' has dtype ${dtype}, expected ${want}`);
      }
      for (const value of [NaN, Infinity, -Infinity]) {
        const c = array('knot_basis', (a) => {
          const d = Float32Array.from(a.data);
          d[a.shape[1] - 1] = value;
          return { ...a, data: d };
        });
        bad(c, "coefficients array 'knot_basis' has non-finite values");
      }
    }
    // the knot tracks: knot_differences 1 or 2, required
    for (const order of [0, 3, -1, 1.5, '1', null, true, [1], undefined]) {
      const c = edit(({ header: h }) => {
        if (order === undefined) delete h.knot_differences;
        else h.knot_differences = order;
      });
      bad(c, `coefficients knot_differences must be 1 or 2, got ${JSON.stringify(order)}`);
    }
    for (const name of ['knot_step', 'knots']) {
      const missing = edit(({ arrays }) => {
        delete arrays[name];
      });
      bad(missing, `coefficients part has no '${name}' array`);
    }
    // shapes: the axes in another order (the tracks are (C, 3, 4, S+1)), a flat array
    bad(array('knots', (a) => ({ ...a, shape: [a.shape[3], a.shape[0], 3, 4] })), /array 'knots' has shape/);
    bad(array('knots', (a) => ({ ...a, shape: [a.data.length] })), /array 'knots' has shape/);
    for (const [name, dtype, Type, want] of [
      ['knot_step', '<f8', Float64Array, '<f4'],
      ['knots', '<i4', Int32Array, '<u4'],
      ['knots', '<f4', Float32Array, '<u4'],
    ]) {
      const c = array(name, (a) => ({ ...a, dtype, data: Type.from(a.data) }));
      bad(c, `coefficients array '${name}' has dtype ${dtype}, expected ${want}`);
    }
    for (const [value, pattern] of [
      [0, 'coefficients knot steps must be positive'],
      [-1, 'coefficients knot steps must be positive'],
      [NaN, "coefficients array 'knot_step' has non-finite values"],
    ]) {
      const c = array('knot_step', (a) => {
        const d = Float32Array.from(a.data);
        d[1] = value;
        return { ...a, data: d };
      });
      bad(c, pattern);
    }
    // finite steps whose knots leave float32 (every step: some codes are not 0)
    const huge = array('knot_step', (a) => ({ ...a, data: new Float32Array(a.data.length).fill(3e38) }));
    bad(huge, 'coefficients knots decode to non-finite values');
  }
  // knots on a basis that leave float32: large weights on a large basis, or a large residual alone
  const { header } = decodeContainer(basisParts.coefficients.slice());
  const S = header.n_segments;
  const T = decodeClip(basisParts.topology, basisParts.coefficients).nCurves * 12;
  const huge = withBasis(basisParts.coefficients, {
    rank: 1,
    q: new Array(T).fill(2 ** 20),
    basis: new Array(S + 1).fill(3e38),
    step: () => 1,
  });
  refused(() => decodeClip(basisParts.topology, huge), 'coefficients knots decode to non-finite values');
  const hugeResidual = withBasis(basisParts.coefficients, {
    rank: 1,
    q: new Array(T).fill(0),
    basis: new Array(S + 1).fill(1),
    step: () => 3e38,
    residual: new Array((S + 1) * T).fill(2),
  });
  refused(
    () => decodeClip(basisParts.topology, hugeResidual),
    'coefficients knots decode to non-finite values',
  );
});
