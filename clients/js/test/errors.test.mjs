// Bad input gives a ClipFormatError (or RangeError for a bad t) with a reason, never a crash or NaN frames.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import {
  ClipFormatError,
  createEvaluator,
  decodeClip,
  decodeClipFile,
  decodeContainer,
  loadClip,
  splitClipFile,
} from '../src/index.js';
import {
  FIXTURES,
  coefficientsV4,
  encodeContainer,
  manifest,
  readBytes,
  strictlyIncreasing,
} from './helpers.mjs';

const man = manifest();
const dynamicCase = (version) =>
  man.cases.find((c) => c.kind === 'dynamic-pde' && c.motion === 'displacement' && c.format_version === version);
const parts = splitClipFile(readBytes(join(FIXTURES, dynamicCase(1).clip))); // format version 1
const parts2 = splitClipFile(readBytes(join(FIXTURES, dynamicCase(2).clip))); // format version 2
const parts3 = splitClipFile(readBytes(join(FIXTURES, dynamicCase(3).clip))); // coefficients version 3

/** Re-encode a part with its header and arrays changed by edit({header, arrays}). */
function edited(bytes, edit) {
  const { header, arrays } = decodeContainer(bytes.slice());
  edit({ header, arrays });
  return encodeContainer(header, arrays);
}

test('truncated, foreign and future containers are rejected with a reason', () => {
  assert.throws(() => decodeContainer(new Uint8Array(5)), /too short/);
  assert.throws(() => decodeContainer(new TextEncoder().encode('{"not": "a container"}')), /magic/);
  const future = parts.coefficients.slice();
  new DataView(future.buffer).setUint32(8, 3, true);
  assert.throws(() => decodeContainer(future), /unsupported container version 3/);
  assert.throws(
    () => decodeContainer(parts.coefficients.slice(0, parts.coefficients.length - 64)),
    /outside the container/,
  );
});

test('unknown format versions, kinds and motions are rejected', () => {
  for (const p of [parts, parts2, parts3]) {
    for (const future of [0, 6, '5', '4', '3', 4.5, null]) {
      const v = edited(p.coefficients, ({ header }) => {
        header.format_version = future;
      });
      const version = JSON.stringify(future).replace('.', '\\.');
      const reads = '1, 2, 3, 4 and 5';
      assert.throws(
        () => decodeClip(p.topology, v),
        new RegExp(`unsupported dynamic-pde coefficients version ${version} \\(this build reads ${reads}\\)`),
      );
    }
    // versions 3 to 5 change the coefficients part only: a topology part claiming them is refused
    for (const version of [3, 4, 5]) {
      const t = edited(p.topology, ({ header }) => {
        header.format_version = version;
      });
      assert.throws(
        () => decodeClip(t, p.coefficients),
        new RegExp(`unsupported dynamic-pde topology version ${version} \\(this build reads 1 and 2\\)`),
      );
    }
  }
  const noVersion = edited(parts3.coefficients, ({ header }) => {
    delete header.format_version;
  });
  assert.throws(() => decodeClip(parts3.topology, noVersion), /unsupported dynamic-pde coefficients version/);
  const kind = edited(parts.coefficients, ({ header }) => {
    header.kind = 'spline';
  });
  assert.throws(() => decodeClip(parts.topology, kind), /unknown clip kind "spline"/);
  const motion = edited(parts.coefficients, ({ header }) => {
    header.motion = 'wobble';
  });
  assert.throws(() => decodeClip(parts.topology, motion), /unknown motion mode/);
  assert.throws(() => decodeClip(parts.coefficients, parts.topology), /expected a topology part/);
});

test('inconsistent arrays are rejected', () => {
  const shape = edited(parts.coefficients, ({ arrays }) => {
    arrays.D = { ...arrays.D, shape: [arrays.D.shape[0] * 3], data: arrays.D.data };
  });
  assert.throws(() => decodeClip(parts.topology, shape), /array 'D' has shape/);
  const nan = edited(parts.coefficients, ({ arrays }) => {
    const d = new Float32Array(arrays.knots.data);
    d[3] = NaN;
    arrays.knots = { ...arrays.knots, data: d };
  });
  assert.throws(() => decodeClip(parts.topology, nan), /non-finite/);
  const fam = edited(parts.coefficients, ({ arrays }) => {
    const d = new Uint8Array(arrays.family.data);
    d[0] = 7;
    arrays.family = { ...arrays.family, data: d };
  });
  assert.throws(() => decodeClip(parts.topology, fam), /family codes must be 0..3/);
  const order = edited(parts.topology, ({ arrays }) => {
    const d = new Int32Array(arrays.order.data);
    d[0] = d[1];
    arrays.order = { ...arrays.order, data: d };
  });
  assert.throws(() => decodeClip(order, parts.coefficients), /permutation/);
});

