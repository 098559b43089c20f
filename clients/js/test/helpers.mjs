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

/** Container bytes from a header and arrays {name: {dtype, shape, data}} (inverse of decodeContainer). */
export function encodeContainer(header, arrays) {
  const table = {};
  const chunks = [];
  let offset = 0;
  for (const [name, a] of Object.entries(arrays)) {
    const raw = new Uint8Array(a.data.buffer, a.data.byteOffset, a.data.byteLength);
    table[name] = { dtype: a.dtype, shape: a.shape, offset, nbytes: raw.byteLength };
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
  view.setUint32(8, 1, true);
  view.setUint32(12, hl, true);
  out.set(meta, 16);
  let o = 16 + hl;
  for (const c of chunks) {
    out.set(c, o);
    o += c.length;
  }
  return out;
}
