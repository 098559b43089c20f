// The bone layer of format 1.1 (feature "bones", docs/format.md): decode the bone arrays of a dynamic-PDE
// coefficients part, evaluate the B rigid bone transforms at a time, and skin the rest pose with them
// (linear-blend skinning); the clip's curves add their residual on top of that skinned base.

import { ClipFormatError } from './container.js';
import { locate, timePair } from './basis.js';
import { naturalSplineTangents, rodrigues } from './dynamic.js';

/** The feature name of the bone layer in a part's `required` list. */
export const BONES_FEATURE = 'bones';
/** Channels per bone: rotation vector (3), then translation (3). */
export const BONE_CHANNELS = 6;
const MAX_INFLUENCES = 4;

/** A bone array checked for dtype and shape (ClipFormatError otherwise); floats must be finite. */
function boneArray(arrays, name, dtype, shape) {
  const a = arrays[name];
  if (!a) throw new ClipFormatError(`coefficients with bones have no '${name}' array`);
  if (a.dtype !== dtype) {
    throw new ClipFormatError(`coefficients array '${name}' has dtype ${a.dtype}, expected ${dtype}`);
  }
  if (a.shape.length !== shape.length || shape.some((n, i) => a.shape[i] !== n)) {
    throw new ClipFormatError(`coefficients array '${name}' has shape [${a.shape}], expected [${shape}]`);
  }
  if (dtype[1] === 'f' && !a.data.every(Number.isFinite)) {
    throw new ClipFormatError(`coefficients array '${name}' has non-finite values`);
  }
  return a.data;
}

/** A header count of the bone layer: an integer in lo..hi. */
function boneCount(header, key, lo, hi) {
  const n = header[key];
  if (!Number.isInteger(n) || n < lo || n > hi) {
    throw new ClipFormatError(`coefficients header '${key}' must be an integer in ${lo}..${hi}, got ${JSON.stringify(n ?? null)}`);
  }
  return n;
}

/** Whether a coefficients header declares the bone layer: exactly when its `required` lists "bones". */
export function hasBones(header) {
  return Array.isArray(header.required) && header.required.includes(BONES_FEATURE);
}

/**
 * The bone layer of a coefficients part (header ch, arrays ca) for V vertices, checked as docs/format.md
 * lists (knots: the curves' decoded knots, to tell whether they add a residual): {residual (false: every knot
 * is 0, the frame is the skinned base), nBones, influences, segmentT (Sb+1), pivot (B*3 float32), index (V*K), weight (V*K float64:
 * the stored K-1 and the implied last, rows summing to 1), timeModel (B*6), m (Sb*B*6), knots ((Sb+1) * B*6 float64 of the float32 knot values,
 * knot-major), tangents (same layout, natural-spline channels' tangents in float64, null without spline
 * channels)}. Plain typed arrays: a Web Worker can transfer them.
 */
export function decodeBones(ch, ca, V, motion, knots) {
  if (motion !== 'displacement') {
    throw new ClipFormatError(`bones need motion "displacement", this clip's is ${JSON.stringify(motion)}`);
  }
  const B = boneCount(ch, 'n_bones', 1, 65536); // bone_index is uint16
  const K = boneCount(ch, 'bone_influences', 1, MAX_INFLUENCES);
  const order = boneCount(ch, 'bone_knot_differences', 1, 2); // the bone tracks' own order of differences
  const segT = ca.bone_segment_t ? boneArray(ca, 'bone_segment_t', '<f8', [ca.bone_segment_t.shape[0]]) : null;
  if (segT === null) throw new ClipFormatError("coefficients with bones have no 'bone_segment_t' array");
  const Sb = segT.length - 1;
  let rising = Sb >= 1 && segT[0] === 0 && segT[Sb] === 1;
  for (let j = 1; j <= Sb && rising; j++) rising = segT[j] > segT[j - 1];
  if (!rising) throw new ClipFormatError('bone_segment_t must rise strictly from 0 to 1 with at least one segment');
  const pivot = boneArray(ca, 'bone_pivot', '<f4', [B, 3]);
  const index = boneArray(ca, 'bone_index', '<u2', [V, K]);
  for (let i = 0; i < index.length; i++) {
    if (index[i] >= B) throw new ClipFormatError(`bone_index holds bone ${index[i]}, the clip has ${B} bones`);
  }
  const bits = boneCount(ch, 'bone_weight_bits', 1, 16);
  const weight = implicitWeights(boneArray(ca, 'bone_weight', '<u2', [V, K - 1]), V, K, 2 ** bits - 1);
  const timeModel = boneArray(ca, 'bone_time_model', '<u1', [B, BONE_CHANNELS]);
  const m = boneArray(ca, 'bone_m', '<f4', [Sb, B, BONE_CHANNELS]);
  const n = B * BONE_CHANNELS;
  let spline = false;
  for (let i = 0; i < n; i++) {
    if (timeModel[i] > 1) throw new ClipFormatError(`bone_time_model must be 0 (paper) or 1 (natural spline), got ${timeModel[i]}`);
    spline ||= timeModel[i] === 1;
    for (let s = 0; s < Sb; s++) {
      const mu = m[s * n + i];
      if (mu <= -Math.PI) throw new ClipFormatError('bone trig time constants must be above -pi');
      if (timeModel[i] === 1 && mu !== 0) {
        throw new ClipFormatError('bone channels on the natural spline must have time constant 0 in every segment');
      }
    }
  }
  const step = boneArray(ca, 'bone_step', '<f4', [B, BONE_CHANNELS]);
  if (!step.every((h) => h > 0)) throw new ClipFormatError('bone_step must be positive');
  const values = boneKnots(boneArray(ca, 'bone_knots', '<u4', [B, BONE_CHANNELS, Sb + 1]), step, order, Sb + 1);
  const tangents = spline ? naturalSplineTangents(segT, values, n) : null;
  const residual = knots.some((x) => x !== 0);
  return { residual, nBones: B, influences: K, segmentT: segT, pivot, index, weight, timeModel, m, knots: values, tangents };
}

