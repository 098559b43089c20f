// The one container version (1): arrays stored raw, as one zstd frame ("zstd") or as byte planes in one
// ("shuffle-zstd"), read exactly; bad frames, sizes, encodings and every other container version rejected
// with a reason.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import * as api from '../src/index.js';
import {
  CONTAINER_VERSION,
  ClipFormatError,
  ENCODINGS,
  FORMAT_VERSION,
  decodeClip,
  decodeContainer,
  splitClipFile,
} from '../src/index.js';
import {
  FIXTURES,
  concat,
  encodeContainer,
  fixtureParts,
  manifest,
  readBytes,
  shuffleBytes,
  storedArrays,
  zstdStoredFrame,
} from './helpers.mjs';

const man = manifest();
const partsOf = (name) => fixtureParts(man.cases.find((c) => c.name === name));
/** The uint32 at byte 8 of container bytes. */
const versionOf = (b) => new DataView(b.buffer, b.byteOffset, b.byteLength).getUint32(8, true);

/** Arrays of every dtype width with values whose bytes differ (so a wrong byte order shows). */
function sampleArrays() {
  return {
    f8: { dtype: '<f8', shape: [3, 2], data: Float64Array.from([1.5, -2.25e-300, 3e300, 0, -0, Math.PI]) },
    f4: { dtype: '<f4', shape: [4], data: Float32Array.from([1.1, -7, 65504.5, 1e-38]) },
    u4: { dtype: '<u4', shape: [5], data: Uint32Array.from([0, 1, 0xdeadbeef, 0x01020304, 4294967295]) },
    i2: { dtype: '<i2', shape: [3], data: Int16Array.from([-1, 258, -32768]) },
    u1: { dtype: '<u1', shape: [2, 2], data: Uint8Array.from([9, 8, 7, 250]) },
    empty: { dtype: '<f4', shape: [0, 3], data: new Float32Array(0) },
  };
}

function withEncoding(arrays, encoding) {
  return Object.fromEntries(Object.entries(arrays).map(([k, a]) => [k, { ...a, encoding }]));
}

test('the build reads container version 1 and clip format 1.x; the per-version exports are gone', () => {
  assert.equal(CONTAINER_VERSION, 1);
  assert.equal(FORMAT_VERSION, '1.0');
  assert.deepEqual([...ENCODINGS], ['zstd', 'shuffle-zstd']);
  assert.ok(Object.isFrozen(ENCODINGS));
  for (const name of [
    'CONTAINER_VERSIONS',
    'DYNAMIC_FORMAT_VERSION',
    'DYNAMIC_FORMAT_VERSIONS',
    'DYNAMIC_TOPOLOGY_VERSIONS',
    'hermiteWeights',
  ]) {
    assert.equal(name in api, false, name);
  }
});

for (const encoding of ['zstd', 'shuffle-zstd']) {
  test(`arrays stored with encoding ${encoding} decode to the same values`, () => {
    const arrays = sampleArrays();
    const blob = encodeContainer({ part: 'test' }, withEncoding(arrays, encoding));
    assert.equal(versionOf(blob), 1);
    const got = decodeContainer(blob);
    assert.deepEqual(got.header, { part: 'test' });
    for (const [name, a] of Object.entries(arrays)) {
      assert.deepEqual(got.arrays[name].shape, a.shape, name);
      assert.equal(got.arrays[name].dtype, a.dtype, name);
      assert.equal(got.arrays[name].encoding, encoding, name);
      assert.deepEqual(got.arrays[name].data, a.data, name);
    }
  });
}

test('shuffle-zstd puts byte j of element i at j * n + i', () => {
  const data = Uint32Array.from([0x04030201, 0x08070605]);
  const planes = Uint8Array.from([1, 5, 2, 6, 3, 7, 4, 8]);
  assert.deepEqual(shuffleBytes(new Uint8Array(data.buffer), 4), planes);
  const stored = zstdStoredFrame(planes);
  const blob = encodeContainer({}, { a: { dtype: '<u4', shape: [2], encoding: 'shuffle-zstd', stored } });
  assert.deepEqual(decodeContainer(blob).arrays.a.data, data);
});

