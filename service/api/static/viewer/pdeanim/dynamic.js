// Decode and evaluate "dynamic-pde" clips (docs/format.md §3) on the CPU.

import { ClipFormatError, checkBounded, checkFormatVersion } from './container.js';
import { locate, rigidTimePair, spaceBasis, timePair } from './basis.js';
import { BonePose, decodeBones, hasBones } from './bones.js';

/** Time models of an item (`time_model`, docs/format.md §3.2): the paper's time pairs, the natural spline. */
export const TIME_PDE = 0;
export const TIME_SPLINE = 1;
const MOTIONS = ['displacement', 'absolute', 'rigid'];

function need(arrays, name, shape, part, dtype = null) {
  const a = arrays[name];
  if (!a) throw new ClipFormatError(`${part} part has no '${name}' array`);
  if (a.shape.length !== shape.length || shape.some((w, i) => w !== null && a.shape[i] !== w)) {
    throw new ClipFormatError(
      `${part} array '${name}' has shape [${a.shape}], expected [${shape.map((w) => w ?? 'any')}]`,
    );
  }
  if (dtype !== null && !dtype.includes(a.dtype)) {
    throw new ClipFormatError(`${part} array '${name}' has dtype ${a.dtype}, expected ${dtype.join(' or ')}`);
  }
  if (a.dtype[1] === 'f') {
    for (let i = 0; i < a.data.length; i++) {
      if (!Number.isFinite(a.data[i]))
        throw new ClipFormatError(`${part} array '${name}' has non-finite values`);
    }
  }
  return a;
}

function nondecreasing(a) {
  for (let i = 1; i < a.length; i++) if (!(a[i] >= a[i - 1])) return false;
  return true;
}

const U4 = ['<u4'];
const F4 = ['<f4'];
const F8 = ['<f8'];

/**
 * segment_t (S+1) float64, or, where it is not stored (a knot at every frame, docs/format.md §3.3), the frame
 * times normalised: (frame_times[s] - frame_times[0]) / (frame_times[F-1] - frame_times[0]).
 */
function segmentTimes(ca, S) {
  if (ca.segment_t !== undefined) return need(ca, 'segment_t', [S + 1], 'coefficients', F8).data;
  const ft = need(ca, 'frame_times', [null], 'coefficients', F8).data;
  if (ft.length !== S + 1 || !(ft[S] > ft[0])) {
    throw new ClipFormatError(
      'coefficients without segment_t need a knot at every frame (n_segments + 1 ' +
        'frame times) and a last frame time after the first',
    );
  }
  const span = ft[S] - ft[0];
  return Float64Array.from(ft, (x) => (x - ft[0]) / span);
}

/**
 * Undo zigzag-coded differences in place order: z (uint32, rows x cols row-major) becomes the running sums
 * along the rows of d = (z >>> 1) ^ -(z & 1), per column, as float64 (exact integers), then value(q, col).
 */
function undoZigzag(z, cols, value, out) {
  const rows = cols ? z.length / cols : 0;
  const sum = new Float64Array(cols);
  for (let r = 0, i = 0; r < rows; r++) {
    for (let c = 0; c < cols; c++, i++) {
      const q = z[i];
      sum[c] += (q >>> 1) ^ -(q & 1);
      out[i] = value(sum[c], c);
    }
  }
  return out;
}

function positiveStep(x, what) {
  if (typeof x !== 'number' || !(x > 0) || !Number.isFinite(x)) {
    throw new ClipFormatError(`topology ${what} must be a positive finite number, got ${JSON.stringify(x)}`);
  }
  return x;
}

function checkFinite(a, what) {
  for (let i = 0; i < a.length; i++) {
    if (!Number.isFinite(a[i])) throw new ClipFormatError(`${what} decode to non-finite values`);
  }
}

/**
 * The arrays of a topology part (docs/format.md §3.1): curve lengths, zigzag differences of order, faces in
 * curve-rank space, u and rest as integer codes in curve order (differences along the curves) times u_step /
 * rest_step.
 */
function topologyArrays(th, ta, V) {
  const lengths = need(ta, 'curve_lengths', [null], 'topology', U4).data;
  const C = lengths.length;
  const offsets = new Int32Array(C + 1);
  let total = 0;
  for (let c = 0; c < C; c++) {
    total += lengths[c];
    if (total > V) break;
    offsets[c + 1] = total;
  }
  if (total !== V) {
    throw new ClipFormatError('topology curves are invalid: curve_lengths must add up to n_vertices');
  }
  const zo = need(ta, 'order', [V], 'topology', U4).data;
  const order = new Int32Array(V);
  undoZigzag(zo, 1, (q) => (q >= 0 && q < V ? q : -1), order);
  if (order.includes(-1)) throw new ClipFormatError('topology order holds an index outside the vertices');
  const faces = decodeFaces(need(ta, 'faces', [null, 3], 'topology', U4).data, order);
  if (faces.includes(-1)) throw new ClipFormatError('topology faces index outside the vertices');
  const uStep = positiveStep(th.u_step, 'u_step');
  const restStep = positiveStep(th.rest_step, 'rest_step');
  const origin = th.rest_origin;
  if (!Array.isArray(origin) || origin.length !== 3 || !origin.every((x) => typeof x === 'number' && Number.isFinite(x))) {
    throw new ClipFormatError('topology rest_origin must be 3 finite numbers');
  }
  const zu = need(ta, 'u', [V, null], 'topology', U4);
  const cols = zu.shape[1];
  if (cols !== 1 && cols !== 3) {
    throw new ClipFormatError(`topology array 'u' must have 1 or 3 columns, got ${cols}`);
  }
  const uCurve = undoZigzag(zu.data, cols, (q) => Math.fround(q * uStep), new Float32Array(V * cols));
  const zr = need(ta, 'rest', [V, 3], 'topology', U4).data;
  const restCurve = undoZigzag(zr, 3, (q, w) => Math.fround(origin[w] + q * restStep), new Float32Array(V * 3));
  checkFinite(uCurve, 'topology u');
  checkFinite(restCurve, 'topology rest');
  checkBounded(restCurve, 'topology rest');
  return { order, offsets, faces, uCurve, restCurve, uColumns: cols };
}

