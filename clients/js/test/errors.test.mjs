// Bad input gives a ClipFormatError (or RangeError for a bad t) with a reason, never a crash or NaN frames:
// the rules a reader of format 1.x must enforce (docs/format.md §1-§3, §4), on parts built from the
// fixtures (the knot arrays' rules are in knots.test.mjs).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import {
  ClipFormatError,
  FORMAT_VERSION,
  createEvaluator,
  decodeClip,
  decodeClipFile,
  decodeContainer,
  loadClip,
  loadClipFile,
} from '../src/index.js';
import {
  FIXTURES,
  edited,
  encodeContainer,
  fixtureParts,
  manifest,
  naiveEvaluate,
  readBytes,
  refused,
  retimed,
  takenTimes,
  worstDeviation,
} from './helpers.mjs';

const man = manifest();
const dynamicCase = (pred) => man.cases.find((c) => c.kind === 'dynamic-pde' && pred(c));
// a displacement clip on the paper's time pairs with plain knots (rank 0, no spline items), one on a knot
// basis, one with spline items, a rigid one and a cyclic one (fixtures the conformance test requires)
const parts = fixtureParts(
  dynamicCase((c) => c.motion === 'displacement' && c.knot_rank === 0 && c.spline_items === 0),
);
const basisParts = fixtureParts(dynamicCase((c) => c.knot_rank > 0 && c.spline_items === 0));
const splineParts = fixtureParts(
  dynamicCase((c) => c.knot_rank === 0 && c.spline_items > 0 && c.motion !== 'rigid'),
);
const rigidParts = fixtureParts(dynamicCase((c) => c.motion === 'rigid'));
const cyclicParts = fixtureParts(man.cases.find((c) => c.kind === 'cyclic-spine'));

/** The C * 3 time models of a coefficients part, and its (S, C, 3) signed m. */
function timeArrays(coefficients) {
  const { arrays } = decodeContainer(coefficients.slice());
  return { model: arrays.time_model.data, m: arrays.m.data, C: arrays.time_model.shape[0] };
}

test('truncated, foreign and future containers are rejected with a reason', () => {
  refused(() => decodeContainer(new Uint8Array(5)), /too short/);
  refused(() => decodeContainer(new TextEncoder().encode('{"not": "a container"}')), /magic/);
  const future = parts.coefficients.slice();
  new DataView(future.buffer).setUint32(8, 3, true);
  refused(() => decodeContainer(future), /unsupported container version 3/);
  refused(
    () => decodeContainer(parts.coefficients.slice(0, parts.coefficients.length - 64)),
    /outside the container/,
  );
});

// every format_version but "1.<digits>": numbers, other majors, malformed minors, other types, missing
const BAD_VERSIONS = [
  1,
  1.5,
  2,
  0,
  '2.0',
  '0.9',
  '10.0',
  '1',
  '1.',
  '.0',
  '1.x',
  '1.0.1',
  '1.0a',
  '1.-1',
  '1.+1',
  '1.1e2',
  '01.0',
  ' 1.0',
  '1.0 ',
  '1.0\n',
  'v1.0',
  '1,0',
  '\uff11.0',
  '1.\u0660',
  '',
  null,
  true,
  ['1.0'],
  { major: 1, minor: 0 },
  undefined,
];

/** Every part kind's bytes with header.format_version set to version (deleted when undefined). */
function withVersion(bytes, version) {
  return edited(bytes, ({ header }) => {
    if (version === undefined) delete header.format_version;
    else header.format_version = version;
  });
}

test('every part and CLIP file must have format_version "1.<digits>" (this build reads 1.x)', async () => {
  const file = readBytes(join(FIXTURES, man.cases.find((c) => c.kind === 'dynamic-pde').clip));
  for (const version of BAD_VERSIONS) {
    const shown = JSON.stringify(version ?? null);
    const want = (part) =>
      `unsupported clip format version ${shown} in the ${part} part (this build reads 1.x)`;
    for (const p of [parts, splineParts, basisParts, rigidParts, cyclicParts]) {
      refused(() => decodeClip(withVersion(p.topology, version), p.coefficients), want('topology'));
      refused(() => decodeClip(p.topology, withVersion(p.coefficients, version)), want('coefficients'));
    }
    const bad = withVersion(file, version);
    refused(() => decodeClipFile(bad), want('clip-file'));
    await assert.rejects(
      loadClipFile(bad),
      (e) => e instanceof ClipFormatError && e.message === want('clip-file'),
    );
  }
});

