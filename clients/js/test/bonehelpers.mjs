// Test helpers for the bone layer (format 1.1, feature "bones"): build bone clips from a 1.0 fixture by
// adding the bone arrays of docs/format.md (encoded here, independently of src/bones.js), and evaluate them
// naively in float64 straight from the spec as a reference.

import { decodeClip, decodeContainer, timePair } from '../src/index.js';
import { denseSplineTangents, edited, encodeContainer, fixtureParts, naiveEvaluate, naiveLocate } from './helpers.mjs';

/** The zigzag code of a signed integer d. */
function zigzag(d) {
  return d >= 0 ? 2 * d : -2 * d - 1;
}

/** Zigzag differences of order (1 or 2) of integers p (one track). */
export function zigzagDifferences(p, order) {
  let d = p.map((x, i) => x - (i ? p[i - 1] : 0));
  if (order === 2) d = d.map((x, i) => x - (i ? d[i - 1] : 0));
  return d.map(zigzag);
}

/** A small deterministic generator (LCG) of numbers in [0, 1). */
export function rng(seed) {
  let s = seed >>> 0;
  return () => {
    s = (Math.imul(s, 1664525) + 1013904223) >>> 0;
    return s / 2 ** 32;
  };
}

/**
 * The bone layer's header keys and arrays for V vertices with rest positions rest (V*3): B bones with pivots
 * spread over the rest pose's extent, K influences per vertex, Sb bone segments (non-uniform), channel time
 * models and constants mixed (spline, exp, trig, linear), knot integers on power-of-two steps giving turns up to
 * about `angle` radians and moves up to `move` of the extent.
 */
export function boneLayer(rest, { B = 3, K = 2, Sb = 4, order = 1, seed = 7, angle = 0.8, move = 0.2 } = {}) {
  const V = rest.length / 3;
  const rand = rng(seed);
  const lo = [0, 1, 2].map((w) => Math.min(...rest.filter((_, i) => i % 3 === w)));
  const hi = [0, 1, 2].map((w) => Math.max(...rest.filter((_, i) => i % 3 === w)));
  const extent = Math.max(...hi.map((h, w) => h - lo[w]));
  const pivot = new Float32Array(B * 3);
  for (let b = 0; b < B; b++) for (let w = 0; w < 3; w++) pivot[b * 3 + w] = lo[w] + ((b + 0.5) / B) * (hi[w] - lo[w]);
  const index = new Uint16Array(V * K);
  const weight = new Uint16Array(V * (K - 1)); // the last influence's weight is implied (docs/format.md §3.9)
  const bits = 12;
  const scale = 2 ** bits - 1;
  for (let v = 0; v < V; v++) {
    let left = scale;
    for (let k = 0; k < K; k++) {
      index[v * K + k] = (v + k * 2) % B;
      if (k === K - 1) break;
      weight[v * (K - 1) + k] = Math.floor(rand() * (left + 1) * (k === 0 ? 1 : 0.5));
      left -= weight[v * (K - 1) + k];
    }
  }
  const segT = Float64Array.from({ length: Sb + 1 }, (_, j) => (j === Sb ? 1 : (j / Sb) ** 1.3));
  const timeModel = new Uint8Array(B * 6);
  const m = new Float32Array(Sb * B * 6);
  const step = new Float32Array(B * 6);
  const knots = new Uint32Array(B * 6 * (Sb + 1));
  for (let i = 0; i < B * 6; i++) {
    timeModel[i] = i % 3 === 1 ? 1 : 0;
    const rot = i % 6 < 3;
    step[i] = rot ? 2 ** -10 : 2 ** -8 * 2 ** Math.round(Math.log2(extent));
    const scale = rot ? angle / 1.8 : move * extent;
    const p = Array.from({ length: Sb + 1 }, () => Math.round(((rand() * 2 - 1) * scale) / step[i]));
    knots.set(zigzagDifferences(p, order), i * (Sb + 1));
    for (let s = 0; s < Sb; s++) {
      const kind = (i + s) % 4;
      m[s * B * 6 + i] = timeModel[i] === 1 || kind === 0 ? 0 : kind === 1 ? 1.7 : kind === 2 ? -2.1 : 0.3;
    }
  }
  const header = {
    format_version: '1.1', required: ['bones'], n_bones: B, bone_influences: K, bone_knot_differences: order,
    bone_weight_bits: bits,
  };
  const arrays = {
    bone_segment_t: { dtype: '<f8', shape: [Sb + 1], data: segT },
    bone_pivot: { dtype: '<f4', shape: [B, 3], data: pivot },
    bone_index: { dtype: '<u2', shape: [V, K], data: index },
    bone_weight: { dtype: '<u2', shape: [V, K - 1], data: weight },
    bone_time_model: { dtype: '<u1', shape: [B, 6], data: timeModel },
    bone_m: { dtype: '<f4', shape: [Sb, B, 6], data: m },
    bone_step: { dtype: '<f4', shape: [B, 6], data: step },
    bone_knots: { dtype: '<u4', shape: [B, 6, Sb + 1], data: knots },
  };
  return { header, arrays };
}

/**
 * A coefficients part (bytes) with a bone layer added (options of boneLayer; residual false zeroes every
 * curve's knots, zeroCurve(c) true those of curve c).
 */