test('coefficients made for another topology are refused by loadClip', async () => {
  const other = edited(parts.topology, ({ header }) => {
    header.param_mode = 'paper';
  });
  await assert.rejects(loadClip(other, parts.coefficients), ClipFormatError);
  await assert.rejects(loadClip(other, parts.coefficients), /topology_id mismatch/);
});

test('a CLIP file must be a clip-file container', () => {
  assert.throws(() => decodeClipFile(parts.topology), /not a pdeanim CLIP file/);
});

test('non-finite times and short buffers are refused', () => {
  for (const c of man.cases) {
    const ev = createEvaluator(decodeClipFile(readBytes(join(FIXTURES, c.clip))));
    assert.throws(() => ev.evaluate(NaN), RangeError);
    assert.throws(() => ev.evaluate(Infinity), RangeError);
    assert.throws(() => ev.evaluate(0, new Float32Array(3)), RangeError);
  }
});

test('cyclic clips with a bad swim header are rejected', () => {
  const c = man.cases.find((x) => x.kind === 'cyclic-spine');
  const p = splitClipFile(readBytes(join(FIXTURES, c.clip)));
  const bad = edited(p.coefficients, ({ header }) => {
    header.swim.frequency = 0;
  });
  assert.throws(() => decodeClip(p.topology, bad), /invalid swim parameters/);
  const future = edited(p.coefficients, ({ header }) => {
    header.format_version = 2;
  });
  assert.throws(() => decodeClip(p.topology, future), /unsupported cyclic-spine coefficients version 2/);
  const noSpine = edited(p.coefficients, ({ arrays }) => {
    delete arrays.spine;
  });
  assert.throws(() => decodeClip(p.topology, noSpine), /lacks arrays: spine/);
});

/** Zigzag codes of the differences along the rows (per column) of integers vals (rows x cols). */
function zigzag(vals, cols = 1) {
  const out = new Uint32Array(vals.length);
  for (let i = 0; i < vals.length; i++) {
    const d = vals[i] - (i >= cols ? vals[i - cols] : 0);
    out[i] = ((d << 1) ^ (d >> 31)) >>> 0;
  }
  return out;
}

/** Inverse of zigzag: the integers behind the codes. */
function unzigzag(codes, cols = 1) {
  const out = new Array(codes.length);
  for (let i = 0; i < codes.length; i++) {
    out[i] = (i >= cols ? out[i - cols] : 0) + ((codes[i] >>> 1) ^ -(codes[i] & 1));
  }
  return out;
}

/** A version 2 part with the integers of a zigzag-coded array changed by edit(values). */
function editedCodes(bytes, name, edit, cols = 1) {
  return edited(bytes, ({ arrays }) => {
    const vals = unzigzag(arrays[name].data, cols);
    edit(vals);
    arrays[name] = { ...arrays[name], data: zigzag(vals, cols) };
  });
}

test('version 2 parts decode to what the helpers encode (zigzag differences, curve order)', () => {
  const { header, arrays } = decodeContainer(parts2.topology.slice());
  const clip = decodeClip(parts2.topology, parts2.coefficients);
  assert.equal(header.format_version, 2);
  const order = unzigzag(arrays.order.data);
  assert.deepEqual(Array.from(clip.order), order);
  // faces: ranks in curve order (column 0 running, columns 1-2 offsets from column 0), vertex = order[rank]
  const fc = arrays.faces.data;
  const first = unzigzag(fc.filter((_, i) => i % 3 === 0));
  const ranks = Array.from(fc, (z, i) => first[Math.floor(i / 3)] + (i % 3 ? unzigzag([z])[0] : 0));
  assert.deepEqual(Array.from(clip.faces), ranks.map((r) => order[r]));
  for (let i = 0; i < ranks.length; i += 3) {
    // canonical: each triangle starts at its lowest rank, rows sorted
    assert.ok(ranks[i] < ranks[i + 1] && ranks[i] < ranks[i + 2]);
    if (i) assert.ok(ranks[i] >= ranks[i - 3]);
  }
  const q = unzigzag(arrays.rest.data, 3);
  for (let i = 0; i < order.length; i++) {
    for (let w = 0; w < 3; w++) {
      const want = Math.fround(header.rest_origin[w] + q[i * 3 + w] * header.rest_step);
      assert.equal(clip.rest[order[i] * 3 + w], want);
    }
  }
  let sum = 0;
  arrays.curve_lengths.data.forEach((n, c) => {
    assert.equal(clip.offsets[c], sum);
    sum += n;
  });
  assert.equal(sum, clip.nVertices);
});

