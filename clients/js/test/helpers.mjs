// Test helpers: read the fixtures, and re-encode containers (to build broken inputs).

import { readFileSync } from 'node:fs';
import { fileURLToPath } from 'node:url';
import { dirname, join } from 'node:path';

export const FIXTURES = join(dirname(fileURLToPath(import.meta.url)), 'fixtures');

export function readBytes(path) {
  const b = readFileSync(path);
  return new Uint8Array(b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength));
}

export function manifest() {
  return JSON.parse(readFileSync(join(FIXTURES, 'manifest.json'), 'utf8'));
}

export function expected(c) {
  return new Float32Array(readBytes(join(FIXTURES, c.expected)).buffer);
}

const ITEMSIZE = { '<f4': 4, '<f8': 8, '<i4': 4, '<u4': 4, '<i2': 2, '<u2': 2, '<u1': 1, '<i1': 1 };

/**
 * A zstd frame (RFC 8878) holding bytes in raw blocks (no compression: the tests need frames, not ratios),
 * declaring `declared` bytes of content (default: the true length) in a 4-byte content-size field.
 */
export function zstdStoredFrame(bytes, { declared = bytes.length, blockSize = 1 << 16 } = {}) {
  const blocks = [];
  for (let o = 0; o === 0 || o < bytes.length; o += blockSize) {
    const part = bytes.subarray(o, Math.min(o + blockSize, bytes.length));
    const last = o + blockSize >= bytes.length ? 1 : 0;
    const h = (part.length << 3) | last; // block type 0: raw
    blocks.push(new Uint8Array([h & 255, (h >> 8) & 255, (h >> 16) & 255]), part);
  }
  // magic; frame header descriptor: 4-byte content size (0b10 << 6), single segment (1 << 5)
  const head = new Uint8Array([0x28, 0xb5, 0x2f, 0xfd, 0xa0, 0, 0, 0, 0]);
  new DataView(head.buffer).setUint32(5, declared, true);
  return concat([head, ...blocks]);
}

/** Bytes of element i grouped by byte plane: byte j (least significant first) of element i at j * n + i. */
export function shuffleBytes(raw, itemsize) {
  const n = raw.length / itemsize;
  const out = new Uint8Array(raw.length);
  for (let i = 0; i < n; i++) for (let j = 0; j < itemsize; j++) out[j * n + i] = raw[i * itemsize + j];
  return out;
}

export function concat(parts) {
  const out = new Uint8Array(parts.reduce((a, p) => a + p.length, 0));
  let o = 0;
  for (const p of parts) {
    out.set(p, o);
    o += p.length;
  }
  return out;
}

/**
 * Container bytes from a header and arrays {name: {dtype, shape, data, encoding?, stored?}} (inverse of
 * decodeContainer). An array with an encoding ("zstd", "shuffle-zstd") is stored as a raw-block zstd frame,
 * or as its `stored` bytes verbatim when given; the version is 2 when any array has an encoding, 1 otherwise
 * (as the Python writer), unless given.
 */
export function encodeContainer(header, arrays, { version } = {}) {
  const table = {};
  const chunks = [];
  let offset = 0;
  const encoded = Object.values(arrays).some((a) => a.encoding !== undefined);
  for (const [name, a] of Object.entries(arrays)) {
    let raw = a.data ? new Uint8Array(a.data.buffer, a.data.byteOffset, a.data.byteLength) : null;
    table[name] = { dtype: a.dtype, shape: a.shape, offset };
    if (a.encoding !== undefined) {
      table[name].encoding = a.encoding;
      if (a.stored) raw = a.stored;
      else {
        const plain = a.encoding === 'shuffle-zstd' ? shuffleBytes(raw, ITEMSIZE[a.dtype]) : raw;
        raw = zstdStoredFrame(plain);
      }
    }
    table[name].nbytes = raw.byteLength;
    const padded = Math.ceil(raw.byteLength / 8) * 8;
    const chunk = new Uint8Array(padded);
    chunk.set(raw);
    chunks.push(chunk);
    offset += padded;
  }
  let meta = new TextEncoder().encode(JSON.stringify({ ...header, arrays: table }));
  const hl = Math.ceil(meta.length / 8) * 8;
  const metaPadded = new Uint8Array(hl).fill(32);
  metaPadded.set(meta);
  meta = metaPadded;
  const out = new Uint8Array(16 + hl + offset);
  out.set(new TextEncoder().encode('PDEANIM\0'), 0);
  const view = new DataView(out.buffer);
  view.setUint32(8, version ?? (encoded ? 2 : 1), true);
  view.setUint32(12, hl, true);
  out.set(meta, 16);
  let o = 16 + hl;
  for (const c of chunks) {
    out.set(c, o);
    o += c.length;
  }
  return out;
}

/** The stored bytes of each array of a container, as written (encoded arrays still compressed). */
export function storedArrays(bytes) {
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const hl = view.getUint32(12, true);
  const header = JSON.parse(new TextDecoder().decode(bytes.subarray(16, 16 + hl)));
  const out = {};
  for (const [name, spec] of Object.entries(header.arrays)) {
    const lo = 16 + hl + spec.offset;
    out[name] = { ...spec, stored: bytes.slice(lo, lo + spec.nbytes) };
  }
  return out;
}
