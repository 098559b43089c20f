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
import { FIXTURES, encodeContainer, manifest, readBytes } from './helpers.mjs';

const man = manifest();
const dynamicCase = (version) =>
  man.cases.find((c) => c.kind === 'dynamic-pde' && c.motion === 'displacement' && c.format_version === version);
const parts = splitClipFile(readBytes(join(FIXTURES, dynamicCase(1).clip))); // format version 1
const parts2 = splitClipFile(readBytes(join(FIXTURES, dynamicCase(2).clip))); // format version 2

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
  for (const p of [parts, parts2]) {
    const v3 = edited(p.coefficients, ({ header }) => {
      header.format_version = 3;
    });
    assert.throws(() => decodeClip(p.topology, v3), /unsupported dynamic-pde coefficients version 3 \(this build reads 1 and 2\)/);
    const t3 = edited(p.topology, ({ header }) => {
      header.format_version = 3;
    });
    assert.throws(() => decodeClip(t3, p.coefficients), /unsupported dynamic-pde topology version 3/);
  }
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
  assert.equal(clip.family[0] % 2, clip.family[1] % 2); // one space kind per item
  assert.deepEqual(Array.from(clip.m.slice(0, 3)), [0.5, 0.5, 0]);
});