/**
 * Triangles (T * 3 vertex indices, -1 for a rank outside the vertices) of face codes, which are in
 * curve-rank space (rank i = vertex order[i]): per row, column 0 is the zigzag difference of its first rank
 * from the previous row's, columns 1 and 2 the zigzag offsets of the other two ranks from the first.
 */
function decodeFaces(codes, order) {
  const V = order.length;
  const faces = new Int32Array(codes.length);
  let first = 0;
  for (let i = 0; i < codes.length; i += 3) {
    first += (codes[i] >>> 1) ^ -(codes[i] & 1);
    for (let j = 0; j < 3; j++) {
      const r = j === 0 ? first : first + ((codes[i + j] >>> 1) ^ -(codes[i + j] & 1));
      faces[i + j] = r >= 0 && r < V ? order[r] : -1;
    }
  }
  return faces;
}

/** Rows stored in curve order (row i belongs to vertex order[i]) moved to the original vertex order. */
function toVertexOrder(rows, cols, order) {
  const out = new Float32Array(rows.length);
  for (let i = 0; i < order.length; i++) {
    const v = order[i];
    for (let c = 0; c < cols; c++) out[v * cols + c] = rows[i * cols + c];
  }
  return out;
}

/**
 * Family codes and m >= 0 (S, C, 3) of a coefficients part: space kind per item, m signed (< 0: trig with
 * |m| < pi, > 0: exp, 0: linear).
 */
function familyOf(ca, S, C) {
  const kind = need(ca, 'space_kind', [C, 3], 'coefficients', ['<u1']).data;
  const signed = need(ca, 'm', [S, C, 3], 'coefficients', ['<f4']).data;
  const family = new Uint8Array(signed.length);
  const m = new Float32Array(signed.length);
  for (let i = 0; i < signed.length; i++) {
    const k = kind[i % (C * 3)];
    if (k > 1) throw new ClipFormatError('space kinds must be 0 or 1');
    if (signed[i] <= -Math.PI) throw new ClipFormatError('trig time constants must be above -pi');
    family[i] = k + (signed[i] < 0 ? 2 : 0);
    m[i] = Math.abs(signed[i]);
  }
  return { family, m };
}

/** Tracks decoded together (their integers, weights and sums stay in cache: a block, not every track). */
const KNOT_BLOCK = 1024;

/**
 * knot_step (C, 3), or (W, C, 3) with knot_windows, and the zigzag codes z (C, 3, 4, S+1) of the `knots` time
 * tracks with their difference order (1 or 2, docs/format.md §3.3), checked.
 */
function knotTracks(ch, ca, S, C) {
  const windows = knotWindows(ca, S);
  const W = windows === null ? 0 : windows.length - 1;
  const steps = need(ca, 'knot_step', W ? [W, C, 3] : [C, 3], 'coefficients', ['<f4']).data;
  if (steps.some((x) => !(x > 0))) throw new ClipFormatError('coefficients knot steps must be positive');
  const order = ch.knot_differences;
  if (order !== 1 && order !== 2) {
    throw new ClipFormatError(`coefficients knot_differences must be 1 or 2, got ${JSON.stringify(order)}`);
  }
  const z = need(ca, 'knots', [C, 3, 4, S + 1], 'coefficients', U4).data;
  return { steps, z, order, windows };
}

/**
 * The integers of tracks t0 .. t0+nb-1 (running sums, one or two, of the zigzag differences z along time)
 * into q (float64, exact integers), knot-major: q[s * nb + k] for track t0 + k.
 */
function trackIntegers(z, order, n, t0, nb, q) {
  for (let k = 0; k < nb; k++) {
    let first = 0;
    let sum = 0;
    for (let s = 0, i = (t0 + k) * n; s < n; s++, i++) {
      const code = z[i];
      const d = (code >>> 1) ^ -(code & 1);
      if (order === 1) sum += d;
      else sum += first += d;
      q[s * nb + k] = sum;
    }
  }
  return q;
}

/**
 * The optional knot_windows (W+1,) uint32 (docs/format.md §3.4): the first knot of each window, then S+1,
 * strictly increasing from 0; null when absent.
 */
function knotWindows(ca, S) {
  if (ca.knot_windows === undefined) return null;
  const bounds = need(ca, 'knot_windows', [null], 'coefficients', U4).data;
  const n = bounds.length;
  let rising = n >= 2 && bounds[0] === 0 && bounds[n - 1] === S + 1;
  for (let i = 1; i < n && rising; i++) rising = bounds[i] > bounds[i - 1];
  if (!rising) throw new ClipFormatError(`coefficients knot_windows must rise strictly from 0 to ${S + 1}`);
  return bounds;
}

/**
 * Knots (S+1, C, 3, 4) float32 (docs/format.md §3.3-3.4). With knot_rank r = 0: float32(q * h) of the
 * `knots` tracks (h = knot_step[c, w], or knot_step[i, c, w] in window i of knot_windows). With r >= 1: integer weights q (r, C, 3, 4), stored as plain zigzag
 * codes (not differences), on r shared time tracks knot_basis (r, S+1), plus residual integers p from the
 * `knots` tracks: float32(sum over j = 0..r-1, in this order from 0, of (q[j, c, w, k] * h) *
 * knot_basis[j, s], then + p[c, w, k, s] * h), every product and sum an IEEE double (no fused multiply-add:
 * bit for bit the knots of every other reader).
 */
