// The space basis of each curve re-expressed as orthonormal columns over the curve's vertices, so that the
// GPU can sum knot x basis products in float32 without cancellation.
//
// For a curve c and coordinate w, the values at the curve's n vertices are B k, with B (n x 4) the four
// space functions at the vertices' u and k the four knot coefficients of a segment boundary. Fitted clips'
// B is ill-conditioned (its columns nearly dependent), so |B_j k_j| can exceed |B k| by 1e3 and more: summed
// in float32 that loses ~1e-5 of the diagonal. With B = Q R (Q orthonormal columns, R upper triangular,
// computed in float64 by Gram-Schmidt with reorthogonalisation) the values are Q (R k): every term of the
// sum is bounded by the norm of the values over the curve, and R k is a forward product (no inverse, so a
// rank-deficient B costs nothing).

import { vertexBasis } from './dynamic.js';

/** A column whose part outside the previous columns is below this fraction of its norm is dropped. */
const DEPENDENT = 1e-13;

/**
 * Orthonormal bases of a decoded dynamic clip: {q: Float32Array (V * 12): per vertex and coordinate the four
 * values of Q's row, r: Float64Array (C * 3 * 16): per curve and coordinate R row-major}. Columns of B that
 * lie (to DEPENDENT) in the span of the previous ones get a zero column in Q and a zero row in R.
 */
export function orthonormalBases(clip) {
  const { nVertices: V, nCurves: C, order, offsets } = clip;
  const B = vertexBasis(clip); // (V, 3, 4) float64
  const q = new Float32Array(V * 12);
  const r = new Float64Array(C * 48);
  let widest = 0;
  for (let c = 0; c < C; c++) widest = Math.max(widest, offsets[c + 1] - offsets[c]);
  const cols = new Float64Array(widest * 4); // Q's columns of one (curve, coordinate), column-major
  // offsets into one buffer, no subarray per column: fitted clips have 1e4 curves of a few vertices
  for (let c = 0; c < C; c++) {
    const first = offsets[c];
    const n = offsets[c + 1] - first;
    for (let w = 0; w < 3; w++) {
      const R = (c * 3 + w) * 16;
      for (let j = 0; j < 4; j++) {
        const col = j * n;
        for (let i = 0; i < n; i++) cols[col + i] = B[order[first + i] * 12 + w * 4 + j];
        const norm0 = Math.sqrt(dotAt(cols, col, col, n));
        for (let pass = 0; pass < 2; pass++) {
          // classical Gram-Schmidt, twice: orthogonal to working precision
          for (let i = 0; i < j; i++) {
            const qi = i * n;
            const d = dotAt(cols, qi, col, n);
            r[R + i * 4 + j] += d;
            for (let k = 0; k < n; k++) cols[col + k] -= d * cols[qi + k];
          }
        }
        const rest = Math.sqrt(dotAt(cols, col, col, n));
        if (rest > DEPENDENT * norm0 && rest > 0) {
          r[R + j * 4 + j] = rest;
          for (let k = 0; k < n; k++) cols[col + k] /= rest;
        } else {
          cols.fill(0, col, col + n);
        }
      }
      for (let i = 0; i < n; i++) {
        const o = order[first + i] * 12 + w * 4;
        for (let j = 0; j < 4; j++) q[o + j] = cols[j * n + i];
      }
    }
  }
  return { q, r };
}

/** The dot product of a[i..i+n) and a[j..j+n), summed in index order. */
function dotAt(a, i, j, n) {
  let s = 0;
  for (let k = 0; k < n; k++) s += a[i + k] * a[j + k];
  return s;
}
