// Test helpers: read the fixtures, and re-encode containers (to build broken inputs).

import { readFileSync } from 'node:fs';
import { fileURLToPath } from 'node:url';
import { dirname, join } from 'node:path';
import { createEvaluator, decodeContainer, splitClipFile, timePair, vertexBasis } from '../src/index.js';

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

/**
 * A version 4 coefficients part (docs/format.md §3.10) re-encoded from a version 2 or 3 one (bytes): header
 * format_version 4, its knot_rank kept (0 for a version 2 part, whose knots then decode as before), and a
 * `tangents` (C, 3) uint8 array from tangents(c, w) (0 or 1). Options: version 5 writes a version 5 part
 * instead (§3.11: the same arrays, natural-spline tangents); linear(s, c, w) true zeroes the signed m of that
 * segment and item (a linear segment, where the cubic applies); segmentT replaces segment_t (float64);
 * edit({header, arrays}) changes anything else before encoding (to build broken parts). Encoded arrays stay
 * encoded (container 2).
 */
export function coefficientsV4(
  bytes,
  { version = 4, tangents = () => 0, linear = null, segmentT = null, edit = null } = {},
) {
  const { header, arrays } = decodeContainer(bytes.slice());
  if (header.format_version !== 2 && header.format_version !== 3) {
    throw new Error(`expected a version 2 or 3 coefficients part, got ${header.format_version}`);
  }
  const C = header.n_curves;
  const S = header.n_segments;
  header.format_version = version;
  header.knot_rank ??= 0;
  if (segmentT) arrays.segment_t = { dtype: '<f8', shape: [S + 1], data: Float64Array.from(segmentT) };
  const t = new Uint8Array(C * 3);
  for (let i = 0; i < t.length; i++) t[i] = tangents(Math.floor(i / 3), i % 3);
  arrays.tangents = { dtype: '<u1', shape: [C, 3], data: t };
  if (linear) {
    const m = Float32Array.from(arrays.m.data);
    for (let i = 0; i < m.length; i++) {
      const item = i % (C * 3);
      if (linear(Math.floor(i / (C * 3)), Math.floor(item / 3), item % 3)) m[i] = 0;
    }
    arrays.m = { ...arrays.m, data: m };
  }
  if (edit) edit({ header, arrays });
  return encodeContainer(header, arrays);
}

/**
 * Version 4 clips built from the version 2 and 3 dynamic-pde fixtures until the Python side writes some:
 * [{name, fixture, motion, looping, diagonal, t, topology, coefficients, original}] where original is the
 * fixture's coefficients part. Items get tangents in a mix (every item of some curves, one coordinate of
 * others, none of the rest) and linear constants in every segment but one, so that the cubic, its
 * neighbours' time pairs and cubic items in non-linear segments all occur; t lists every segment boundary,
 * points just inside each segment, a grid, and times outside [0, 1].
 */
export function versionFourCases({ version = 4 } = {}) {
  const out = [];
  for (const c of manifest().cases) {
    if (c.kind !== 'dynamic-pde' || (c.format_version !== 2 && c.format_version !== 3)) continue;
    const { topology, coefficients } = splitClipFile(readBytes(join(FIXTURES, c.clip)));
    const { header, arrays } = decodeContainer(coefficients.slice());
    const S = header.n_segments;
    const tangents = (cc, w) => (cc % 3 === 0 ? 1 : cc % 3 === 1 ? Number(w === 1) : 0);
    const linear = (s, cc) => s !== (cc % S); // one non-linear segment per curve, the others linear
    // version 5 with tangents needs strictly increasing boundaries: a repeated one moves to the middle
    const segT = version === 5 ? strictlyIncreasing(arrays.segment_t.data) : Array.from(arrays.segment_t.data);
    const written = version === 5 ? segT : null; // (version 4 keeps the fixture's segment_t)
    const t = [...segT];
    for (let s = 0; s < S; s++) {
      for (const f of [1e-9, 0.013, 0.25, 0.5, 0.77, 1 - 1e-9]) t.push(segT[s] + f * (segT[s + 1] - segT[s]));
    }
    for (let k = 0; k <= 20; k++) t.push(k / 20);
    if (c.looping) t.push(-0.3, 1.2, 2.61); // clips that do not loop take t in [0, 1] only
    out.push({
      name: `${c.name}-v${version}`,
      fixture: c,
      motion: c.motion,
      looping: c.looping,
      diagonal: c.diagonal,
      t,
      topology,
      coefficients: coefficientsV4(coefficients, { version, tangents, linear, segmentT: written }),
      original: coefficients,
      segmentT: written,
    });
  }
  return out;
}

/**
 * Version 5 clips (natural-spline time tangents, docs/format.md §3.11) built as versionFourCases() builds
 * version 4 ones, with strictly increasing segment boundaries (the synthetic fixtures' repeated boundary
 * moved halfway to the next): [{..., name: '<fixture>-v5', segmentT}] (segmentT: the boundaries written; pass
 * it to coefficientsV4 to build the same clip with other options).
 */