function decodeKnots(ch, ca, S, C, maxRank = S + 1) {
  const r = ch.knot_rank;
  if (!Number.isInteger(r) || r < 0 || r > maxRank) {
    throw new ClipFormatError(`coefficients knot_rank must be an integer in 0..${maxRank}, got ${JSON.stringify(r)}`);
  }
  const { steps, z, order, windows } = knotTracks(ch, ca, S, C);
  const n = S + 1;
  const T = C * 12; // one track per curve, coordinate and coefficient
  const knots = new Float32Array(n * T);
  let weightCodes = null;
  let basis = null;
  if (r === 0) {
    for (const name of ['knot_weights', 'knot_basis']) {
      if (ca[name] !== undefined) {
        throw new ClipFormatError(`coefficients with knot_rank 0 must not hold '${name}'`);
      }
    }
  } else {
    if (windows !== null) throw new ClipFormatError('knot steps per window (knot_windows) need knot_rank 0');
    weightCodes = need(ca, 'knot_weights', [r, C, 3, 4], 'coefficients', U4).data;
    basis = need(ca, 'knot_basis', [r, S + 1], 'coefficients', ['<f4']).data;
  }
  // a block of tracks at a time: its integers, weights and sums stay in cache (the same operations, in the
  // same order, per knot as a pass over every track)
  const B = Math.min(KNOT_BLOCK, T);
  const q = new Float64Array(n * B);
  const weights = r ? new Float64Array(r * B) : null; // q * h of the block
  const acc = r ? new Float64Array(B) : null;
  for (let t0 = 0; t0 < T; t0 += B) {
    const nb = Math.min(B, T - t0);
    trackIntegers(z, order, n, t0, nb, q);
    if (r === 0) {
      for (let s = 0, win = 0; s < n; s++) {
        if (windows !== null && s === windows[win + 1]) win++;
        const h = win * (T >> 2); // this knot's window of steps (one window without knot_windows)
        for (let k = 0, o = s * T + t0; k < nb; k++, o++) knots[o] = Math.fround(q[s * nb + k] * steps[h + ((t0 + k) >> 2)]);
      }
      continue;
    }
    for (let j = 0; j < r; j++) {
      for (let k = 0; k < nb; k++) {
        const c = weightCodes[j * T + t0 + k];
        weights[j * nb + k] = ((c >>> 1) ^ -(c & 1)) * steps[(t0 + k) >> 2];
      }
    }
    for (let s = 0; s < n; s++) {
      acc.fill(0, 0, nb);
      for (let j = 0; j < r; j++) {
        const b = basis[j * n + s];
        for (let k = 0, o = j * nb; k < nb; k++, o++) acc[k] += weights[o] * b;
      }
      for (let k = 0, o = s * T + t0; k < nb; k++, o++) {
        knots[o] = Math.fround(acc[k] + q[s * nb + k] * steps[(t0 + k) >> 2]);
      }
    }
  }
  checkFinite(knots, 'coefficients knots');
  checkBounded(knots, 'coefficients knots');
  return knots;
}

/**
 * The `time_model` (C, 3) of a coefficients part (docs/format.md §3.2, §3.5): uint8, 1 where the item is on
 * the natural spline in every segment (its constants must then be 0), 0 where it uses the paper's time pairs.
 */
function timeModelOf(ca, C, m, S, segT) {
  const model = need(ca, 'time_model', [C, 3], 'coefficients', ['<u1']).data;
  let spline = false;
  for (let i = 0; i < model.length; i++) {
    if (model[i] > TIME_SPLINE) {
      throw new ClipFormatError(`coefficients time_model must be 0 (paper) or 1 (natural spline), got ${model[i]}`);
    }
    if (model[i] === TIME_SPLINE) {
      spline = true;
      for (let s = 0; s < S; s++) {
        if (m[s * C * 3 + i] !== 0) {
          throw new ClipFormatError('items on the natural spline must have time constant 0 in every segment');
        }
      }
    }
  }
  if (spline) {
    // the spline's tangents divide by every segment's length (docs/format.md §3.5)
    for (let j = 1; j <= S; j++) {
      if (!(segT[j] > segT[j - 1])) {
        throw new ClipFormatError(
          `natural-spline items need strictly increasing segment times (segment ${j - 1} has length 0)`,
        );
      }
    }
  }
  return spline ? model : null;
}

/** A header count: a JSON integer >= 0 (not a string, a boolean or a float), else ClipFormatError. */
function count(header, key, part) {
  const value = header[key];
  if (!Number.isInteger(value) || value < 0) {
    throw new ClipFormatError(
      `${part} header field '${key}' must be a non-negative integer, got ${JSON.stringify(value ?? null)}`,
    );
  }
  return value;
}

/** Per vertex its curve (V) from the curves' order and offsets; order must be a permutation of 0..V-1. */
function curveOfVertices(order, offsets, V) {
  const curveOf = new Int32Array(V).fill(-1);
  for (let c = 0; c + 1 < offsets.length; c++) {
    for (let i = offsets[c]; i < offsets[c + 1]; i++) {
      const v = order[i];
      if (v < 0 || v >= V || curveOf[v] !== -1) {
        throw new ClipFormatError('topology curves are invalid: order must be a permutation of the vertices');
      }
      curveOf[v] = c;
    }
  }
  return curveOf;
}

/** The rigid tracks of a rigid clip's coefficients part (docs/format.md §3.7): boundaries, centre, knots, mu. */
function rigidTracks(ca, C) {
  const rs = need(ca, 'rigid_segment_t', [null], 'coefficients', F8).data;
  const Sr = rs.length - 1;
  if (Sr < 1 || !nondecreasing(rs)) {
    throw new ClipFormatError('rigid segment boundaries must be non-decreasing with at least one segment');
  }
  const rigid = { segmentT: rs, centre: need(ca, 'rigid_centre', [C, 3], 'coefficients', F4).data };
  checkBounded(rigid.centre, 'rigid centres');
  for (const name of ['rot', 'trans']) {
    rigid[`${name}Knots`] = need(ca, `rigid_${name}_knots`, [Sr + 1, C, 3], 'coefficients', F4).data;
    checkBounded(rigid[`${name}Knots`], `rigid_${name}_knots`);
    const mu = need(ca, `rigid_${name}_mu`, [Sr, C], 'coefficients', F4).data;
    if (mu.some((x) => x <= -Math.PI)) throw new ClipFormatError('rigid trig time constants must be above -pi');
    rigid[`${name}Mu`] = mu;
  }
  return rigid;
}