/**
 * Weights of V vertices x K influences from the stored K-1 per vertex (q, V*(K-1) uint16): the last is implied,
 * scale - sum of the others (refused when negative), and w = q / scale in float64 (scale = 2^bits - 1).
 */
function implicitWeights(q, V, K, scale) {
  const w = new Float64Array(V * K);
  for (let v = 0; v < V; v++) {
    let sum = 0;
    for (let k = 0; k < K - 1; k++) {
      const x = q[v * (K - 1) + k];
      sum += x;
      w[v * K + k] = x / scale;
    }
    if (sum > scale) {
      throw new ClipFormatError(`bone_weight row ${v} sums to ${sum}, above 2^bone_weight_bits - 1 = ${scale}`);
    }
    w[v * K + K - 1] = (scale - sum) / scale;
  }
  return w;
}

/**
 * Knot values of the bone channels from their zigzag differences z (B*6 tracks of n knots, order 1 or 2):
 * float32(p * h) per knot, as float64, knot-major ((n) x B*6: row j holds every channel's knot j).
 */
function boneKnots(z, step, order, n) {
  const channels = step.length;
  const out = new Float64Array(n * channels);
  for (let c = 0; c < channels; c++) {
    let first = 0;
    let p = 0;
    for (let j = 0; j < n; j++) {
      const code = z[c * n + j];
      const d = (code >>> 1) ^ -(code & 1);
      if (order === 1) p += d;
      else p += first += d;
      out[j * channels + c] = Math.fround(p * step[c]);
    }
  }
  if (!out.every(Number.isFinite)) throw new ClipFormatError('bone knots decode to non-finite values');
  return out;
}

/**
 * The distinct time constants of each bone segment's channels that are not on the spline: {index (S * n: the
 * channel's among its segment's), unique (their values, segment after segment), start (S + 1), widest}.
 */
function distinctConstants(m, n, S, timeModel) {
  const index = new Int32Array(S * n);
  const unique = [];
  const start = new Int32Array(S + 1);
  let widest = 1;
  for (let s = 0; s < S; s++) {
    const seen = new Map();
    for (let i = 0; i < n; i++) {
      if (timeModel[i] === 1) continue;
      const mu = m[s * n + i];
      if (!seen.has(mu)) {
        seen.set(mu, seen.size);
        unique.push(mu);
      }
      index[s * n + i] = seen.get(mu);
    }
    start[s + 1] = unique.length;
    widest = Math.max(widest, seen.size);
  }
  return { index, unique: Float64Array.from(unique), start, widest };
}

/**
 * The bone transforms of a decoded bone layer at a time: at(tw) fills rot (B*9, row-major R_b) and trans
 * (B*3, T_b) in float64 (docs/format.md: channel values by their time models, R_b by Rodrigues), and
 * affine (B*12: rows of x -> R_b (x - c_b) + c_b + T_b, i.e. [R_b | c_b + T_b - R_b c_b], for the GPU).
 */
export class BonePose {
  constructor(bones) {
    this.bones = bones;
    const B = bones.nBones;
    this.rot = new Float64Array(B * 9);
    this.trans = new Float64Array(B * 3);
    this.values = new Float64Array(B * BONE_CHANNELS);
    this.loc = [0, 0, 0];
    this.pair = [0, 0];
    this.tw = NaN;
    this.distinct = null; // distinctConstants(), made on first use
    this.phi0 = null;
    this.phi1 = null;
  }