test('version 2 topologies with bad curves, order, faces or steps are rejected', () => {
  const bad = (topo, pattern) => assert.throws(() => decodeClip(topo, parts2.coefficients), pattern);
  bad(editedCodes(parts2.topology, 'order', (v) => (v[1] = v[0])), /order must be a permutation/);
  bad(editedCodes(parts2.topology, 'order', (v) => (v[0] = v.length)), /order holds an index outside/);
  bad(editedCodes(parts2.topology, 'order', (v) => (v[2] = -1)), /order holds an index outside/);
  const V = decodeClip(parts2.topology, parts2.coefficients).nVertices;
  const faceCodes = (edit) =>
    edited(parts2.topology, ({ arrays }) => {
      const d = Uint32Array.from(arrays.faces.data);
      edit(d);
      arrays.faces = { ...arrays.faces, data: d };
    });
  bad(faceCodes((d) => (d[4] = 2 * V)), /faces index outside the vertices/); // row 1: offset V past its first
  bad(faceCodes((d) => (d[0] = 5)), /faces index outside the vertices/); // first rank -3
  bad(faceCodes((d) => (d[2] = 2 * V + 1)), /faces index outside the vertices/); // offset -(V + 1)
  const lengths = edited(parts2.topology, ({ arrays }) => {
    const d = Uint32Array.from(arrays.curve_lengths.data);
    d[0] += 1;
    arrays.curve_lengths = { ...arrays.curve_lengths, data: d };
  });
  bad(lengths, /curve_lengths must add up to n_vertices/);
  const signed = edited(parts2.topology, ({ arrays }) => {
    arrays.order = { ...arrays.order, dtype: '<i4', data: Int32Array.from(arrays.order.data) };
  });
  bad(signed, /array 'order' has dtype <i4, expected <u4/);
  for (const [key, value] of [
    ['rest_step', 0],
    ['rest_step', -0.5],
    ['rest_step', '0.001'],
    ['u_step', null],
    ['u_step', undefined],
  ]) {
    const t = edited(parts2.topology, ({ header }) => {
      header[key] = value;
    });
    bad(t, new RegExp(`topology ${key} must be a positive finite number`));
  }
  for (const origin of [[0, 0], [0, 0, 'x'], null]) {
    const t = edited(parts2.topology, ({ header }) => {
      header.rest_origin = origin;
    });
    bad(t, /rest_origin must be 3 finite numbers/);
  }
  const huge = edited(parts2.topology, ({ header }) => {
    header.rest_step = 1e38; // finite, but codes of a few steps leave float32
  });
  bad(huge, /topology rest decode to non-finite values/);
  const hugeU = edited(parts2.topology, ({ header }) => {
    header.u_step = 1e38;
  });
  bad(hugeU, /topology u decode to non-finite values/);
});

test('version 2 coefficients with bad knot steps or codes are rejected', () => {
  const bad = (coef, pattern) => assert.throws(() => decodeClip(parts2.topology, coef), pattern);
  for (const [value, pattern] of [
    [0, /knot steps must be positive/],
    [-1, /knot steps must be positive/],
    [NaN, /array 'knot_step' has non-finite values/],
    [3e38, /coefficients knots decode to non-finite values/],
  ]) {
    const c = edited(parts2.coefficients, ({ arrays }) => {
      const d = Float32Array.from(arrays.knot_step.data);
      d[1] = value;
      arrays.knot_step = { ...arrays.knot_step, data: d };
    });
    bad(c, pattern);
  }
  const missing = edited(parts2.coefficients, ({ arrays }) => {
    delete arrays.knot_step;
  });
  bad(missing, /coefficients part has no 'knot_step' array/);
  const floatKnots = edited(parts2.coefficients, ({ arrays }) => {
    arrays.knots = { ...arrays.knots, dtype: '<f4', data: Float32Array.from(arrays.knots.data) };
  });
  bad(floatKnots, /array 'knots' has dtype <f4, expected <u4/);
  const badKind = edited(parts2.coefficients, ({ arrays }) => {
    const d = Uint8Array.from(arrays.space_kind.data);
    d[0] = 2;
    arrays.space_kind = { ...arrays.space_kind, data: d };
  });
  bad(badKind, /space kinds must be 0 or 1/);
  const trigOverPi = edited(parts2.coefficients, ({ arrays }) => {
    const d = Float32Array.from(arrays.m.data);
    d[0] = -4; // trig time with a constant above pi
    arrays.m = { ...arrays.m, data: d };
  });
  bad(trigOverPi, /time constants must be >= 0 \(and < pi for trig families\)/);
});