/** The coefficients header's motion mode, one of MOTIONS. */
function motionOf(ch) {
  const motion = String(ch.motion);
  if (!MOTIONS.includes(motion)) throw new ClipFormatError(`unknown motion mode ${JSON.stringify(ch.motion)}`);
  return motion;
}

/** Validate and decode the topology and coefficients containers of a dynamic-PDE clip (format 1.x). */
export function decodeDynamic(topo, coef) {
  const th = topo.header;
  const ch = coef.header;
  checkFormatVersion(th, 'topology');
  checkFormatVersion(ch, 'coefficients');
  const V = count(th, 'n_vertices', 'topology');
  const ta = topo.arrays;
  const ca = coef.arrays;
  const t = topologyArrays(th, ta, V);
  const { order, offsets, faces, uColumns } = t;
  const C = offsets.length - 1;
  if (C < 0 || offsets[0] !== 0 || offsets[C] !== V || !nondecreasing(offsets)) {
    throw new ClipFormatError('topology curves are invalid: offsets must run from 0 to n_vertices');
  }
  const curveOf = curveOfVertices(order, offsets, V);
  const u = toVertexOrder(t.uCurve, uColumns, order);
  for (let i = 0; i < u.length; i++) {
    if (!(u[i] >= 0 && u[i] <= 1)) throw new ClipFormatError('topology curve parameters u must lie in [0, 1]');
  }
  const rest = toVertexOrder(t.restCurve, 3, order);

  const S = count(ch, 'n_segments', 'coefficients');
  const segT = segmentTimes(ca, S);
  if (!(S >= 1) || !nondecreasing(segT)) {
    throw new ClipFormatError('segment boundaries must be non-decreasing with at least one segment');
  }
  const { family, m } = familyOf(ca, S, C);
  const timeModel = timeModelOf(ca, C, m, S, segT);
  const motion = motionOf(ch);
  const D = need(ca, 'D', [C, 3], 'coefficients', F4).data;
  const knots = decodeKnots(ch, ca, S, C);
  const frameTimes = need(ca, 'frame_times', [null], 'coefficients', F8).data;
  const rigid = motion === 'rigid' ? rigidTracks(ca, C) : null;
  return {
    kind: 'dynamic-pde',
    nVertices: V,
    nCurves: C,
    nSegments: S,
    faces,
    rest,
    order,
    offsets,
    curveOf,
    u,
    uColumns,
    paramMode: String(th.param_mode ?? 'chord'),
    segmentT: segT,
    frameTimes,
    family,
    m,
    D,
    knots,
    timeModel,
    motion,
    looping: Boolean(ch.looping),
    rigid,
    bones: hasBones(ch) ? decodeBones(ch, ca, V, motion, knots) : null,
    header: ch,
    topologyHeader: th,
  };
}

/** The decoding steps a streamable clip's head and windows share with whole clips (streamformat.js). */
export const parts = {
  need,
  count,
  topologyArrays,
  curveOfVertices,
  toVertexOrder,
  nondecreasing,
  familyOf,
  timeModelOf,
  decodeKnots,
  rigidTracks,
  motionOf,
  checkFinite,
};

/** Per-vertex space basis (V, 3, 4) float64 of a decoded dynamic clip (t-independent). */
export function vertexBasis(clip) {
  const { nVertices: V, curveOf, u, uColumns, D, family } = clip;
  const B = new Float64Array(V * 12);
  for (let v = 0; v < V; v++) {
    const c = curveOf[v];
    for (let w = 0; w < 3; w++) {
      const uu = u[uColumns === 1 ? v : v * 3 + w];
      spaceBasis(uu, D[c * 3 + w], family[c * 3 + w] % 2, B, v * 12 + w * 4);
    }
  }
  return B;
}

/** The vertex positions before motion ("base"): rest, zeros, or rest - centre (float32, as in Python). */
export function vertexBase(clip) {
  const { nVertices: V, rest, motion, rigid, curveOf } = clip;
  const base = new Float32Array(V * 3);
  if (motion === 'displacement') base.set(rest);
  else if (motion === 'rigid') {
    for (let v = 0; v < V; v++) {
      const c = curveOf[v];
      for (let w = 0; w < 3; w++) base[v * 3 + w] = rest[v * 3 + w] - rigid.centre[c * 3 + w];
    }
  }
  return base;
}

/** Rodrigues rotation of vector r (3 values at r[ro]) into the 9 values of R at out[o] (row-major). */
export function rodrigues(rx, ry, rz, out, o = 0) {
  const th = Math.sqrt(rx * rx + ry * ry + rz * rz);
  const th2 = th * th; // the square of the rounded norm, as the reference evaluator (numpy th**2)
  let a;
  let b;
  if (th < 1e-4) {
    a = 1 - th2 / 6;
    b = 0.5 - th2 / 24;
  } else {
    a = Math.sin(th) / th;
    b = (1 - Math.cos(th)) / th2;
  }
  // K = [[0, -rz, ry], [rz, 0, -rx], [-ry, rx, 0]]; R = I + a K + b K^2
  out[o] = 1 + b * (-rz * rz - ry * ry);
  out[o + 1] = -a * rz + b * (rx * ry);
  out[o + 2] = a * ry + b * (rx * rz);
  out[o + 3] = a * rz + b * (rx * ry);
  out[o + 4] = 1 + b * (-rz * rz - rx * rx);
  out[o + 5] = -a * rx + b * (ry * rz);
  out[o + 6] = -a * ry + b * (rx * rz);
  out[o + 7] = a * rx + b * (ry * rz);
  out[o + 8] = 1 + b * (-ry * ry - rx * rx);
  return out;
}

/** Values per column block of naturalSplineTangents (bounds its float64 scratch to 8 MiB). */
const SPLINE_BLOCK = 1 << 20;