  /** The transforms at wrapped (or clamped) clip time tw in [0, 1]; returns this. */
  at(tw) {
    if (tw === this.tw) return this;
    const { segmentT, timeModel, m, knots, tangents, nBones: B } = this.bones;
    const [s, tau] = locate(segmentT, tw, false, this.loc);
    const n = B * BONE_CHANNELS;
    const P0 = s * n;
    const P1 = (s + 1) * n;
    const delta = segmentT[s + 1] - segmentT[s];
    const omt = 1 - tau;
    const h00 = (1 + 2 * tau) * omt * omt;
    const h01 = tau * tau * (3 - 2 * tau);
    const h10 = tau * omt * omt;
    const h11 = tau * tau * (tau - 1);
    const v = this.values;
    // each distinct constant of the segment's channels once (a crowd poses every player each frame)
    const { index, unique, start } = (this.distinct ??= distinctConstants(m, n, segmentT.length - 1, timeModel));
    const phi0 = (this.phi0 ??= new Float64Array(this.distinct.widest));
    const phi1 = (this.phi1 ??= new Float64Array(this.distinct.widest));
    for (let k = 0, j = start[s]; j < start[s + 1]; k++, j++) {
      const pair = timePair(tau, unique[j], this.pair);
      phi0[k] = pair[0];
      phi1[k] = pair[1];
    }
    for (let i = 0; i < n; i++) {
      if (timeModel[i] === 1) {
        v[i] = h00 * knots[P0 + i] + h01 * knots[P1 + i] + delta * (h10 * tangents[P0 + i] + h11 * tangents[P1 + i]);
      } else {
        const k = index[s * n + i];
        v[i] = phi0[k] * knots[P0 + i] + phi1[k] * knots[P1 + i];
      }
    }
    for (let b = 0; b < B; b++) {
      const o = b * BONE_CHANNELS;
      rodrigues(v[o], v[o + 1], v[o + 2], this.rot, b * 9);
      this.trans[b * 3] = v[o + 3];
      this.trans[b * 3 + 1] = v[o + 4];
      this.trans[b * 3 + 2] = v[o + 5];
    }
    this.tw = tw;
    return this;
  }

  /** Rows [R_b | c_b + T_b - R_b c_b] of every bone (B*12 float64) into out; returns out. */
  affine(out = new Float64Array(this.bones.nBones * 12)) {
    const { rot, trans } = this;
    const c = this.bones.pivot;
    for (let b = 0; b < this.bones.nBones; b++) {
      const R = b * 9;
      for (let i = 0; i < 3; i++) {
        const r = R + i * 3;
        const o = b * 12 + i * 4;
        out[o] = rot[r];
        out[o + 1] = rot[r + 1];
        out[o + 2] = rot[r + 2];
        out[o + 3] = c[b * 3 + i] + trans[b * 3 + i] - (rot[r] * c[b * 3] + rot[r + 1] * c[b * 3 + 1] + rot[r + 2] * c[b * 3 + 2]);
      }
    }
    return out;
  }

  /**
   * The skinned position of vertex v (rest: V*3 float32) in float64 into out[o..o+2], influences in stored
   * order: acc += w * (R_b (rest - c_b) + c_b + T_b) (docs/format.md's order; round to float32 for the base).
   */
  skinVertex(rest, v, out, o = 0) {
    const { index, weight, pivot, influences: K } = this.bones;
    const { rot, trans } = this;
    const x = rest[v * 3];
    const y = rest[v * 3 + 1];
    const z = rest[v * 3 + 2];
    let a0 = 0;
    let a1 = 0;
    let a2 = 0;
    for (let k = 0, i = v * K; k < K; k++, i++) {
      const b = index[i];
      const w = weight[i];
      const R = b * 9;
      const c0 = pivot[b * 3];
      const c1 = pivot[b * 3 + 1];
      const c2 = pivot[b * 3 + 2];
      const d0 = x - c0;
      const d1 = y - c1;
      const d2 = z - c2;
      a0 += w * (rot[R] * d0 + rot[R + 1] * d1 + rot[R + 2] * d2 + c0 + trans[b * 3]);
      a1 += w * (rot[R + 3] * d0 + rot[R + 4] * d1 + rot[R + 5] * d2 + c1 + trans[b * 3 + 1]);
      a2 += w * (rot[R + 6] * d0 + rot[R + 7] * d1 + rot[R + 8] * d2 + c2 + trans[b * 3 + 2]);
    }
    out[o] = a0;
    out[o + 1] = a1;
    out[o + 2] = a2;
    return out;
  }

  /** The skinned base of every vertex (float32(acc), V*3) into out (a Float32Array rounds); returns out. */
  skin(rest, out) {
    const V = rest.length / 3;
    for (let v = 0; v < V; v++) this.skinVertex(rest, v, out, v * 3);
    return out;
  }
}