test('a container may mix raw and encoded arrays, or hold raw ones only', () => {
  const arrays = sampleArrays();
  const mixed = {
    ...arrays,
    u4: { ...arrays.u4, encoding: 'zstd' },
    i2: { ...arrays.i2, encoding: 'shuffle-zstd' },
  };
  const got = decodeContainer(encodeContainer({}, mixed));
  assert.deepEqual(got.arrays.f8.data, arrays.f8.data);
  assert.equal(got.arrays.f8.encoding, undefined);
  assert.deepEqual(got.arrays.u4.data, arrays.u4.data);
  assert.equal(got.arrays.u4.encoding, 'zstd');
  assert.deepEqual(got.arrays.i2.data, arrays.i2.data);
  const raw = decodeContainer(encodeContainer({}, arrays));
  for (const [name, a] of Object.entries(arrays)) {
    assert.deepEqual(raw.arrays[name].data, a.data, name);
    assert.equal(raw.arrays[name].encoding, undefined, name);
  }
});

test('the Python-written fixtures use both encodings, real zstd compression and container version 1', () => {
  const seen = new Set();
  const versions = new Set();
  let compressed = 0;
  for (const c of man.cases) {
    const file = readBytes(join(FIXTURES, c.clip));
    versions.add(versionOf(file));
    const parts = splitClipFile(file);
    for (const part of [parts.topology, parts.coefficients]) {
      versions.add(versionOf(part));
      for (const [name, a] of Object.entries(storedArrays(part))) {
        if (!a.encoding) continue;
        seen.add(a.encoding);
        const decoded = decodeContainer(part).arrays[name];
        const count = a.shape.reduce((x, y) => x * y, 1);
        assert.equal(decoded.data.length, count);
        if (a.nbytes < count * decoded.data.BYTES_PER_ELEMENT) compressed++;
      }
    }
  }
  assert.deepEqual([...seen].sort(), ['shuffle-zstd', 'zstd']);
  assert.deepEqual([...versions], [1]);
  assert.ok(compressed > 0, 'no array is smaller than its raw bytes');
});

/** A container with one u4 array "a" of 64 values whose stored bytes are `stored`. */
function oneArray(stored, { encoding = 'zstd', version } = {}) {
  return encodeContainer({}, { a: { dtype: '<u4', shape: [64], encoding, stored } }, { version });
}

const VALUES = Uint32Array.from({ length: 64 }, (_, i) => i * 2654435761);
const RAW = new Uint8Array(VALUES.buffer);

test('a frame declaring another size than the array is rejected before decompressing', () => {
  assert.throws(() => decodeContainer(oneArray(zstdStoredFrame(RAW, { declared: 255 }))), (err) => {
    assert.ok(err instanceof ClipFormatError);
    assert.match(err.message, /array "a": zstd frame holds 255 bytes, expected 256/);
    return true;
  });
  // no content size in the header (descriptor 0x00: no single segment, no size field)
  const noSize = concat([Uint8Array.from([0x28, 0xb5, 0x2f, 0xfd, 0x00, 0x58]), zstdStoredFrame(RAW).subarray(9)]);
  assert.throws(() => decodeContainer(oneArray(noSize)), /does not declare its content size/);
});

test('frames whose content is shorter or longer than declared are rejected', () => {
  const short = zstdStoredFrame(RAW.subarray(0, 200), { declared: 256 });
  assert.throws(() => decodeContainer(oneArray(short)), /decompresses to 200 bytes, expected 256/);
  const long = zstdStoredFrame(concat([RAW, RAW]), { declared: 256 });
  assert.throws(() => decodeContainer(oneArray(long)), /decompresses to more than the expected 256 bytes/);
});