test('minor versions 1.x decode as 1.0, ignoring the header keys and arrays they may add', () => {
  for (const p of [parts, splineParts, basisParts, rigidParts, cyclicParts]) {
    const want = createEvaluator(decodeClip(p.topology, p.coefficients));
    for (const version of ['1.0', '1.1', '1.10', '1.999999']) {
      const add = ({ header, arrays }) => {
        header.format_version = version;
        header.future_key = { any: ['thing'] };
        header.motion_hint = 'wobble';
        // arrays a later 1.x may add (even with names of removed layouts): read by nobody
        const future = Float32Array.from([1, NaN, -Infinity, 4]);
        arrays.future_array = { dtype: '<f4', shape: [2, 2], data: future };
        arrays.tangents = { dtype: '<u1', shape: [1, 3], data: Uint8Array.from([1, 7, 255]) };
        arrays.family = { dtype: '<f8', shape: [3], data: Float64Array.from([0.5, 2, 9]) };
      };
      const topology = edited(p.topology, add);
      const coefficients = edited(p.coefficients, ({ header, arrays }) => {
        add({ header, arrays });
        header.topology_id = null; // (the topology bytes changed)
      });
      const got = createEvaluator(decodeClip(topology, coefficients));
      for (const t of [0, 0.37, 0.8, 1]) assert.deepEqual(got.evaluate(t), want.evaluate(t), `${version}`);
    }
  }
  // a CLIP file of version 1.3 with extra keys
  const c = man.cases.find((x) => x.spline_items > 0);
  const file = edited(readBytes(join(FIXTURES, c.clip)), ({ header }) => {
    header.format_version = '1.3';
    header.extra = 1;
  });
  assert.deepEqual(
    createEvaluator(decodeClipFile(file)).evaluate(0.4),
    createEvaluator(decodeClipFile(readBytes(join(FIXTURES, c.clip)))).evaluate(0.4),
  );
});

test('unknown kinds, motions and parts are rejected', () => {
  const kind = edited(parts.coefficients, ({ header }) => {
    header.kind = 'spline';
  });
  refused(() => decodeClip(parts.topology, kind), /unknown clip kind "spline"/);
  for (const motion of ['wobble', null, undefined, 3]) {
    const c = edited(parts.coefficients, ({ header }) => {
      header.motion = motion;
    });
    refused(() => decodeClip(parts.topology, c), /unknown motion mode/);
  }
  refused(() => decodeClip(parts.coefficients, parts.topology), /expected a topology part/);
  refused(() => decodeClip(parts.topology, parts.topology), /expected a coefficients part/);
});

test('coefficients made for another topology are refused by loadClip', async () => {
  const other = edited(parts.topology, ({ header }) => {
    header.param_mode = 'paper';
  });
  await assert.rejects(loadClip(other, parts.coefficients), ClipFormatError);
  await assert.rejects(loadClip(other, parts.coefficients), /topology_id mismatch/);
});

test('a CLIP file must be a clip-file container of two uint8 parts', () => {
  refused(() => decodeClipFile(parts.topology), /not a pdeanim CLIP file/);
  const file = readBytes(join(FIXTURES, man.cases[0].clip));
  for (const edit of [
    ({ header }) => {
      header.part = 'clip';
    },
    ({ arrays }) => {
      delete arrays.coefficients;
    },
    ({ arrays }) => {
      const { shape, data } = arrays.topology;
      arrays.topology = { dtype: '<i1', shape, data: Int8Array.from(data) };
    },
  ]) {
    refused(() => decodeClipFile(edited(file, edit)), /not a pdeanim CLIP file/);
  }
});

test('non-finite times and short buffers are refused', () => {
  for (const c of man.cases) {
    const ev = createEvaluator(decodeClipFile(readBytes(join(FIXTURES, c.clip))));
    assert.throws(() => ev.evaluate(NaN), RangeError);
    assert.throws(() => ev.evaluate(Infinity), RangeError);
    assert.throws(() => ev.evaluate(0, new Float32Array(3)), RangeError);
  }
});