/**
 * The knot tangents of the natural cubic spline (docs/format.md §3.5) through per-knot
 * data values ((S+1) x cols, row-major: row j holds every column's value at knot j, e.g. the per-vertex knot
 * fields P_j or the knot coefficients) over the boundaries segmentT (S+1, strictly increasing), into out (the
 * same layout; a Float32Array rounds the tangents to float32). Solves, per column and in float64, the
 * tridiagonal system
 *
 *   2 T_0 + T_1 = 3 d_0,
 *   Δ_j T_j-1 + 2 (Δ_j-1 + Δ_j) T_j + Δ_j-1 T_j+1 = 3 (Δ_j d_j-1 + Δ_j-1 d_j)   (j = 1..S-1),
 *   T_S-1 + 2 T_S = 3 d_S-1,
 *
 * with Δ_j = t_j+1 - t_j and d_j = (P_j+1 - P_j) / Δ_j, by the Thomas algorithm (no pivoting: the system is
 * strictly diagonally dominant). Its matrix depends on segmentT only: the forward elimination's pivots are
 * computed once and applied to all columns together (in blocks of columns, to bound the scratch memory).
 */
export function naturalSplineTangents(segmentT, values, cols, out = new Float64Array(values.length)) {
  const S = segmentT.length - 1;
  const n = S + 1;
  if (!(S >= 1) || values.length !== n * cols || out.length < n * cols) {
    throw new RangeError(`natural spline tangents need (S+1) x cols = ${n} x ${cols} values, S >= 1`);
  }
  const delta = new Float64Array(S);
  for (let j = 0; j < S; j++) delta[j] = segmentT[j + 1] - segmentT[j];
  // row j: sub[j] T_j-1 + diagonal T_j + upper T_j+1; after elimination the pivot piv[j] of T_j and
  // upper[j] = super-diagonal / piv[j]
  const sub = new Float64Array(n);
  const piv = new Float64Array(n);
  const upper = new Float64Array(n);
  piv[0] = 2;
  upper[0] = 1 / 2;
  for (let j = 1; j < S; j++) {
    sub[j] = delta[j];
    piv[j] = 2 * (delta[j - 1] + delta[j]) - delta[j] * upper[j - 1];
    upper[j] = delta[j - 1] / piv[j];
  }
  sub[S] = 1;
  piv[S] = 2 - upper[S - 1];
  const block = Math.max(1, Math.min(cols, Math.floor(SPLINE_BLOCK / n)));
  const y = new Float64Array(n * block); // the eliminated right-hand sides, then the tangents
  for (let c0 = 0; c0 < cols; c0 += block) {
    const nc = Math.min(block, cols - c0);
    for (let j = 0; j <= S; j++) {
      const yo = j * block;
      const prev = yo - block;
      const vo = j * cols + c0; // value at knot j of the block's first column
      for (let k = 0; k < nc; k++) {
        const p = values[vo + k];
        let rhs;
        if (j === 0) rhs = 3 * ((values[vo + cols + k] - p) / delta[0]);
        else if (j === S) rhs = 3 * ((p - values[vo - cols + k]) / delta[S - 1]);
        else {
          const dl = (p - values[vo - cols + k]) / delta[j - 1];
          const dr = (values[vo + cols + k] - p) / delta[j];
          rhs = 3 * (delta[j] * dl + delta[j - 1] * dr);
        }
        y[yo + k] = j === 0 ? rhs / piv[0] : (rhs - sub[j] * y[prev + k]) / piv[j];
      }
    }
    for (let k = 0; k < nc; k++) out[S * cols + c0 + k] = y[S * block + k];
    for (let j = S - 1; j >= 0; j--) {
      const yo = j * block;
      const vo = j * cols + c0;
      for (let k = 0; k < nc; k++) {
        const tj = y[yo + k] - upper[j] * y[yo + block + k];
        y[yo + k] = tj;
        out[vo + k] = tj;
      }
    }
  }
  return out;
}

/**
 * The knot tangents of the cubic spline through values ((S+1) x cols) at segmentT with known end tangents
 * (first, last: cols float64 values each, or null for that end's natural condition; docs/format.md §3.10): the
 * natural spline's system of naturalSplineTangents with a known end's row replaced by T = value (diagonal 1,
 * off-diagonal 0), solved by the Thomas algorithm in float64 in the reference reader's order. Both null:
 * naturalSplineTangents. out as there.
 */
export function clampedSplineTangents(segmentT, values, cols, first, last, out = new Float64Array(values.length)) {
  if (first === null && last === null) return naturalSplineTangents(segmentT, values, cols, out);
  const S = segmentT.length - 1;
  if (!(S >= 1) || values.length !== (S + 1) * cols) {
    throw new RangeError(`spline tangents need (S+1) x cols = ${S + 1} x ${cols} values, S >= 1`);
  }
  const dx = new Float64Array(S);
  for (let j = 0; j < S; j++) dx[j] = segmentT[j + 1] - segmentT[j];
  const lower = new Float64Array(S + 1); // coefficient of T_j-1 in row j
  const diag = new Float64Array(S + 1);
  const upper = new Float64Array(S + 1); // coefficient of T_j+1
  diag[0] = 2;
  upper[0] = 1;
  for (let j = 1; j < S; j++) {
    lower[j] = dx[j];
    diag[j] = 2 * (dx[j - 1] + dx[j]);
    upper[j] = dx[j - 1];
  }
  lower[S] = 1;
  diag[S] = 2;
  if (first !== null) [diag[0], upper[0]] = [1, 0];
  if (last !== null) [diag[S], lower[S]] = [1, 0];
  const c = new Float64Array(S + 1);
  const piv = new Float64Array(S + 1);
  c[0] = upper[0] / diag[0];
  piv[0] = diag[0];
  for (let j = 1; j <= S; j++) {
    piv[j] = diag[j] - lower[j] * c[j - 1];
    c[j] = upper[j] / piv[j];
  }
  const y = new Float64Array(S + 1);
  for (let k = 0; k < cols; k++) {
    const d = (j) => (values[(j + 1) * cols + k] - values[j * cols + k]) / dx[j];
    for (let j = 0; j <= S; j++) {
      let rhs;
      if (j === 0) rhs = first !== null ? first[k] : 3 * d(0);
      else if (j === S) rhs = last !== null ? last[k] : 3 * d(S - 1);
      else rhs = 3 * (dx[j] * d(j - 1) + dx[j - 1] * d(j));
      if (j === 0) y[0] = rhs / diag[0];
      else y[j] = (rhs - lower[j] * y[j - 1]) / piv[j];
    }
    out[S * cols + k] = y[S];
    for (let j = S - 1; j >= 0; j--) {
      y[j] -= c[j] * y[j + 1];
      out[j * cols + k] = y[j];
    }
  }
  return out;
}