export function versionFiveCases() {
  return versionFourCases({ version: 5 });
}

/** Boundaries (array of numbers) with each repeated one moved halfway to the next (or last) distinct one. */
export function strictlyIncreasing(segT) {
  const out = Array.from(segT);
  for (let j = 1; j < out.length; j++) {
    if (out[j] > out[j - 1]) continue;
    let k = j;
    while (k < out.length && !(out[k] > out[j - 1])) k++;
    if (k === out.length) throw new Error('the last boundaries are equal');
    out[j] = (out[j - 1] + out[k]) / 2;
  }
  return out;
}

/** The largest absolute difference between two equal-length arrays. */
export function worstDeviation(a, b) {
  let worst = 0;
  for (let i = 0; i < a.length; i++) worst = Math.max(worst, Math.abs(a[i] - b[i]));
  return worst;
}

/** Segment, local time and wrapped time of t (docs/format.md §2, §3.6 step 1), written out naively. */
export function naiveLocate(segT, t, looping) {
  const tw = looping ? t - Math.floor(t) : Math.min(Math.max(t, 0), 1);
  const S = segT.length - 1;
  let s = 0;
  for (let j = 0; j <= S; j++) if (segT[j] <= tw) s = j;
  s = Math.min(s, S - 1);
  const len = segT[s + 1] - segT[s];
  const tau = Math.min(Math.max((tw - segT[s]) / (len > 0 ? len : 1), 0), 1);
  return [s, tau, tw];
}

/** Catmull-Rom knot tangents of §3.10 (one-sided at the ends, 0 where the times are equal) of values P. */
export function centralTangents(segT, P) {
  const S = segT.length - 1;
  return P.map((_, j) => {
    const lo = Math.max(j - 1, 0);
    const hi = Math.min(j + 1, S);
    const dt = segT[hi] - segT[lo];
    return dt === 0 ? 0 : (P[hi] - P[lo]) / dt;
  });
}

/**
 * Positions (V * 3, float64) of a decoded clip at t from the Hermite form of §3.10, in float64 throughout:
 * the knot values P_j per vertex coordinate, their tangents T = tangentsOf(segmentT, P) (central differences
 * for version 4, the natural spline's for version 5), value = h00 P_s + h01 P_s+1 + Δ (h10 T_s + h11 T_s+1)
 * for items with tangents 1 in segments with a linear constant, the time pair of §3.4 otherwise. The space
 * basis and the rigid motion are the library's (checked by the conformance fixtures).
 */
export function naiveEvaluate(clip, t, tangentsOf) {
  const { nVertices: V, nCurves: C, nSegments: S, curveOf, knots, segmentT: segT, family, m } = clip;
  const B = vertexBasis(clip);
  const knotValues = (v, w) =>
    Array.from({ length: S + 1 }, (_, j) => {
      let acc = 0;
      for (let k = 0; k < 4; k++) acc += knots[((j * C + curveOf[v]) * 3 + w) * 4 + k] * B[v * 12 + w * 4 + k];
      return acc;
    });
  const [s, tau, tw] = naiveLocate(segT, t, clip.looping);
  const delta = segT[s + 1] - segT[s];
  const h00 = (1 + 2 * tau) * (1 - tau) ** 2;
  const h01 = tau * tau * (3 - 2 * tau);
  const h10 = tau * (1 - tau) ** 2;
  const h11 = tau * tau * (tau - 1);
  let rot = null;
  let trans = null;
  if (clip.rigid) {
    const ev = createEvaluator(clip);
    ev.prepare(tw);
    rot = ev.rot;
    trans = ev.trans;
  }
  const out = new Float64Array(V * 3);
  for (let v = 0; v < V; v++) {
    const c = curveOf[v];
    const x = [0, 1, 2].map((w) => {
      const i = (s * C + c) * 3 + w;
      const mu = (family[i] >= 2 ? -1 : 1) * m[i];
      const P = knotValues(v, w);
      let value;
      if (clip.tangents?.[c * 3 + w] === 1 && Math.abs(mu) <= 1e-12) {
        const T = tangentsOf(segT, P);
        value = h00 * P[s] + h01 * P[s + 1] + delta * (h10 * T[s] + h11 * T[s + 1]);
      } else {
        const pair = timePair(tau, mu, [0, 0]);
        value = pair[0] * P[s] + pair[1] * P[s + 1];
      }
      const rest = clip.rest[v * 3 + w];
      if (clip.motion === 'displacement') return rest + value;
      if (clip.motion === 'absolute') return value;
      return rest - clip.rigid.centre[c * 3 + w] + value;
    });
    for (let w = 0; w < 3; w++) {
      const r = c * 9 + w * 3;
      out[v * 3 + w] = rot ? rot[r] * x[0] + rot[r + 1] * x[1] + rot[r + 2] * x[2] + trans[c * 3 + w] : x[w];
    }
  }
  return out;
}