test('truncated, garbled and foreign zstd data is rejected', () => {
  const frame = zstdStoredFrame(RAW, { blockSize: 100 });
  for (const cut of [3, 8, 12, frame.length - 1]) {
    assert.throws(() => decodeContainer(oneArray(frame.subarray(0, cut))), /array "a": bad zstd data/, `cut ${cut}`);
  }
  assert.throws(() => decodeContainer(oneArray(concat([frame, Uint8Array.of(0)]))), /1 bytes after the frame/);
  assert.throws(() => decodeContainer(oneArray(concat([frame, frame]))), /bytes after the frame/);
  const notZstd = frame.slice();
  notZstd[0] ^= 0xff;
  assert.throws(() => decodeContainer(oneArray(notZstd)), /not a zstd frame/);
  const reserved = frame.slice();
  reserved[9] |= 6; // first block header: type 3 (reserved)
  assert.throws(() => decodeContainer(oneArray(reserved)), /reserved block type/);

  // a real (Python-written, compressed) frame: truncated, and its compressed block garbled
  const part = partsOf('fit-rigid-chord').coefficients;
  const [name, spec] = Object.entries(storedArrays(part)).find(([, a]) => a.encoding && a.nbytes > 40);
  const blob = (stored) => encodeContainer({}, { [name]: { ...spec, stored } });
  assert.ok(decodeContainer(blob(spec.stored)).arrays[name].data.length > 0);
  assert.throws(() => decodeContainer(blob(spec.stored.subarray(0, spec.nbytes - 5))), /bad zstd data/);
  const garbled = spec.stored.slice();
  garbled.fill(0xff, 12, spec.nbytes); // the compressed block's literals and sequences
  assert.throws(() => decodeContainer(blob(garbled)), ClipFormatError);
});

test('unknown encodings and every container version but 1 are rejected (2 too: there is one version)', () => {
  const frame = zstdStoredFrame(RAW);
  assert.deepEqual(decodeContainer(oneArray(frame)).arrays.a.data, VALUES);
  for (const encoding of ['lz4', 'ZSTD', 'shuffle', '', null, 1]) {
    const want = `array "a" has an unknown encoding ${JSON.stringify(encoding)} (known: zstd, shuffle-zstd)`;
    assert.throws(
      () => decodeContainer(oneArray(frame, { encoding })),
      (e) => e instanceof ClipFormatError && e.message === want,
    );
  }
  for (const version of [0, 2, 3, 7, 256, 2 ** 32 - 1]) {
    for (const blob of [oneArray(frame, { version }), encodeContainer({}, sampleArrays(), { version })]) {
      assert.throws(
        () => decodeContainer(blob),
        (e) =>
          e instanceof ClipFormatError &&
          e.message === `unsupported container version ${version} (this build reads 1)`,
      );
    }
  }
  // the Python-written parts too
  const part = partsOf('fit-rigid-chord').coefficients.slice();
  new DataView(part.buffer).setUint32(8, 2, true);
  assert.throws(() => decodeContainer(part), /unsupported container version 2 \(this build reads 1\)/);
});

test('a CLIP file is a container of two raw uint8 parts whose own arrays are encoded', () => {
  const c = man.cases.find((x) => x.kind === 'dynamic-pde');
  const bytes = readBytes(join(FIXTURES, c.clip));
  const file = storedArrays(bytes);
  assert.deepEqual(Object.keys(file).sort(), ['coefficients', 'topology']);
  for (const a of Object.values(file)) {
    assert.equal(a.dtype, '<u1');
    assert.equal(a.encoding, undefined);
  }
  const { topology, coefficients, header } = splitClipFile(bytes);
  assert.equal(header.part, 'clip-file');
  assert.equal(header.format_version, FORMAT_VERSION);
  assert.ok(Object.values(storedArrays(topology)).every((a) => a.encoding));
  assert.ok(Object.values(storedArrays(coefficients)).every((a) => a.encoding));
  const clip = decodeClip(topology, coefficients);
  assert.equal(clip.header.format_version, FORMAT_VERSION);
  assert.equal(clip.topologyHeader.format_version, FORMAT_VERSION);
});