/**
 * The known end tangent fields (float64, V * 3: sum over k of the end's tangent coefficients times S_k(u),
 * in the order of the knot fields) of a streamable clip's window (§3.10), or null for a natural end.
 */
function endTangentField(clip, ends) {
  if (ends === null) return null;
  const { nVertices: V, curveOf } = clip;
  const B = vertexBasis(clip);
  const out = new Float64Array(V * 3);
  for (let v = 0; v < V; v++) {
    const kc = curveOf[v] * 12;
    for (let w = 0; w < 3; w++) {
      const b = v * 12 + w * 4;
      const k = kc + w * 4;
      out[v * 3 + w] = B[b] * ends[k] + B[b + 1] * ends[k + 1] + B[b + 2] * ends[k + 2] + B[b + 3] * ends[k + 3];
    }
  }
  return out;
}

/**
 * The float64 weights of the natural-spline cubic (docs/format.md §3.5) in segment s of boundaries segmentT at
 * local time tau, on T_s, P_s, P_s+1 and T_s+1 in that order (Δ h10, h00, h01, Δ h11 with
 * Δ = t_s+1 - t_s), into out[o..o+3].
 */
export function splineWeights(segmentT, s, tau, out, o = 0) {
  const delta = segmentT[s + 1] - segmentT[s];
  const omt = 1 - tau;
  out[o] = delta * (tau * omt * omt);
  out[o + 1] = (1 + 2 * tau) * omt * omt;
  out[o + 2] = tau * tau * (3 - 2 * tau);
  out[o + 3] = delta * (tau * tau * (tau - 1));
  return out;
}

/**
 * Normalised clip time t checked against the clip: looping clips take any finite t (they wrap with period
 * 1), others t in [0, 1] only (as `pdeanim frame --t` and GET /v1/clips/{id}/frame, which refuse the rest).
 * Throws RangeError; returns t.
 */
export function checkTime(t, looping) {
  if (!Number.isFinite(t)) throw new RangeError(`clip time must be a finite number, got ${t}`);
  if (!looping && !(t >= 0 && t <= 1)) {
    throw new RangeError(`clip time t must lie in [0, 1] for this clip (it does not loop), got ${t}`);
  }
  return t;
}

/**
 * Rigid clips: turn the values before the rigid motion (V * 3, read as float32, in place in out) by each
 * vertex's curve rotation rot (C * 9, row-major) and add its centre trans (C * 3).
 */
function applyRigid(out, rot, trans, curveOf) {
  const f = Math.fround;
  for (let v = 0, i = 0; v < curveOf.length; v++, i += 3) {
    const x = f(out[i]);
    const y = f(out[i + 1]);
    const z = f(out[i + 2]);
    const c = curveOf[v];
    const r = c * 9;
    out[i] = rot[r] * x + rot[r + 1] * y + rot[r + 2] * z + trans[c * 3];
    out[i + 1] = rot[r + 3] * x + rot[r + 4] * y + rot[r + 5] * z + trans[c * 3 + 1];
    out[i + 2] = rot[r + 6] * x + rot[r + 7] * y + rot[r + 8] * z + trans[c * 3 + 2];
  }
  return out;
}

/**
 * Per knot the per-vertex contribution P[s] = knots_s . S(u) ((S+1) x V x 3 float32, like the Python
 * evaluator) of a decoded dynamic clip.
 */
function knotFields(clip) {
  const { nVertices: V, nCurves: C, nSegments: S, curveOf, knots } = clip;
  const B = vertexBasis(clip);
  const fields = new Float32Array((S + 1) * V * 3);
  for (let s = 0; s <= S; s++) {
    const off = s * V * 3;
    const ko = s * C * 12;
    for (let v = 0; v < V; v++) {
      const kc = ko + curveOf[v] * 12;
      for (let w = 0; w < 3; w++) {
        const b = v * 12 + w * 4;
        const k = kc + w * 4;
        fields[off + v * 3 + w] =
          B[b] * knots[k] + B[b + 1] * knots[k + 1] + B[b + 2] * knots[k + 2] + B[b + 3] * knots[k + 3];
      }
    }
  }
  return fields;
}

/**
 * The per-segment time constants of a dynamic clip, indexed so that a frame evaluates each distinct one once:
 * {mu (S * C * 3 signed constants), muUnique, muStart (S+1: segment s has muUnique[muStart[s]..muStart[s+1])),
 * muIndex (per segment and item, the index into them), widest (most distinct constants in a segment)}. Plain
 * typed arrays: a Web Worker can make them and transfer them.
 */
export function timeIndex(clip) {
  const { nCurves: C, nSegments: S, family, m } = clip;
  const mu = new Float64Array(S * C * 3); // signed time constants
  for (let i = 0; i < mu.length; i++) mu[i] = (family[i] >= 2 ? -1 : 1) * m[i];
  // per segment its distinct time constants (fitted clips have a few hundred at most, most items linear)
  const muIndex = new Int32Array(S * C * 3);
  const unique = [];
  const muStart = new Int32Array(S + 1);
  let widest = 1;
  for (let s = 0; s < S; s++) {
    const seen = new Map();
    let last = NaN;
    let lastK = -1;
    for (let i = s * C * 3; i < (s + 1) * C * 3; i++) {
      const x = mu[i];
      let k = x === last ? lastK : seen.get(x); // runs of one constant (most items are linear) skip the map
      if (k === undefined) {
        k = seen.size;
        seen.set(x, k);
        unique.push(x);
      }
      muIndex[i] = k;
      last = x;
      lastK = k;
    }
    muStart[s + 1] = unique.length;
    widest = Math.max(widest, seen.size);
  }
  return { mu, muIndex, muUnique: Float64Array.from(unique), muStart, widest };
}