export function withBones(coefficients, rest, { residual = true, zeroCurve = null, ...options } = {}) {
  return edited(coefficients, ({ header, arrays }) => {
    const layer = boneLayer(rest, { order: 3 - header.knot_differences, ...options }); // not the curves' order
    Object.assign(header, layer.header);
    Object.assign(arrays, layer.arrays);
    if (!residual) {
      for (const name of ['knots', 'knot_weights']) {
        if (arrays[name]) arrays[name] = { ...arrays[name], data: new Uint32Array(arrays[name].data.length) };
      }
    }
    if (zeroCurve) {
      const C = header.n_curves;
      for (const name of ['knots', 'knot_weights']) {
        if (!arrays[name]) continue;
        const data = Uint32Array.from(arrays[name].data);
        // knots (C, 3, 4, S+1): a block per curve; knot_weights (r, C, 3, 4): 12 codes per rank and curve
        const block = name === 'knots' ? data.length / C : 12;
        for (let i = 0; i < data.length; i++) if (zeroCurve(Math.floor(i / block) % C)) data[i] = 0;
        arrays[name] = { ...arrays[name], data };
      }
    }
  });
}

/** The rest positions (V*3, original vertex order) of a fixture's parts, decoded by the library. */
export function restOf(parts) {
  return decodeClip(parts.topology, parts.coefficients).rest;
}

/**
 * A bone clip made from a 1.0 fixture case: {topology, coefficients, file} bytes (file: a 1.1 CLIP file whose
 * outer header requires "bones" too).
 */
export function boneClipParts(c, options = {}) {
  const parts = fixtureParts(c);
  const rest = restOf(parts);
  const coefficients = withBones(parts.coefficients, rest, options);
  const outer = { ...parts.header, format_version: '1.1', required: ['bones'] };
  delete outer.arrays;
  const file = encodeContainer(outer, {
    topology: { dtype: '<u1', shape: [parts.topology.length], data: Uint8Array.from(parts.topology) },
    coefficients: { dtype: '<u1', shape: [coefficients.length], data: coefficients },
  });
  return { topology: parts.topology, coefficients, file };
}

/** Rotation matrix (row-major, 9) of rotation vector r by the axis-angle formula (cos, sin, 1 - cos). */
function axisAngle(rx, ry, rz) {
  const th = Math.hypot(rx, ry, rz);
  if (th === 0) return [1, 0, 0, 0, 1, 0, 0, 0, 1];
  const [x, y, z] = [rx / th, ry / th, rz / th];
  const c = Math.cos(th);
  const s = Math.sin(th);
  const C = 1 - c;
  return [c + x * x * C, x * y * C - z * s, x * z * C + y * s, y * x * C + z * s, c + y * y * C, y * z * C - x * s,
    z * x * C - y * s, z * y * C + x * s, c + z * z * C];
}

/**
 * Positions (V*3 float64) of a decoded bone clip at t from docs/format.md in float64 throughout, from the raw
 * coefficients bytes (not the library's decoding of the bone arrays): skinned rest pose plus the residual.
 */
export function naiveBoneEvaluate(clip, coefficients, t) {
  const { header, arrays: a } = decodeContainer(coefficients.slice());
  const B = header.n_bones;
  const K = header.bone_influences;
  const segT = a.bone_segment_t.data;
  const Sb = segT.length - 1;
  const [, , tw] = naiveLocate(clip.segmentT, t, clip.looping);
  const [s, tau] = naiveLocate(segT, tw, false);
  const values = new Float64Array(B * 6);
  for (let i = 0; i < B * 6; i++) {
    const z = a.bone_knots.data.subarray(i * (Sb + 1), (i + 1) * (Sb + 1));
    let first = 0;
    let p = 0;
    const P = Array.from(z, (code) => {
      const d = code % 2 ? -(code + 1) / 2 : code / 2;
      p += header.bone_knot_differences === 1 ? d : (first += d);
      return Math.fround(p * a.bone_step.data[i]);
    });
    if (a.bone_time_model.data[i] === 1) {
      const T = denseSplineTangents(segT, P);
      const delta = segT[s + 1] - segT[s];
      const h = [(1 + 2 * tau) * (1 - tau) ** 2, tau * tau * (3 - 2 * tau), tau * (1 - tau) ** 2, tau * tau * (tau - 1)];
      values[i] = h[0] * P[s] + h[1] * P[s + 1] + delta * (h[2] * T[s] + h[3] * T[s + 1]);
    } else {
      const pair = timePair(tau, a.bone_m.data[s * B * 6 + i], [0, 0]);
      values[i] = pair[0] * P[s] + pair[1] * P[s + 1];
    }
  }
  const residual = naiveEvaluate(clip, t); // rest + the curves' value (displacement)
  const out = new Float64Array(clip.nVertices * 3);
  for (let v = 0; v < clip.nVertices; v++) {
    const scale = 2 ** header.bone_weight_bits - 1;
    let stored = 0;
    for (let k = 0; k < K - 1; k++) stored += a.bone_weight.data[v * (K - 1) + k];
    for (let k = 0; k < K; k++) {
      const b = a.bone_index.data[v * K + k];
      const w = (k === K - 1 ? scale - stored : a.bone_weight.data[v * (K - 1) + k]) / scale;
      const R = axisAngle(values[b * 6], values[b * 6 + 1], values[b * 6 + 2]);
      const c = a.bone_pivot.data.subarray(b * 3, b * 3 + 3);
      const d = [0, 1, 2].map((j) => clip.rest[v * 3 + j] - c[j]);
      for (let i = 0; i < 3; i++) {
        out[v * 3 + i] += w * (R[i * 3] * d[0] + R[i * 3 + 1] * d[1] + R[i * 3 + 2] * d[2] + c[i] + values[b * 6 + 3 + i]);
      }
    }
    for (let i = 0; i < 3; i++) out[v * 3 + i] += residual[v * 3 + i] - clip.rest[v * 3 + i];
  }
  return out;
}