test('cyclic clips with a bad swim header or missing arrays are rejected', () => {
  const p = cyclicParts;
  const bad = edited(p.coefficients, ({ header }) => {
    header.swim.frequency = 0;
  });
  refused(() => decodeClip(p.topology, bad), /invalid swim parameters/);
  const noSpine = edited(p.coefficients, ({ arrays }) => {
    delete arrays.spine;
  });
  refused(() => decodeClip(p.topology, noSpine), /lacks arrays: spine/);
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

/** A part with the integers of a zigzag-coded array changed by edit(values). */
function editedCodes(bytes, name, edit, cols = 1) {
  return edited(bytes, ({ arrays }) => {
    const vals = unzigzag(arrays[name].data, cols);
    edit(vals);
    arrays[name] = { ...arrays[name], data: zigzag(vals, cols) };
  });
}

test('topology parts decode to what the helpers encode (zigzag differences, curve order)', () => {
  const { header, arrays } = decodeContainer(parts.topology.slice());
  const clip = decodeClip(parts.topology, parts.coefficients);
  assert.equal(header.format_version, FORMAT_VERSION);
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
  const cols = arrays.u.shape[1];
  const qu = unzigzag(arrays.u.data, cols);
  for (let i = 0; i < order.length; i++) {
    for (let k = 0; k < cols; k++) {
      assert.equal(clip.u[order[i] * cols + k], Math.fround(qu[i * cols + k] * header.u_step));
    }
  }
  let sum = 0;
  arrays.curve_lengths.data.forEach((n, c) => {
    assert.equal(clip.offsets[c], sum);
    sum += n;
  });
  assert.equal(sum, clip.nVertices);
});

test('topologies with bad counts, curves, order, faces, u or steps are rejected', () => {
  const bad = (topo, pattern) => refused(() => decodeClip(topo, parts.coefficients), pattern);
  for (const V of [-1, 1.5, '42', true, null, undefined, [42]]) {
    const t = edited(parts.topology, ({ header }) => {
      if (V === undefined) delete header.n_vertices;
      else header.n_vertices = V;
    });
    const got = JSON.stringify(V ?? null);
    bad(t, `topology header field 'n_vertices' must be a non-negative integer, got ${got}`);
  }
  bad(editedCodes(parts.topology, 'order', (v) => (v[1] = v[0])), /order must be a permutation/);
  bad(editedCodes(parts.topology, 'order', (v) => (v[0] = v.length)), /order holds an index outside/);
  bad(editedCodes(parts.topology, 'order', (v) => (v[2] = -1)), /order holds an index outside/);
  const V = decodeClip(parts.topology, parts.coefficients).nVertices;
  const faceCodes = (edit) =>
    edited(parts.topology, ({ arrays }) => {
      const d = Uint32Array.from(arrays.faces.data);
      edit(d);
      arrays.faces = { ...arrays.faces, data: d };
    });
  bad(faceCodes((d) => (d[4] = 2 * V)), /faces index outside the vertices/); // row 1: offset V past its first
  bad(faceCodes((d) => (d[0] = 5)), /faces index outside the vertices/); // first rank -3
  bad(faceCodes((d) => (d[2] = 2 * V + 1)), /faces index outside the vertices/); // offset -(V + 1)
  const lengths = edited(parts.topology, ({ arrays }) => {
    const d = Uint32Array.from(arrays.curve_lengths.data);
    d[0] += 1;
    arrays.curve_lengths = { ...arrays.curve_lengths, data: d };
  });
  bad(lengths, /curve_lengths must add up to n_vertices/);
  for (const name of ['curve_lengths', 'order', 'u', 'faces', 'rest']) {
    const missing = edited(parts.topology, ({ arrays }) => {
      delete arrays[name];
    });
    bad(missing, `topology part has no '${name}' array`);
    const signed = edited(parts.topology, ({ arrays }) => {
      arrays[name] = { ...arrays[name], dtype: '<i4', data: Int32Array.from(arrays[name].data) };
    });
    bad(signed, `topology array '${name}' has dtype <i4, expected <u4`);
  }
  const uCols = edited(parts.topology, ({ arrays }) => {
    const n = arrays.u.shape[0];
    arrays.u = { ...arrays.u, shape: [n, 2], data: new Uint32Array(n * 2) };
  });
  bad(uCols, /topology array 'u' must have 1 or 3 columns, got 2/);
  for (const [key, value] of [
    ['rest_step', 0],
    ['rest_step', -0.5],
    ['rest_step', '0.001'],
    ['u_step', null],
    ['u_step', undefined],
  ]) {
    const t = edited(parts.topology, ({ header }) => {
      header[key] = value;
    });
    bad(t, new RegExp(`topology ${key} must be a positive finite number`));
  }
  for (const origin of [[0, 0], [0, 0, 'x'], null]) {
    const t = edited(parts.topology, ({ header }) => {
      header.rest_origin = origin;
    });
    bad(t, /rest_origin must be 3 finite numbers/);
  }
  const huge = edited(parts.topology, ({ header }) => {
    header.rest_step = 1e38; // finite, but codes of a few steps leave float32
  });
  bad(huge, /topology rest decode to non-finite values/);
  const hugeU = edited(parts.topology, ({ header }) => {
    header.u_step = 1e38;
  });
  bad(hugeU, /topology u decode to non-finite values/);
});

test('curve parameters outside [0, 1] are rejected (they would overflow the space basis)', () => {
  const t = edited(parts.topology, ({ header }) => {
    header.u_step = 2 ** 40;
  });
  const c = edited(parts.coefficients, ({ header }) => {
    header.topology_id = null;
  });
  refused(() => decodeClip(t, c), /topology curve parameters u must lie in \[0, 1\]/);
});

test('the float layouts of earlier drafts are refused: only the integer-coded arrays are read', () => {
  // a topology with float u and rest, int32 order and faces and curve offsets instead of lengths
  const clip = decodeClip(parts.topology, parts.coefficients);
  const { header } = decodeContainer(parts.topology.slice());
  const floatTopology = encodeContainer(header, {
    offsets: { dtype: '<i4', shape: [clip.nCurves + 1], data: Int32Array.from(clip.offsets) },
    order: { dtype: '<i4', shape: [clip.nVertices], data: Int32Array.from(clip.order) },
    u: { dtype: '<f4', shape: [clip.nVertices, clip.uColumns], data: Float32Array.from(clip.u) },
    faces: { dtype: '<i4', shape: [clip.faces.length / 3, 3], data: Int32Array.from(clip.faces) },
    rest: { dtype: '<f4', shape: [clip.nVertices, 3], data: Float32Array.from(clip.rest) },
  });
  refused(() => decodeClip(floatTopology, parts.coefficients), "topology part has no 'curve_lengths' array");
  // coefficients with float family codes and float knots (no space_kind, knot_step, time_model)
  const { header: ch, arrays } = decodeContainer(parts.coefficients.slice());
  const S = clip.nSegments;
  const C = clip.nCurves;
  const floatCoefficients = encodeContainer(ch, {
    segment_t: arrays.segment_t,
    frame_times: arrays.frame_times,
    family: { dtype: '<u1', shape: [S, C, 3], data: Uint8Array.from(clip.family) },
    m: { dtype: '<f4', shape: [S, C, 3], data: Float32Array.from(clip.m) },
    D: arrays.D,
    knots: { dtype: '<f4', shape: [S + 1, C, 3, 4], data: Float32Array.from(clip.knots) },
  });
  refused(() => decodeClip(parts.topology, floatCoefficients), "coefficients part has no 'space_kind' array");
  const floatKnots = edited(parts.coefficients, ({ arrays: a }) => {
    a.knots = { dtype: '<f4', shape: [S + 1, C, 3, 4], data: Float32Array.from(clip.knots) };
  });
  refused(() => decodeClip(parts.topology, floatKnots), /coefficients array 'knots' has shape/);
});

test('coefficients with bad counts, arrays, space kinds, time constants or boundaries are rejected', () => {
  const bad = (coef, pattern) => refused(() => decodeClip(parts.topology, coef), pattern);
  const { header } = decodeContainer(parts.coefficients.slice());
  for (const S of [-1, 1.5, '3', true, null, undefined, [3]]) {
    const c = edited(parts.coefficients, ({ header: h }) => {
      if (S === undefined) delete h.n_segments;
      else h.n_segments = S;
    });
    const got = JSON.stringify(S ?? null);
    bad(c, `coefficients header field 'n_segments' must be a non-negative integer, got ${got}`);
  }
  // another valid count than the arrays': their shapes disagree
  const more = edited(parts.coefficients, ({ header: h }) => {
    h.n_segments = header.n_segments + 1;
  });
  bad(more, /coefficients array 'segment_t' has shape/);
  const shape = edited(parts.coefficients, ({ arrays }) => {
    arrays.D = { ...arrays.D, shape: [arrays.D.shape[0] * 3], data: arrays.D.data };
  });
  bad(shape, /array 'D' has shape/);
  // every float array has its stated dtype (float64 times, float32 constants)
  for (const [name, dtype, Typed] of [
    ['segment_t', '<f4', Float32Array],
    ['frame_times', '<f4', Float32Array],
    ['D', '<f8', Float64Array],
  ]) {
    const retyped = edited(parts.coefficients, ({ arrays }) => {
      arrays[name] = { ...arrays[name], dtype, data: Typed.from(arrays[name].data) };
    });
    bad(retyped, new RegExp(`array '${name}' has dtype ${dtype}`));
  }
  for (const [name, index] of [
    ['D', 0],
    ['m', 5],
    ['segment_t', 1],
    ['frame_times', 0],
  ]) {
    for (const value of [NaN, Infinity, -Infinity]) {
      const c = edited(parts.coefficients, ({ arrays }) => {
        const d = arrays[name].data.slice();
        d[index] = value;
        arrays[name] = { ...arrays[name], data: d };
      });
      bad(c, `coefficients array '${name}' has non-finite values`);
    }
  }
  for (const name of ['segment_t', 'frame_times', 'space_kind', 'time_model', 'm', 'D']) {
    const missing = edited(parts.coefficients, ({ arrays }) => {
      delete arrays[name];
    });
    // segment_t may be absent only with a knot at every frame, which this clip has not
    const why = name === 'segment_t' ? 'coefficients without segment_t need a knot at every frame' : null;
    bad(missing, why ? new RegExp(why) : `coefficients part has no '${name}' array`);
  }
  for (const [name, dtype, Type, want] of [
    ['space_kind', '<i1', Int8Array, '<u1'],
    ['space_kind', '<u4', Uint32Array, '<u1'],
    ['m', '<f8', Float64Array, '<f4'],
  ]) {
    const c = edited(parts.coefficients, ({ arrays }) => {
      arrays[name] = { ...arrays[name], dtype, data: Type.from(arrays[name].data) };
    });
    bad(c, `coefficients array '${name}' has dtype ${dtype}, expected ${want}`);
  }
  for (const kind of [2, 255]) {
    const c = edited(parts.coefficients, ({ arrays }) => {
      const d = Uint8Array.from(arrays.space_kind.data);
      d[d.length - 1] = kind;
      arrays.space_kind = { ...arrays.space_kind, data: d };
    });
    bad(c, /space kinds must be 0 or 1/);
  }
  // trig time constants at or beyond -pi (float32(-pi) is below -pi)
  for (const mu of [-4, -Math.PI, Math.fround(-Math.PI)]) {
    const c = edited(parts.coefficients, ({ arrays }) => {
      const d = Float32Array.from(arrays.m.data);
      d[d.length - 1] = mu;
      arrays.m = { ...arrays.m, data: d };
    });
    bad(c, 'trig time constants must be above -pi');
  }
  const justAbove = edited(parts.coefficients, ({ arrays }) => {
    const d = Float32Array.from(arrays.m.data);
    d[0] = -3.1415925; // the float32 just above -pi
    arrays.m = { ...arrays.m, data: d };
  });
  assert.ok(decodeClip(parts.topology, justAbove).m[0] > 3.14);
  // segment boundaries: decreasing, or a single boundary (S = 0)
  const { arrays } = decodeContainer(parts.coefficients.slice());
  const segT = Array.from(arrays.segment_t.data);
  const down = retimed(parts.coefficients, { segmentT: segT.map((x, j) => (j === 1 ? -0.5 : x)) });
  bad(down, 'segment boundaries must be non-decreasing with at least one segment');
  const none = edited(parts.coefficients, ({ header: h, arrays: a }) => {
    h.n_segments = 0;
    a.segment_t = { ...a.segment_t, shape: [1], data: Float64Array.from([0]) };
    a.m = { ...a.m, shape: [0, a.m.shape[1], 3], data: new Float32Array(0) };
    const [C] = a.knots.shape;
    a.knots = { ...a.knots, shape: [C, 3, 4, 1], data: new Uint32Array(C * 12) };
  });
  bad(none, 'segment boundaries must be non-decreasing with at least one segment');
});

test('the signed m gives the family: < 0 trig, > 0 exp, 0 linear', () => {
  const c = edited(parts.coefficients, ({ arrays }) => {
    const d = Float32Array.from(arrays.m.data);
    d[0] = -0.5;
    d[1] = 0.5;
    d[2] = 0;
    arrays.m = { ...arrays.m, data: d };
  });
  const clip = decodeClip(parts.topology, c);
  assert.ok(clip.family[0] >= 2 && clip.family[1] < 2 && clip.family[2] < 2); // trig, exp, (linear) exp
  const plain = decodeClip(parts.topology, parts.coefficients);
  for (const i of [0, 1, 2]) assert.equal(clip.family[i] % 2, plain.family[i] % 2); // the item's space kind
  assert.deepEqual(Array.from(clip.m.slice(0, 3)), [0.5, 0.5, 0]);
});

test('time_model: required, (C, 3) uint8 of 0 and 1; null on the clip when no item is on the spline', () => {
  for (const p of [parts, splineParts, basisParts]) {
    const bad = (coef, pattern) => refused(() => decodeClip(p.topology, coef), pattern);
    const { model, C } = timeArrays(p.coefficients);
    const clip = decodeClip(p.topology, p.coefficients);
    if (model.includes(1)) assert.deepEqual(clip.timeModel, model);
    else assert.equal(clip.timeModel, null);
    const edit = (change) =>
      edited(p.coefficients, ({ arrays }) => {
        arrays.time_model = change(arrays.time_model);
      });
    // missing, or the removed `tangents` array in its place
    const missing = edited(p.coefficients, ({ arrays }) => {
      delete arrays.time_model;
    });
    bad(missing, "coefficients part has no 'time_model' array");
    const renamed = edited(p.coefficients, ({ arrays }) => {
      arrays.tangents = arrays.time_model;
      delete arrays.time_model;
    });
    bad(renamed, "coefficients part has no 'time_model' array");
    for (const shape of [[C * 3], [3, C], [C, 3, 1], [C + 1, 3], [C, 4], [1, C, 3]]) {
      const n = shape.reduce((a, b) => a * b, 1);
      const c = edit((a) => ({ ...a, shape, data: new Uint8Array(n) }));
      bad(c, /coefficients array 'time_model' has shape/);
    }
    for (const [dtype, Type] of [
      ['<i1', Int8Array],
      ['<u2', Uint16Array],
      ['<u4', Uint32Array],
      ['<f4', Float32Array],
    ]) {
      const c = edit((a) => ({ ...a, dtype, data: Type.from(a.data) }));
      bad(c, `coefficients array 'time_model' has dtype ${dtype}, expected <u1`);
    }
    for (const value of [2, 3, 255]) {
      for (const i of [0, C * 3 - 1]) {
        const c = edit((a) => {
          const d = Uint8Array.from(a.data);
          d[i] = value;
          return { ...a, data: d };
        });
        bad(c, `coefficients time_model must be 0 (paper) or 1 (natural spline), got ${value}`);
      }
    }
  }
});

test('items on the spline must have m = 0 in every segment; the other items keep their constants', () => {
  const { model, m, C } = timeArrays(splineParts.coefficients);
  const S = m.length / (C * 3);
  assert.ok(S >= 3);
  const item = model.indexOf(1);
  const off = model.indexOf(0);
  assert.ok(item >= 0 && off >= 0);
  assert.ok(Array.from({ length: S }, (_, s) => m[s * C * 3 + off]).some((x) => x !== 0)); // not all linear
  for (const s of [0, 1, S - 1]) {
    for (const mu of [0.5, -0.5, 1e-30, -1e-30, 2]) {
      const c = edited(splineParts.coefficients, ({ arrays }) => {
        const d = Float32Array.from(arrays.m.data);
        d[s * C * 3 + item] = mu;
        arrays.m = { ...arrays.m, data: d };
      });
      refused(
        () => decodeClip(splineParts.topology, c),
        'items on the natural spline must have time constant 0 in every segment',
      );
    }
  }
  // an item put on the spline without zeroing its constants; -0 is 0
  const moved = edited(splineParts.coefficients, ({ arrays }) => {
    const d = Uint8Array.from(arrays.time_model.data);
    d[off] = 1;
    arrays.time_model = { ...arrays.time_model, data: d };
  });
  refused(() => decodeClip(splineParts.topology, moved), /must have time constant 0 in every segment/);
  const negativeZero = edited(splineParts.coefficients, ({ arrays }) => {
    const d = Float32Array.from(arrays.m.data);
    for (let s = 0; s < S; s++) d[s * C * 3 + item] = -0;
    arrays.m = { ...arrays.m, data: d };
  });
  const clip = decodeClip(splineParts.topology, negativeZero);
  assert.equal(clip.m[item], 0);
  // the same clip with every item on the paper's time pairs keeps every constant
  const paper = decodeClip(splineParts.topology, retimed(splineParts.coefficients, { timeModel: () => 0 }));
  assert.equal(paper.timeModel, null);
  assert.deepEqual(paper.m, decodeClip(splineParts.topology, splineParts.coefficients).m);
});

test('a zero-length segment is refused when some item is on the spline, read otherwise', () => {
  for (const p of [splineParts, parts, basisParts]) {
    const { header, arrays } = decodeContainer(p.coefficients.slice());
    const S = header.n_segments;
    const C = arrays.time_model.shape[0];
    const even = Array.from({ length: S + 1 }, (_, j) => j / S);
    for (const j of [0, 1, S - 1]) {
      // segment j of length 0 (the first, an inner one, the last)
      const segmentT = even.map((x, i) => (i === j + 1 ? even[j] : x));
      for (const spline of [(c, w) => Number(c === 1 && w === 2), () => 1]) {
        refused(
          () => decodeClip(p.topology, retimed(p.coefficients, { timeModel: spline, segmentT })),
          `natural-spline items need strictly increasing segment times (segment ${j} has length 0)`,
        );
      }
      const paper = decodeClip(p.topology, retimed(p.coefficients, { timeModel: () => 0, segmentT }));
      assert.equal(paper.timeModel, null);
      assert.ok(createEvaluator(paper).evaluate(even[j]).every(Number.isFinite));
      // strictly increasing boundaries are fine with the spline
      const ok = decodeClip(p.topology, retimed(p.coefficients, { timeModel: () => 1, segmentT: even }));
      assert.equal(ok.timeModel.length, C * 3);
      // decreasing boundaries stay refused with and without spline items
      const back = even.map((x, i) => (i === j + 1 ? -1 : x));
      for (const timeModel of [() => 0, () => 1]) {
        refused(
          () => decodeClip(p.topology, retimed(p.coefficients, { timeModel, segmentT: back })),
          'segment boundaries must be non-decreasing with at least one segment',
        );
      }
    }
  }
});

test('zero-length segments without spline items: the last of equal boundaries wins, t = 1 too', () => {
  // boundaries 0, 0.3, 0.3, 1, 1 (S = 4): t = 0.3 is in segment 2 at tau = 0 (the motion jumps from P_1 to
  // P_2 there), and t = 1 in the empty segment 3 at tau = 0 (its first knot, P_3); every t evaluates as the
  // naive form of docs/format.md
  let tested = 0;
  for (const c of man.cases.filter((x) => x.kind === 'dynamic-pde' && x.spline_items === 0 && !x.bones)) {
    const p = fixtureParts(c);
    if (decodeContainer(p.coefficients.slice()).header.n_segments !== 4) continue;
    tested++;
    const segmentT = [0, 0.3, 0.3, 1, 1];
    const clip = decodeClip(p.topology, retimed(p.coefficients, { segmentT }));
    const ev = createEvaluator(clip);
    assert.deepEqual(ev.locate(0.3).slice(0, 2), [2, 0]);
    assert.deepEqual(ev.locate(0.3 - 1e-12).slice(0, 1), [0]);
    assert.deepEqual(ev.locate(1).slice(0, 2), c.looping ? [0, 0] : [3, 0]);
    for (const t of takenTimes([0, 0.1, 0.3 - 1e-12, 0.3, 0.31, 0.6, 0.999999, 1, 1.5], c.looping)) {
      const worst = worstDeviation(ev.evaluate(t), naiveEvaluate(clip, t));
      assert.ok(worst <= 1e-6 * c.diagonal, `${c.name} t = ${t}: ${worst}`);
    }
  }
  assert.ok(tested >= 2, `${tested} clips of 4 segments`);
});

test('rigid tracks with bad boundaries, shapes, constants or values are rejected', () => {
  const bad = (coef, pattern) => refused(() => decodeClip(rigidParts.topology, coef), pattern);
  const edit = (name, change) =>
    edited(rigidParts.coefficients, ({ arrays }) => {
      arrays[name] = change(arrays[name]);
    });
  const names = ['rigid_segment_t', 'rigid_centre', 'rigid_rot_knots', 'rigid_rot_mu', 'rigid_trans_knots'];
  for (const name of names) {
    const missing = edited(rigidParts.coefficients, ({ arrays }) => {
      delete arrays[name];
    });
    // segment_t may be absent only with a knot at every frame, which this clip has not
    const why = name === 'segment_t' ? 'coefficients without segment_t need a knot at every frame' : null;
    bad(missing, why ? new RegExp(why) : `coefficients part has no '${name}' array`);
  }
  bad(
    edit('rigid_segment_t', (a) => ({ ...a, data: Float64Array.from(a.data, (x, i) => (i === 1 ? -1 : x)) })),
    'rigid segment boundaries must be non-decreasing with at least one segment',
  );
  bad(
    edit('rigid_segment_t', (a) => ({ ...a, shape: [1], data: a.data.slice(0, 1) })),
    'rigid segment boundaries must be non-decreasing with at least one segment',
  );
  const fewer = edit('rigid_trans_knots', (a) => {
    const shape = [a.shape[0] - 1, ...a.shape.slice(1)];
    return { ...a, shape, data: a.data.slice(0, shape.reduce((x, y) => x * y, 1)) };
  });
  bad(fewer, /coefficients array 'rigid_trans_knots' has shape/);
  for (const name of ['rigid_rot_mu', 'rigid_trans_mu']) {
    bad(
      edit(name, (a) => ({ ...a, data: Float32Array.from(a.data, (x, i) => (i === 0 ? -4 : x)) })),
      'rigid trig time constants must be above -pi',
    );
  }
  bad(
    edit('rigid_rot_knots', (a) => ({ ...a, data: Float32Array.from(a.data, (x, i) => (i ? x : NaN)) })),
    "coefficients array 'rigid_rot_knots' has non-finite values",
  );
});

test('segment_t may be left out only with a knot at every frame: it is then the normalised frame times', () => {
  const dense = manifest().cases.find((c) => c.name.endsWith('-windows'));
  const p = fixtureParts(dense);
  const { arrays } = decodeContainer(p.coefficients.slice());
  assert.equal(arrays.segment_t, undefined); // the writer leaves it out
  const ft = arrays.frame_times.data;
  const clip = decodeClip(p.topology, p.coefficients);
  const span = ft[ft.length - 1] - ft[0];
  assert.deepEqual(Array.from(clip.segmentT), Array.from(ft, (x) => (x - ft[0]) / span));
  const flat = edited(p.coefficients, ({ arrays: a }) => {
    a.frame_times = { ...a.frame_times, data: new Float64Array(ft.length) };
  });
  const why = /without segment_t need a knot at every frame/;
  refused(() => decodeClip(p.topology, flat), why);
  const few = edited(parts.coefficients, ({ arrays: a }) => {
    delete a.segment_t;
  });
  refused(() => decodeClip(parts.topology, few), why);
});

test('finite knots or rest values whose frames could overflow float32 are refused at decode (format §5)', () => {
  // knot steps of 2^97: every knot stays finite in float32, yet above 2^96 in magnitude
  const big = edited(parts.coefficients, ({ arrays }) => {
    arrays.knot_step.data = arrays.knot_step.data.map(() => 2 ** 97);
  });
  refused(() => decodeClip(parts.topology, big), /coefficients knots hold a value above 2\^96/);
  const farCyclic = edited(cyclicParts.topology, ({ arrays }) => {
    arrays.rest.data = arrays.rest.data.map((x, i) => (i === 0 ? 1.6e38 : x));
  });
  const coefficients = edited(cyclicParts.coefficients, ({ header }) => {
    header.topology_id = undefined;
  });
  refused(() => decodeClip(farCyclic, coefficients), /cyclic-spine rest hold a value above 2\^96/);
});