/** The (curve, coordinate) item of each of a clip's V * 3 values: made once per curveOf array (windows share it). */
const ITEMS = new WeakMap();
function valueItems(clip) {
  let item = ITEMS.get(clip.curveOf);
  if (item === undefined) {
    const V = clip.nVertices;
    item = new Int32Array(V * 3);
    for (let v = 0; v < V; v++) for (let w = 0; w < 3; w++) item[v * 3 + w] = clip.curveOf[v] * 3 + w;
    ITEMS.set(clip.curveOf, item);
  }
  return item;
}

/**
 * CPU evaluator of a decoded dynamic-PDE clip. The per-segment time state (what the GPU path needs each
 * frame) is set up here; the per-vertex knot fields of the CPU evaluation on first use.
 */
export class DynamicEvaluator {
  /** prepared: timeIndex(clip) made elsewhere (a Web Worker builds it with the GPU tables), else made here. */
  constructor(clip, prepared = null) {
    this.clip = clip;
    const { nVertices: V, nCurves: C } = clip;
    this.nVertices = V;
    this._fields = null;
    this._tangentFields = null;
    this.item = valueItems(clip); // (curve, coordinate) item of each value (shared by a streaming clip's windows)
    const { mu, muIndex, muUnique, muStart, widest } = prepared ?? timeIndex(clip);
    Object.assign(this, { mu, muIndex, muUnique, muStart });
    this.uPhi0 = new Float64Array(widest); // the distinct pairs of the current segment
    this.uPhi1 = new Float64Array(widest);
    this.loc = [0, 0, 0]; // segment, tau, wrapped t of the last locate()
    this.rigidLoc = [0, 0, 0];
    // a streaming clip's windows share the shell's base (read only here; a bone clip makes its own below)
    this.base = clip.windowed && clip.base?.length === V * 3 ? clip.base : vertexBase(clip);
    this.phi0 = new Float64Array(C * 3);
    this.phi1 = new Float64Array(C * 3);
    // The natural-spline time model (docs/format.md §3.5): null unless some item is on it (every other
    // clip takes the plain path below). spline (C * 3) is 1 for the items on it, in every segment;
    // cubicWeights are the segment's four weights on T_s, P_s, P_s+1, T_s+1 (float32-rounded), the same for
    // all its spline items, with tangentFields ((S+1) x V x 3 float32, the layout of fields) the tangents
    // T_j of every knot, solved on first use
    this.spline = clip.timeModel ?? null;
    if (this.spline !== null) {
      this.cubicWeights = new Float64Array(4);
      this.weights = new Float64Array(C * 12); // per item, by prepare(): the four weights it applies
    }
    this.pair = new Float64Array(2);
    this.pair2 = new Float64Array(2);
    if (clip.rigid) {
      this.rot = new Float64Array(C * 9);
      this.trans = new Float64Array(C * 3);
    }
    // the bone layer (format 1.1): its transforms at the time of segmentState(); base is then the skinned
    // rest pose of the frame (evaluate() writes it), the curves adding their residual to it
    this.bones = clip.bones ? new BonePose(clip.bones) : null;
    if (this.bones) this.base = new Float32Array(V * 3);
  }

  /** Per knot the per-vertex contribution P[s] ((S+1) x V x 3 float32), computed on first use. */
  get fields() {
    if (this._fields === null) this._fields = knotFields(this.clip);
    return this._fields;
  }

  /**
   * Clips with spline items: the tangents T_j of every knot in the layout of fields, solved once on first use
   * from the float32 fields in float64 and rounded to float32 (as the reference evaluator); else null.
   */
  get tangentFields() {
    if (this._tangentFields === null && this.spline !== null) {
      const fields = this.fields;
      const out = new Float32Array(fields.length);
      // a streamable clip's window: its known end tangents (§3.10); else (both null) the natural spline
      const first = endTangentField(this.clip, this.clip.tangentFirst ?? null);
      const last = endTangentField(this.clip, this.clip.tangentLast ?? null);
      this._tangentFields = clampedSplineTangents(this.clip.segmentT, fields, this.nVertices * 3, first, last, out);
    }
    return this._tangentFields;
  }

  /**
   * The per-curve state at t (everything t changes before the per-vertex sums): fills this.phi0, this.phi1
   * (C * 3 time pairs of the segment), for rigid clips this.rot (C * 9) and this.trans (C * 3), and for
   * clips with spline items this.weights (C * 3 * 4: per item the four weights on T_s, P_s, P_s+1, T_s+1:
   * the spline's float32-rounded ones, or 0, phi0, phi1, 0); returns the segment index.
   */
  prepare(t) {
    const s = this.locate(t)[0];
    this.segmentState();
    const { phi0, phi1, uPhi0, uPhi1, muIndex } = this;
    const n = phi0.length;
    for (let i = 0, j = s * n; i < n; i++, j++) {
      const k = muIndex[j];
      phi0[i] = uPhi0[k];
      phi1[i] = uPhi1[k];
    }
    if (this.spline !== null) {
      const { spline, cubicWeights: cw, weights } = this;
      for (let i = 0; i < n; i++) {
        const cub = spline[i] === 1;
        weights[i * 4] = cub ? cw[0] : 0;
        weights[i * 4 + 1] = cub ? cw[1] : phi0[i];
        weights[i * 4 + 2] = cub ? cw[2] : phi1[i];
        weights[i * 4 + 3] = cub ? cw[3] : 0;
      }
    }
    return s;
  }

  /**
   * Segment, local time and wrapped time of t into this.loc (no allocation); returns this.loc. Throws
   * RangeError for a t the clip does not take (checkTime).
   */
  locate(t) {
    const clip = this.clip;
    return locate(clip.segmentT, checkTime(t, clip.looping), clip.looping, this.loc);
  }

