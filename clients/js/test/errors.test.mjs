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
const dyn = man.cases.find((c) => c.kind === 'dynamic-pde' && c.motion === 'displacement');
const parts = splitClipFile(readBytes(join(FIXTURES, dyn.clip)));

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
  new DataView(future.buffer).setUint32(8, 2, true);
  assert.throws(() => decodeContainer(future), /unsupported container version 2/);
  assert.throws(
    () => decodeContainer(parts.coefficients.slice(0, parts.coefficients.length - 64)),
    /outside the container/,
  );
});

test('unknown format versions, kinds and motions are rejected', () => {
  const v2 = edited(parts.coefficients, ({ header }) => {
    header.format_version = 2;
  });
  assert.throws(() => decodeClip(parts.topology, v2), /unsupported dynamic-pde coefficients version 2/);
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
