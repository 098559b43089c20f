// Test helpers: read the fixtures, re-encode containers (to build broken or varied inputs), and evaluate
// clips naively (float64, straight from docs/format.md) as a reference.

import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { fileURLToPath } from 'node:url';
import { dirname, join } from 'node:path';
import {
  ClipFormatError,
  createEvaluator,
  decodeContainer,
  splitClipFile,
  timePair,
  vertexBasis,
} from '../src/index.js';

export const FIXTURES = join(dirname(fileURLToPath(import.meta.url)), 'fixtures');

export function readBytes(path) {
  const b = readFileSync(path);
  return new Uint8Array(b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength));
}

export function manifest() {
  return JSON.parse(readFileSync(join(FIXTURES, 'manifest.json'), 'utf8'));
}

/** The manifest without its streamable cases, for tests of whole clips' internals (knots, tables). */
export function withoutStream(man) {
  return { ...man, cases: man.cases.filter((c) => !c.stream) };
}

export function expected(c) {
  return new Float32Array(readBytes(join(FIXTURES, c.expected)).buffer);
}

/** The two parts {topology, coefficients, header} of a manifest case's CLIP file. */
export function fixtureParts(c) {
  return splitClipFile(readBytes(join(FIXTURES, c.clip)));
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
 * or as its `stored` bytes verbatim when given. The version at byte 8 is 1 (the one container version)
 * unless given.
 */
export function encodeContainer(header, arrays, { version = 1 } = {}) {
  const table = {};
  const chunks = [];
  let offset = 0;
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
  view.setUint32(8, version, true);
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

/** Assert that fn throws a ClipFormatError whose message matches want (a RegExp) or equals it (a string). */
export function refused(fn, want) {
  assert.throws(fn, (e) => {
    assert.ok(e instanceof ClipFormatError, `not a ClipFormatError: ${e}`);
    if (typeof want === 'string') assert.equal(e.message, want);
    else assert.match(e.message, want);
    return true;
  });
}

/**
 * A part (bytes) re-encoded with its header and arrays changed by edit({header, arrays}); encoded arrays stay
 * encoded (as raw-block zstd frames).
 */
export function edited(bytes, edit) {
  const { header, arrays } = decodeContainer(bytes.slice());
  edit({ header, arrays });
  return encodeContainer(header, arrays);
}

/**
 * A dynamic-pde coefficients part (bytes) with other time models: timeModel(c, w) gives each item's
 * time_model (0: the paper's time pair, 1: the natural spline; default: the part's own), and an item on the
 * spline gets m = 0 in every segment (the format requires it); linear(s, c, w) true zeroes m of more segments
 * and items; segmentT replaces segment_t.
 */
export function retimed(bytes, { timeModel = null, linear = null, segmentT = null } = {}) {
  return edited(bytes, ({ arrays }) => {
    const C = arrays.time_model.shape[0];
    const model = Uint8Array.from(arrays.time_model.data);
    if (timeModel) for (let i = 0; i < model.length; i++) model[i] = timeModel(Math.floor(i / 3), i % 3);
    arrays.time_model = { ...arrays.time_model, data: model };
    const m = Float32Array.from(arrays.m.data);
    for (let i = 0; i < m.length; i++) {
      const item = i % (C * 3);
      const s = Math.floor(i / (C * 3));
      if (model[item] === 1 || linear?.(s, Math.floor(item / 3), item % 3)) m[i] = 0;
    }
    arrays.m = { ...arrays.m, data: m };
    if (segmentT) {
      const data = Float64Array.from(segmentT);
      arrays.segment_t = { dtype: '<f8', shape: [data.length], data };
    }
  });
}

/**
 * Times that reach every part of a clip with boundaries segT: every boundary, points just inside and across
 * each segment, a grid, and for looping clips times outside [0, 1] (the others refuse them).
 */
export function sampleTimes(segT, looping) {
  const t = Array.from(segT);
  for (let s = 0; s + 1 < segT.length; s++) {
    for (const f of [1e-9, 0.013, 0.25, 0.5, 0.77, 1 - 1e-9]) t.push(segT[s] + f * (segT[s + 1] - segT[s]));
  }
  for (let k = 0; k <= 20; k++) t.push(k / 20);
  if (looping) t.push(-0.3, 1.2, 2.61);
  return t;
}

/** The times of a list that a clip takes: all for a looping clip, those in [0, 1] for the others. */
export function takenTimes(times, looping) {
  return looping ? [...times] : times.filter((t) => t >= 0 && t <= 1);
}

/** The largest absolute difference between two equal-length arrays. */
export function worstDeviation(a, b) {
  let worst = 0;
  for (let i = 0; i < a.length; i++) worst = Math.max(worst, Math.abs(a[i] - b[i]));
  return worst;
}

/** Segment, local time and wrapped time of t (docs/format.md §2, §3.8 step 1), written out naively. */
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

/**
 * The natural spline's tangents T_0..T_S of knot values P (S+1) at times t (docs/format.md §3.5.2) from the
 * full (S+1) x (S+1) system, by Gaussian elimination with partial pivoting on the dense matrix (float64).
 */
export function denseSplineTangents(t, P) {
  const S = t.length - 1;
  const n = S + 1;
  const A = Array.from({ length: n }, () => new Float64Array(n + 1)); // augmented rows
  const d = (j) => (P[j + 1] - P[j]) / (t[j + 1] - t[j]);
  A[0][0] = 2;
  A[0][1] = 1;
  A[0][n] = 3 * d(0);
  for (let j = 1; j < S; j++) {
    const dl = t[j] - t[j - 1];
    const dr = t[j + 1] - t[j];
    A[j][j - 1] = dr;
    A[j][j] = 2 * (dl + dr);
    A[j][j + 1] = dl;
    A[j][n] = 3 * (dr * d(j - 1) + dl * d(j));
  }
  A[S][S - 1] += 1; // (with S = 1 row 0 and row S share no entry: += keeps both rows' terms)
  A[S][S] += 2;
  A[S][n] = 3 * d(S - 1);
  for (let k = 0; k < n; k++) {
    let best = k;
    for (let i = k + 1; i < n; i++) if (Math.abs(A[i][k]) > Math.abs(A[best][k])) best = i;
    [A[k], A[best]] = [A[best], A[k]];
    for (let i = k + 1; i < n; i++) {
      const f = A[i][k] / A[k][k];
      for (let j = k; j <= n; j++) A[i][j] -= f * A[k][j];
    }
  }
  const T = new Float64Array(n);
  for (let k = n - 1; k >= 0; k--) {
    let acc = A[k][n];
    for (let j = k + 1; j < n; j++) acc -= A[k][j] * T[j];
    T[k] = acc / A[k][k];
  }
  return T;
}

/** Per decoded clip, its knot values P[v * 3 + w] (S+1 each, float64) and their dense spline tangents. */
const naiveKnots = new WeakMap();

function knotValuesOf(clip) {
  let out = naiveKnots.get(clip);
  if (out) return out;
  const { nVertices: V, nCurves: C, nSegments: S, curveOf, knots, segmentT } = clip;
  const B = vertexBasis(clip);
  const P = [];
  const T = [];
  for (let v = 0; v < V; v++) {
    for (let w = 0; w < 3; w++) {
      const values = Array.from({ length: S + 1 }, (_, j) => {
        const o = ((j * C + curveOf[v]) * 3 + w) * 4;
        let acc = 0;
        for (let k = 0; k < 4; k++) acc += knots[o + k] * B[v * 12 + w * 4 + k];
        return acc;
      });
      P.push(values);
      T.push(clip.timeModel?.[curveOf[v] * 3 + w] === 1 ? denseSplineTangents(segmentT, values) : null);
    }
  }
  out = { P, T };
  naiveKnots.set(clip, out);
  return out;
}

/**
 * Positions (V * 3, float64) of a decoded dynamic clip at t, in float64 throughout, from docs/format.md
 * §3.5: per vertex coordinate the knot values P_j; items with time_model 1 take the Hermite form
 * h00 P_s + h01 P_s+1 + Δ (h10 T_s + h11 T_s+1) with the tangents of the dense spline system, the others the
 * time pair of their constant. The space basis and the rigid motion are the library's (checked by the
 * conformance fixtures).
 */
export function naiveEvaluate(clip, t) {
  const { nVertices: V, nCurves: C, curveOf, segmentT: segT, family, m } = clip;
  const knotValues = knotValuesOf(clip);
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
      const P = knotValues.P[v * 3 + w];
      const T = knotValues.T[v * 3 + w];
      let value;
      if (T) value = h00 * P[s] + h01 * P[s + 1] + delta * (h10 * T[s] + h11 * T[s + 1]);
      else {
        const pair = timePair(tau, (family[i] >= 2 ? -1 : 1) * m[i], [0, 0]);
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

/**
 * The conformance tolerance of docs/format.md §6 for a manifest case c whose positions are values: 1e-6 of
 * the diagonal plus 2^-20 of the largest coordinate magnitude (float32 rounding grows with the coordinates).
 */
export function caseTolerance(c, values) {
  const man = manifest();
  let largest = 0;
  for (let i = 0; i < values.length; i++) largest = Math.max(largest, Math.abs(values[i]));
  return man.tolerance_rel_diagonal * c.diagonal + man.tolerance_rel_coordinate * largest;
}