  /**
   * The state of this.loc that does not depend on the item: the distinct time pairs of the segment
   * (uPhi0/uPhi1, indexed by muIndex[s * C * 3 + item]), for clips with spline items the spline's four
   * weights (cubicWeights: splineWeights, computed in float64 and rounded to float32 as the reference
   * evaluator does) and, for rigid clips, rot and trans (of the curves rigidCurves lists when given: a GPU
   * crowd evaluates the others' rigid motion in the shader; this.rigidLoc has the rigid segment and time).
   */
  segmentState(rigidCurves = null) {
    const s = this.loc[0];
    const tau = this.loc[1];
    const { pair, muUnique, uPhi0, uPhi1 } = this;
    for (let k = 0, j = this.muStart[s]; j < this.muStart[s + 1]; k++, j++) {
      timePair(tau, muUnique[j], pair);
      uPhi0[k] = pair[0];
      uPhi1[k] = pair[1];
    }
    if (this.spline !== null) {
      const cw = splineWeights(this.clip.segmentT, s, tau, this.cubicWeights);
      for (let i = 0; i < 4; i++) cw[i] = Math.fround(cw[i]);
    }
    if (this.clip.rigid) this._rigidAt(this.loc[2], rigidCurves);
    if (this.bones !== null) this.bones.at(this.loc[2]);
  }

  /** Positions (V, 3) at t into out (Float32Array of V * 3, original vertex order); returns out. */
  evaluate(t, out = new Float32Array(this.nVertices * 3)) {
    if (out.length < this.nVertices * 3) throw new RangeError(`output needs ${this.nVertices * 3} floats`);
    const clip = this.clip;
    const s = this.prepare(t);
    if (this.bones !== null) {
      this.bones.skin(clip.rest, this.base);
      // no residual: the skinned base is the frame (the knot fields are never made)
      if (!clip.bones.residual) {
        out.set(this.base);
        return out;
      }
    }
    if (this.spline !== null) this._valuesSpline(s, out);
    else this._values(s, out);
    return clip.rigid ? applyRigid(out, this.rot, this.trans, clip.curveOf) : out;
  }

  /**
   * The values of segment s before any rigid motion into out: base + phi0 P_s + phi1 P_s+1 per value, the
   * time part rounded to float32 first in rigid clips (as the reference evaluator).
   */
  _values(s, out) {
    const { phi0, phi1, item, base } = this;
    const N = this.nVertices * 3;
    const fields = this.fields;
    const P0 = fields.subarray(s * N, (s + 1) * N);
    const P1 = fields.subarray((s + 1) * N, (s + 2) * N);
    if (!this.clip.rigid) {
      for (let i = 0; i < N; i++) {
        const k = item[i];
        out[i] = base[i] + phi0[k] * P0[i] + phi1[k] * P1[i];
      }
      return out;
    }
    const f = Math.fround;
    for (let i = 0; i < N; i++) {
      const k = item[i];
      out[i] = f(base[i] + f(phi0[k] * P0[i] + phi1[k] * P1[i]));
    }
    return out;
  }

  /**
   * _values() of a clip with spline items: their values are ((w_0 T_s + w_1 P_s) + w_2 P_s+1) + w_3 T_s+1
   * + base (docs/format.md §3.5), every product and sum rounded to float32, as the reference evaluator; the
   * other items' as in _values().
   */
  _valuesSpline(s, out) {
    const clip = this.clip;
    const { phi0, phi1, item, base } = this;
    const N = this.nVertices * 3;
    const f = Math.fround;
    const fields = this.fields;
    const field = (j) => fields.subarray(j * N, (j + 1) * N);
    const tangent = (j) => this.tangentFields.subarray(j * N, (j + 1) * N);
    const PL = tangent(s);
    const P0 = field(s);
    const P1 = field(s + 1);
    const PH = tangent(s + 1);
    const [wl, ws, w1, wh] = this.cubicWeights;
    const spline = this.spline;
    const rigid = Boolean(clip.rigid);
    for (let i = 0; i < N; i++) {
      const k = item[i];
      if (spline[k] === 1) out[i] = base[i] + f(f(f(f(wl * PL[i]) + f(ws * P0[i])) + f(w1 * P1[i])) + f(wh * PH[i]));
      // rigid clips round the plain items' time part to float32 before adding the base
      else if (rigid) out[i] = base[i] + f(phi0[k] * P0[i] + phi1[k] * P1[i]);
      else out[i] = base[i] + phi0[k] * P0[i] + phi1[k] * P1[i];
    }
    return out;
  }

  /** Per-curve rotation (C, 3, 3) and centroid (C, 3) of the rigid tracks at wrapped time tw (curves: only those). */
  _rigidAt(tw, curves = null) {
    const rg = this.clip.rigid;
    const C = this.clip.nCurves;
    const rl = locate(rg.segmentT, tw, false, this.rigidLoc);
    const s = rl[0];
    const tau = rl[1];
    const pr = this.pair;
    const pt = this.pair2;
    const n = curves === null ? C : curves.length;
    for (let i = 0; i < n; i++) {
      const c = curves === null ? i : curves[i];
      rigidTimePair(tau, rg.rotMu[s * C + c], pr);
      rigidTimePair(tau, rg.transMu[s * C + c], pt);
      const k0 = (s * C + c) * 3;
      const k1 = ((s + 1) * C + c) * 3;
      const rk = rg.rotKnots;
      const tk = rg.transKnots;
      rodrigues(
        pr[0] * rk[k0] + pr[1] * rk[k1],
        pr[0] * rk[k0 + 1] + pr[1] * rk[k1 + 1],
        pr[0] * rk[k0 + 2] + pr[1] * rk[k1 + 2],
        this.rot,
        c * 9,
      );
      for (let w = 0; w < 3; w++) this.trans[c * 3 + w] = pt[0] * tk[k0 + w] + pt[1] * tk[k1 + w];
    }
  }
}