test('curve parameters outside [0, 1] are rejected (they would overflow the space basis)', () => {
  const t = edited(parts2.topology, ({ header }) => {
    header.u_step = 2 ** 40;
  });
  const c = edited(parts2.coefficients, ({ header }) => {
    header.topology_id = null;
  });
  assert.throws(() => decodeClip(t, c), /topology curve parameters u must lie in \[0, 1\]/);
});

test('version 2 signed m gives the family: < 0 trig, > 0 exp, 0 linear', () => {
  const c = edited(parts2.coefficients, ({ arrays }) => {
    const d = Float32Array.from(arrays.m.data);
    d[0] = -0.5;
    d[1] = 0.5;
    d[2] = 0;
    arrays.m = { ...arrays.m, data: d };
  });
  const clip = decodeClip(parts2.topology, c);
  assert.ok(clip.family[0] >= 2 && clip.family[1] < 2 && clip.family[2] < 2); // trig, exp, (linear) exp
  const plain = decodeClip(parts2.topology, parts2.coefficients);
  for (const i of [0, 1, 2]) assert.equal(clip.family[i] % 2, plain.family[i] % 2); // the item's space kind
  assert.deepEqual(Array.from(clip.m.slice(0, 3)), [0.5, 0.5, 0]);
});

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

test('version 3 knots are the weights on the basis, summed in order, plus the residual, bit for bit', () => {
  for (const c of man.cases.filter((x) => x.format_version === 3)) {
    const p3 = splitClipFile(readBytes(join(FIXTURES, c.clip)));
    const { header, arrays } = decodeContainer(p3.coefficients.slice());
    const clip = decodeClip(p3.topology, p3.coefficients);
    assert.equal(header.format_version, 3);
    const r = header.knot_rank;
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
 * A version 3 part with weights (r, C, 3, 4) of the integers q, basis (r, S+1), residual integers p
 * (S+1, C, 3, 4; zeros unless given) coded with `order` (default 1) differences, and steps as given.
 */
function withBasis(bytes, { rank, q, basis, step, residual, order = 1 }) {
  return edited(bytes, ({ header, arrays }) => {
    const C = arrays.knot_step.shape[0];
    const n = basis.length / rank;
    const T = C * 12;
    header.format_version = 3;
    header.knot_rank = rank;
    header.knot_differences = order;
    arrays.knots = {
      dtype: '<u4',
      shape: [C, 3, 4, n],
      data: tracksOf(residual ?? new Array(n * T).fill(0), T, n, order),
    };
    arrays.knot_weights = { dtype: '<u4', shape: [rank, C, 3, 4], data: codesOf(q) };
    arrays.knot_basis = { dtype: '<f4', shape: [rank, n], data: Float32Array.from(basis) };
    if (step) arrays.knot_step = { ...arrays.knot_step, data: Float32Array.from(arrays.knot_step.data, step) };
  });
}

test('a full-rank identity basis decodes to the knots of version 2 (knot_rank may be S + 1)', () => {
  const { header, arrays } = decodeContainer(parts2.coefficients.slice());
  const S = header.n_segments;
  const n = S + 1;
  const T = arrays.knot_step.shape[0] * 12;
  // the version 2 integers q[track, s] (running sums of order knot_differences along s) as weights q[s, track]
  const q = trackIntegers(arrays.knots.data, T, n, header.knot_differences);
  const eye = Array.from({ length: n * n }, (_, i) => (Math.floor(i / n) === i % n ? 1 : 0));
  const want = decodeClip(parts2.topology, parts2.coefficients);
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
      const v3 = withBasis(parts2.coefficients, { rank: n, q: weights, basis: eye, residual, order });
      const got = decodeClip(parts2.topology, v3);
      assert.equal(got.header.format_version, 3);
      assert.deepEqual(got.knots, want.knots);
      assert.deepEqual(createEvaluator(got).evaluate(0.42), a);
    }
  }
});

test('a version 2 part with zero weights on any basis decodes to its own knots: the residual is its tracks', () => {
  const want = decodeClip(parts2.topology, parts2.coefficients);
  const c = edited(parts2.coefficients, ({ header, arrays }) => {
    const C = arrays.knot_step.shape[0];
    header.format_version = 3;
    header.knot_rank = 2; // knot_differences and knots stay those of version 2
    arrays.knot_weights = { dtype: '<u4', shape: [2, C, 3, 4], data: new Uint32Array(2 * C * 12) };
    arrays.knot_basis = {
      dtype: '<f4',
      shape: [2, header.n_segments + 1],
      data: Float32Array.from({ length: 2 * (header.n_segments + 1) }, (_, i) => 0.25 * i - 1),
    };
  });
  assert.deepEqual(decodeClip(parts2.topology, c).knots, want.knots);
});

test('version 3 sums the basis tracks from j = 0 upwards in doubles, then rounds to float32', () => {
  // per track the products 1, 2^53 and -2^53: (0 + 1 + 2^53) rounds to 2^53 (ties to even), so the
  // ascending sum is 0; summed from j = r - 1 downwards it is 1
  const { header, arrays } = decodeContainer(parts3.coefficients.slice());
  const S = header.n_segments;
  const T = arrays.knot_step.shape[0] * 12;
  const q = [...new Array(T).fill(1), ...new Array(T).fill(2 ** 22), ...new Array(T).fill(-(2 ** 22))];
  const basis = [...new Array(S + 1).fill(1), ...new Array(2 * (S + 1)).fill(2 ** 31)];
  const c = withBasis(parts3.coefficients, { rank: 3, q, basis, step: () => 1 });
  const clip = decodeClip(parts3.topology, c);
  assert.ok(clip.knots.every((k) => Object.is(k, 0)));
  // the total is rounded once, to float32: 1 + 3 * 2^-25 is more than half a float32 ulp above 1, so it
  // rounds up to 1 + 2^-23 (a float32 accumulator would stay at 1)
  const once = withBasis(parts3.coefficients, {
    rank: 4,
    q: new Array(4 * T).fill(1),
    basis: [...new Array(S + 1).fill(1), ...new Array(3 * (S + 1)).fill(2 ** -25)],
    step: () => 1,
  });
  assert.ok(decodeClip(parts3.topology, once).knots.every((k) => k === 1 + 2 ** -23));
});

test('version 3 adds the residual p * h after the basis sum, in doubles', () => {
  const { header, arrays } = decodeContainer(parts3.coefficients.slice());
  const S = header.n_segments;
  const n = S + 1;
  const T = arrays.knot_step.shape[0] * 12;
  // basis products 2^53 then -2^53, residual 1: after the basis sum, (0 + 2^53 - 2^53) + 1 = 1; added first,
  // (0 + 1 + 2^53) would round to 2^53 (ties to even) and the total would be 0
  const q = [...new Array(T).fill(2 ** 22), ...new Array(T).fill(-(2 ** 22))];
  const basis = new Array(2 * n).fill(2 ** 31);
  for (const order of [1, 2]) {
    const residual = new Array(n * T).fill(1);
    const c = withBasis(parts3.coefficients, { rank: 2, q, basis, step: () => 1, residual, order });
    assert.ok(decodeClip(parts3.topology, c).knots.every((k) => k === 1));
  }
  // a residual that varies along the tracks (differences of order 1 and 2), on steps of 2^-3 and a basis
  // part of weights 3 on a ramp: knots = float32((3 h) * ramp[s] + p[s, t] h)
  const h = 2 ** -3;
  const ramp = Array.from({ length: n }, (_, s) => 0.1 * s - 0.35);
  const residual = Array.from({ length: n * T }, (_, i) => ((i * 7919) % 23) - 11);
  for (const order of [1, 2]) {
    const q3 = new Array(T).fill(3);
    const c = withBasis(parts3.coefficients, { rank: 1, q: q3, basis: ramp, step: () => h, residual, order });
    const { knots } = decodeClip(parts3.topology, c);
    for (let s = 0; s < n; s++) {
      for (let t = 0; t < T; t++) {
        const want = Math.fround(3 * h * Math.fround(ramp[s]) + residual[s * T + t] * h);
        assert.equal(knots[s * T + t], want);
      }
    }
  }
});

test('version 3 coefficients with a bad knot_rank, weights, basis, steps or residual tracks are rejected', () => {
  const bad = (coef, pattern) => assert.throws(() => decodeClip(parts3.topology, coef), pattern);
  const { header } = decodeContainer(parts3.coefficients.slice());
  const S = header.n_segments;
  const r = header.knot_rank;
  const rankError = new RegExp(`coefficients knot_rank must be an integer in 1\\.\\.${S + 1}, got`);
  for (const rank of [0, -1, S + 2, 1.5, '2', null, true, [2], undefined]) {
    const c = edited(parts3.coefficients, ({ header: h }) => {
      h.knot_rank = rank;
    });
    bad(c, rankError);
  }
  // another valid rank than the arrays': their shapes disagree
  const lower = edited(parts3.coefficients, ({ header: h }) => {
    h.knot_rank = r - 1 || r + 1;
  });
  bad(lower, /array 'knot_weights' has shape/);
  // a version 2 part that claims version 3: no knot_rank (and no weights nor basis)
  const claimed = edited(parts2.coefficients, ({ header: h }) => {
    h.format_version = 3;
  });
  assert.throws(
    () => decodeClip(parts2.topology, claimed),
    /coefficients knot_rank must be an integer in 1\.\.\d+, got undefined/,
  );
  const edit = (name, change) =>
    edited(parts3.coefficients, ({ arrays }) => {
      arrays[name] = change(arrays[name]);
    });
  for (const name of ['knot_weights', 'knot_basis', 'knot_step', 'knots']) {
    const missing = edited(parts3.coefficients, ({ arrays }) => {
      delete arrays[name];
    });
    bad(missing, new RegExp(`coefficients part has no '${name}' array`));
  }
  // the residual tracks are read as version 2 knots: knot_differences 1 or 2, required
  for (const order of [0, 3, -1, 1.5, '1', null, true, [1], undefined]) {
    const c = edited(parts3.coefficients, ({ header: h }) => {
      if (order === undefined) delete h.knot_differences;
      else h.knot_differences = order;
    });
    const want = `coefficients knot_differences must be 1 or 2, got ${JSON.stringify(order)}`;
    assert.throws(
      () => decodeClip(parts3.topology, c),
      (e) => e instanceof ClipFormatError && e.message.includes(want),
    );
  }
  // shapes: the axes in another order, a flat array, a rank too many
  bad(edit('knots', (a) => ({ ...a, shape: [a.shape[3], a.shape[0], 3, 4] })), /array 'knots' has shape/);
  bad(edit('knots', (a) => ({ ...a, shape: [a.data.length] })), /array 'knots' has shape/);
  const moved = edit('knot_weights', (a) => ({ ...a, shape: [a.shape[1], 3, 4, a.shape[0]] }));
  bad(moved, /array 'knot_weights' has shape/);
  bad(edit('knot_weights', (a) => ({ ...a, shape: [a.data.length] })), /array 'knot_weights' has shape/);
  bad(edit('knot_basis', (a) => ({ ...a, shape: [a.shape[1], a.shape[0]] })), /array 'knot_basis' has shape/);
  const extraRow = edit('knot_basis', (a) => ({
    ...a,
    shape: [a.shape[0] + 1, a.shape[1]],
    data: new Float32Array(a.data.length + a.shape[1]),
  }));
  bad(extraRow, /array 'knot_basis' has shape/);
  // dtypes: signed or float weights, a float64 basis, float64 steps
  for (const [name, dtype, Type, want] of [
    ['knot_weights', '<i4', Int32Array, '<u4'],
    ['knot_weights', '<f4', Float32Array, '<u4'],
    ['knot_basis', '<f8', Float64Array, '<f4'],
    ['knot_step', '<f8', Float64Array, '<f4'],
    ['knots', '<i4', Int32Array, '<u4'],
    ['knots', '<f4', Float32Array, '<u4'],
  ]) {
    const c = edit(name, (a) => ({ ...a, dtype, data: Type.from(a.data) }));
    bad(c, new RegExp(`array '${name}' has dtype ${dtype}, expected ${want}`));
  }
  // values: a non-finite basis, bad steps, knots that leave float32
  for (const value of [NaN, Infinity, -Infinity]) {
    bad(
      edit('knot_basis', (a) => {
        const d = Float32Array.from(a.data);
        d[a.shape[1] - 1] = value;
        return { ...a, data: d };
      }),
      /array 'knot_basis' has non-finite values/,
    );
  }
  for (const [value, pattern] of [
    [0, /knot steps must be positive/],
    [-1, /knot steps must be positive/],
    [NaN, /array 'knot_step' has non-finite values/],
  ]) {
    bad(
      edit('knot_step', (a) => {
        const d = Float32Array.from(a.data);
        d[1] = value;
        return { ...a, data: d };
      }),
      pattern,
    );
  }
  const T = decodeClip(parts3.topology, parts3.coefficients).nCurves * 12;
  const huge = withBasis(parts3.coefficients, {
    rank: 1,
    q: new Array(T).fill(2 ** 20),
    basis: new Array(S + 1).fill(3e38),
    step: () => 1,
  });
  bad(huge, /coefficients knots decode to non-finite values/);
  // a residual alone that leaves float32 (zero weights): 2 * 3e38
  const hugeResidual = withBasis(parts3.coefficients, {
    rank: 1,
    q: new Array(T).fill(0),
    basis: new Array(S + 1).fill(1),
    step: () => 3e38,
    residual: new Array((S + 1) * T).fill(2),
  });
  bad(hugeResidual, /coefficients knots decode to non-finite values/);
  // the version 2 checks still apply: space kinds and signed m
  const badKind = edit('space_kind', (a) => {
    const d = Uint8Array.from(a.data);
    d[0] = 2;
    return { ...a, data: d };
  });
  bad(badKind, /space kinds must be 0 or 1/);
});

for (const version of [4, 5]) {
  const what = 'a bad knot_rank, basis arrays at rank 0, or bad tangents';
  test(`version ${version} coefficients with ${what} are rejected`, () => {
    // docs/format.md §3.10: besides what §3.9 rejects, a knot_rank that is not an integer in 0..S+1, arrays of
    // the basis present with rank 0, and a tangents array that is missing, of another shape or dtype, or holds
    // a value other than 0 and 1; version 5 (§3.11) rejects the same (its segment boundaries here strictly
    // increasing: the rejection of repeated ones has a test of its own)
    const tangents = (c, w) => Number((c + w) % 2 === 0);
    for (const p of [parts2, parts3]) {
      const segT = decodeContainer(p.coefficients.slice()).arrays.segment_t.data;
      const segmentT = version === 5 ? strictlyIncreasing(segT) : null;
      const v4 = (edit) => coefficientsV4(p.coefficients, { version, tangents, segmentT, edit });
      const bad = (coef, pattern) => {
        assert.throws(
          () => decodeClip(p.topology, coef),
          (e) => e instanceof ClipFormatError && pattern.test(e.message),
          `${pattern}`,
        );
      };
      const ok = decodeClip(p.topology, v4());
      assert.equal(ok.header.format_version, version);
      const S = ok.nSegments;
      const C = ok.nCurves;
      const rank = ok.header.knot_rank; // 0 from version 2, >= 1 from version 3
      // knot_rank: not an integer in 0..S+1 (missing too)
      const rankError = new RegExp(`coefficients knot_rank must be an integer in 0\\.\\.${S + 1}, got`);
      for (const r of [-1, S + 2, 0.5, 1.5, '0', '1', null, true, false, [0], undefined]) {
        bad(v4(({ header }) => {
          if (r === undefined) delete header.knot_rank;
          else header.knot_rank = r;
        }), rankError);
      }
      if (rank === 0) {
        // rank 0 with either basis array present (even of a consistent shape) is refused
        for (const name of ['knot_weights', 'knot_basis']) {
          const c = v4(({ arrays }) => {
            arrays[name] = name === 'knot_weights'
              ? { dtype: '<u4', shape: [0, C, 3, 4], data: new Uint32Array(0) }
              : { dtype: '<f4', shape: [0, S + 1], data: new Float32Array(0) };
          });
          bad(c, new RegExp(`knot_rank is 0 \\(no shared basis\\), but the part has '${name}'`));
        }
        // a rank >= 1 on a part without the basis: its arrays are missing
        bad(v4(({ header }) => { header.knot_rank = 1; }), /coefficients part has no 'knot_weights' array/);
      } else {
        // rank 0 on a part with a basis: the arrays of the basis are present
        bad(v4(({ header }) => { header.knot_rank = 0; }), /knot_rank is 0 \(no shared basis\), but the part has/);
        // the version 3 rules still apply: a basis of the wrong rank, a missing or non-finite basis
        bad(v4(({ header }) => { header.knot_rank = rank === 1 ? 2 : rank - 1; }), /array 'knot_weights' has shape/);
        bad(v4(({ arrays }) => { delete arrays.knot_basis; }), /coefficients part has no 'knot_basis' array/);
        bad(v4(({ arrays }) => {
          const d = Float32Array.from(arrays.knot_basis.data);
          d[0] = NaN;
          arrays.knot_basis = { ...arrays.knot_basis, data: d };
        }), /array 'knot_basis' has non-finite values/);
      }
      // the version 2 rules too: knot_differences, knot steps, space kinds
      bad(v4(({ header }) => { header.knot_differences = 3; }), /knot_differences must be 1 or 2, got 3/);
      bad(v4(({ arrays }) => {
        const d = Float32Array.from(arrays.knot_step.data);
        d[0] = 0;
        arrays.knot_step = { ...arrays.knot_step, data: d };
      }), /knot steps must be positive/);
      // tangents: missing, another shape, another dtype, values other than 0 and 1
      bad(v4(({ arrays }) => { delete arrays.tangents; }), /coefficients part has no 'tangents' array/);
      for (const shape of [[C * 3], [3, C], [C, 3, 1], [C + 1, 3], [C, 4]]) {
        const n = shape.reduce((a, b) => a * b, 1);
        bad(v4(({ arrays }) => {
          arrays.tangents = { dtype: '<u1', shape, data: new Uint8Array(n) };
        }), /array 'tangents' has shape/);
      }
      for (const [dtype, Type] of [
        ['<i1', Int8Array],
        ['<u2', Uint16Array],
        ['<u4', Uint32Array],
        ['<f4', Float32Array],
      ]) {
        bad(v4(({ arrays }) => {
          arrays.tangents = { dtype, shape: [C, 3], data: Type.from(arrays.tangents.data) };
        }), new RegExp(`array 'tangents' has dtype ${dtype}, expected <u1`));
      }
      for (const value of [2, 255]) {
        bad(v4(({ arrays }) => {
          const d = Uint8Array.from(arrays.tangents.data);
          d[d.length - 1] = value;
          arrays.tangents = { ...arrays.tangents, data: d };
        }), new RegExp(`coefficients tangents must be 0 or 1, got ${value}`));
      }
      // a version 2 or 3 part that claims version 4 or 5 keeps its basis and needs its tangents
      const claimed = edited(p.coefficients, ({ header }) => {
        header.format_version = version;
        header.knot_rank ??= 0;
      });
      bad(claimed, /coefficients part has no 'tangents' array/);
    }
  });
}

test('version 5 rejects segment boundaries that are not strictly increasing where some item has tangents', () => {
  // docs/format.md §3.11: a segment of zero length cannot occur in a version 5 clip with tangents (its
  // natural-spline tangents divide by every segment's length); without tangents, and in version 4, it can
  for (const p of [parts2, parts3]) {
    const S = decodeContainer(p.coefficients.slice()).header.n_segments;
    const even = Array.from({ length: S + 1 }, (_, j) => j / S);
    for (const j of [0, 1, S - 1]) {
      // segment j of length 0 (the first, an inner one, the last)
      const segmentT = even.map((x, i) => (i === j + 1 ? even[j] : x));
      const tangents = (c, w) => Number(c === 1 && w === 2);
      const coef = (version, tg = tangents) =>
        coefficientsV4(p.coefficients, { version, tangents: tg, segmentT });
      assert.throws(
        () => decodeClip(p.topology, coef(5)),
        (e) =>
          e instanceof ClipFormatError &&
          e.message ===
            'segment boundaries must be strictly increasing in a version 5 clip with tangents' +
              ` (segment ${j} has length 0)`,
      );
      assert.equal(decodeClip(p.topology, coef(5, () => 0)).header.format_version, 5);
      assert.equal(decodeClip(p.topology, coef(4)).header.format_version, 4);
      // decreasing boundaries stay refused in every version, with the message of every version
      const back = even.map((x, i) => (i === j + 1 ? -1 : x));
      const down = coefficientsV4(p.coefficients, { version: 5, tangents, segmentT: back });
      assert.throws(() => decodeClip(p.topology, down), /segment boundaries must be non-decreasing/);
    }
  }
});
