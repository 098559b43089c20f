// GPU evaluation data (no three.js import): float textures, per-vertex attributes and per-frame uniforms of a
// clip (docs/format.md has the math; this mirrors the CPU path). The GLSL is in glsl.js, the TSL in webgpu.js.

import { CyclicEvaluator } from './cyclic.js';
import { DynamicEvaluator, naturalSplineTangents } from './dynamic.js';
import { triangleFrame, triangleQuality } from './geometry.js';
import { orthonormalBases, orthonormalCoefficients } from './orthobasis.js';

export const TEXTURE_WIDTH = 4096;

/** The largest power of two <= width (texel addressing in the shader is then a shift and a mask). */
function pow2Width(width) {
  if (!(width >= 1)) throw new RangeError(`texture width must be >= 1, got ${width}`);
  return 2 ** Math.floor(Math.log2(width));
}

/** A float RGBA texture of n texels, rows of w (a power of two): {data (padded), width, height}. */
function texture(nTexels, width) {
  const h = Math.max(1, Math.ceil(nTexels / width));
  return { data: new Float32Array(width * h * 4), width, height: h };
}

/**
 * The data textures and constants of a decoded clip (independent of the mesh and of three.js; plain typed
 * arrays, so that a Web Worker can build them and transfer them): {kind, rigid, spline, nCurves, nVertices,
 * nSegments, width, weightTexels, curveTexels, textures: {vertex, knot, tangent?, curve}, maxHeight} (cyclic
 * clips: {kind, nVertices, width, textures: {vertex}, axis, bend, rotate, maxHeight}).
 *
 * Dynamic clips: per vertex 4 texels (curve, base xyz) and the row of each coordinate's orthonormal space
 * basis (orthobasis.js); per (knot, curve, coordinate) the knots in that basis; for clips with items on the
 * natural spline (docs/format.md §3.5: `spline` true) the tangents T_j of every knot's coefficients likewise
 * (the spline's tridiagonal solve once per clip); the `curve` texture is the per-frame table that
 * timeUniforms() rewrites: per curve the time pairs (phi0 xyz, phi1 xyz) of the current segment and, for
 * rigid clips, the rows of R with the centroid (R row i, c_i), all computed in float64 by the CPU evaluator's
 * own code. Clips with spline items carry four weights per item instead of the pair (texels w_0 xyz, w_1 xyz,
 * w_2 xyz, w_3 xyz: the weights of T_s, P_s, P_s+1, T_s+1, or 0, phi0, phi1, 0 for an item off the spline),
 * then the rigid rows.
 */
export function gpuTables(clip, { width = TEXTURE_WIDTH } = {}) {
  width = pow2Width(width);
  if (clip.kind === 'cyclic-spine') return cyclicTables(clip, width);
  const { nVertices: V, nCurves: C, nSegments: S, curveOf, knots, rigid } = clip;
  const spline = (clip.timeModel ?? null) !== null; // null unless some item is on the natural spline
  const base = new DynamicEvaluator(clip).base;
  const { q, r } = orthonormalBases(clip);
  const vertex = texture(V * 4, width); // per vertex: (curve, base xyz), basis x, basis y, basis z
  for (let v = 0; v < V; v++) {
    const o = v * 16;
    vertex.data[o] = curveOf[v];
    vertex.data.set(base.subarray(v * 3, v * 3 + 3), o + 1);
    vertex.data.set(q.subarray(v * 12, v * 12 + 12), o + 4);
  }
  const coefficients = orthonormalCoefficients(r, knots);
  const knot = texture((S + 1) * C * 3, width); // per (knot, curve, coordinate): 4 basis coefficients
  knot.data.set(coefficients);
  const textures = { vertex, knot };
  if (spline) {
    // natural-spline tangents of every knot's coefficients (linear: the same in either basis)
    const tangent = texture((S + 1) * C * 3, width);
    naturalSplineTangents(clip.segmentT, coefficients, C * 12, tangent.data);
    textures.tangent = tangent;
  }
  const weightTexels = spline ? 4 : 2;
  const curveTexels = weightTexels + (rigid ? 3 : 0);
  textures.curve = texture(C * curveTexels, width);
  return {
    kind: clip.kind,
    rigid: Boolean(rigid),
    spline,
    nCurves: C,
    nVertices: V,
    nSegments: S,
    weightTexels,
    width,
    curveTexels,
    textures,
    maxHeight: Math.max(...Object.values(textures).map((x) => x.height)),
  };
}

/**
 * The tables of gpuTables() with the clip and its CPU evaluator (whose per-segment time state fills the
 * per-curve table): what timeUniforms() and the shaders need. tables: gpuTables(clip) made elsewhere (in a
 * Web Worker), else made here; evaluator: the clip's, when the caller has one.
 */
export function gpuLayout(clip, { width = TEXTURE_WIDTH, tables = null, evaluator = null } = {}) {
  const t = tables ?? gpuTables(clip, { width });
  if (clip.kind === 'cyclic-spine') return { ...t, clip };
  return { ...t, clip, evaluator: evaluator ?? new DynamicEvaluator(clip), tableAt: [-1, NaN, NaN] };
}

/** Bytes of the data textures of gpuTables() (what the GPU holds for the clip, whatever the mesh). */
export function textureBytes(tables) {
  return Object.values(tables.textures).reduce((n, t) => n + t.data.byteLength, 0);
}

function cyclicTables(clip, width) {
  const ev = new CyclicEvaluator(clip);
  const V = clip.nVertices;
  const vertex = texture(V * 3, width); // per vertex: (rest xyz, ra), (dS, dC, gS, gC), (rl, 0, 0, 0)
  for (let v = 0; v < V; v++) {
    const o = v * 12;
    vertex.data.set(clip.rest.subarray(v * 3, v * 3 + 3), o);
    vertex.data[o + 3] = ev.ra[v];
    vertex.data[o + 4] = ev.dS[v];
    vertex.data[o + 5] = ev.dC[v];
    vertex.data[o + 6] = ev.gS[v];
    vertex.data[o + 7] = ev.gC[v];
    vertex.data[o + 8] = ev.rl[v];
  }
  return {
    kind: clip.kind,
    rigid: false,
    spline: false,
    nCurves: 0,
    nVertices: V,
    nSegments: 0,
    width,
    textures: { vertex },
    maxHeight: vertex.height,
    axis: ev.axis,
    bend: ev.bend,
    rotate: ev.rotate,
  };
}

/**
 * The state at t: returns the uniforms {seg, sw, cw} (segment of the dynamic clip; sin and cos of the swim
 * phase of a cyclic one) and `changed`: whether the per-curve table layout.textures.curve.data was rewritten
 * (dynamic clips; upload it only then). The table is left as it is when t maps to the same segment, local
 * time (and rigid time) as at the previous call; otherwise each distinct time constant of the segment is
 * evaluated once (fitted clips have a few hundred, most items are linear) and the C x 3 pairs are gathered.
 */
export function timeUniforms(layout, t) {
  if (!Number.isFinite(t)) throw new RangeError(`clip time must be a finite number, got ${t}`);
  const clip = layout.clip;
  if (clip.kind === 'cyclic-spine') {
    const wt = 2 * Math.PI * clip.swim.frequency * (t * clip.period);
    return { seg: 0, sw: Math.sin(wt), cw: Math.cos(wt), changed: true };
  }
  const ev = layout.evaluator;
  const loc = ev.locate(t);
  const seg = loc[0];
  const last = layout.tableAt ?? (layout.tableAt = [-1, NaN, NaN]);
  if (seg === last[0] && loc[1] === last[1] && (!layout.rigid || loc[2] === last[2])) {
    return { seg, sw: 0, cw: 0, changed: false };
  }
  last[0] = seg;
  last[1] = loc[1];
  last[2] = loc[2];
  ev.segmentState();
  const { uPhi0, uPhi1, muIndex } = ev;
  const d = layout.textures.curve.data;
  const K = layout.curveTexels * 4;
  const C = layout.nCurves;
  if (!layout.spline) {
    for (let c = 0, o = 0, j = seg * C * 3; c < C; c++, o += K, j += 3) {
      const kx = muIndex[j];
      const ky = muIndex[j + 1];
      const kz = muIndex[j + 2];
      d[o] = uPhi0[kx];
      d[o + 1] = uPhi0[ky];
      d[o + 2] = uPhi0[kz];
      d[o + 4] = uPhi1[kx];
      d[o + 5] = uPhi1[ky];
      d[o + 6] = uPhi1[kz];
    }
  } else {
    // four weights per item: the segment's spline weights (docs/format.md §3.5) or (0, phi0, phi1, 0)
    const { spline, cubicWeights: cw } = ev;
    for (let c = 0, o = 0, j = seg * C * 3; c < C; c++, o += K) {
      for (let w = 0; w < 3; w++, j++) {
        if (spline[c * 3 + w] === 1) {
          d[o + w] = cw[0];
          d[o + 4 + w] = cw[1];
          d[o + 8 + w] = cw[2];
          d[o + 12 + w] = cw[3];
        } else {
          const k = muIndex[j];
          d[o + w] = 0;
          d[o + 4 + w] = uPhi0[k];
          d[o + 8 + w] = uPhi1[k];
          d[o + 12 + w] = 0;
        }
      }
    }
  }
  if (layout.rigid) rigidRows(layout, ev, d);
  return { seg, sw: 0, cw: 0, changed: true };
}

/** The rigid rows of the per-curve table d (after the weights): (R row i, c_i) of each curve, from ev. */
function rigidRows(layout, ev, d) {
  const { rot, trans } = ev;
  const K = layout.curveTexels * 4;
  for (let c = 0, o = layout.weightTexels * 4; c < layout.nCurves; c++, o += K) {
    for (let i = 0; i < 3; i++) {
      d[o + i * 4] = rot[c * 9 + i * 3];
      d[o + 1 + i * 4] = rot[c * 9 + i * 3 + 1];
      d[o + 2 + i * 4] = rot[c * 9 + i * 3 + 2];
      d[o + 3 + i * 4] = trans[c * 3 + i];
    }
  }
}

/**
 * Per mesh vertex attributes: pdeVertex (n, 3) = clip vertex of the mesh vertex and of two neighbours (the
 * corners of its best-shaped triangle), pdeNormalFrame (n, 3) = the mesh normal in that triangle's rest
 * frame. vertexMap (n) maps mesh vertices to clip vertices; positions/normals (n * 3) are the mesh's; index
 * the triangle list (null for non-indexed geometry). A vertex without a usable triangle gets neighbours equal
 * to itself (its normal is then kept as it is).
 */
export function meshAttributes({ vertexMap, positions, normals, index }) {
  const n = vertexMap.length;
  const pdeVertex = new Float32Array(n * 3);
  const frame = new Float32Array(n * 3);
  const best = new Float64Array(n).fill(-1);
  const nb = new Int32Array(n * 2);
  for (let i = 0; i < n; i++) {
    nb[i * 2] = i;
    nb[i * 2 + 1] = i;
  }
  const nTri = index ? index.length / 3 : n / 3;
  for (let f = 0; f < nTri; f++) {
    for (let r = 0; r < 3; r++) {
      const k = f * 3;
      const p = index ? index[k + r] : k + r;
      const a = index ? index[k + ((r + 1) % 3)] : k + ((r + 1) % 3);
      const b = index ? index[k + ((r + 2) % 3)] : k + ((r + 2) % 3);
      const q = triangleQuality(positions, p, a, b);
      if (q > best[p]) {
        best[p] = q;
        nb[p * 2] = a;
        nb[p * 2 + 1] = b;
      }
    }
  }
  const fr = new Float64Array(9);
  for (let i = 0; i < n; i++) {
    const a = nb[i * 2];
    const b = nb[i * 2 + 1];
    const ok =
      best[i] > 1e-6 &&
      vertexMap[a] !== vertexMap[i] &&
      vertexMap[b] !== vertexMap[i] &&
      vertexMap[a] !== vertexMap[b];
    pdeVertex[i * 3] = vertexMap[i];
    pdeVertex[i * 3 + 1] = ok ? vertexMap[a] : vertexMap[i];
    pdeVertex[i * 3 + 2] = ok ? vertexMap[b] : vertexMap[i];
    if (!ok || !normals) continue;
    triangleFrame(positions, i, a, b, fr);
    const nx = normals[i * 3];
    const ny = normals[i * 3 + 1];
    const nz = normals[i * 3 + 2];
    for (let k = 0; k < 3; k++) frame[i * 3 + k] = fr[k * 3] * nx + fr[k * 3 + 1] * ny + fr[k * 3 + 2] * nz;
  }
  return { pdeVertex, pdeNormalFrame: frame };
}

/**
 * CPU counterpart of the shader's normals: mesh normals (n * 3) from clip positions (V * 3) and the mesh
 * attributes of meshAttributes(); vertices without a frame keep restNormals. Allocation-free after the first
 * call (per frame).
 */
export function frameNormals(clipPositions, attrs, restNormals, out) {
  const { pdeVertex, pdeNormalFrame } = attrs;
  const fr = (frameNormals.scratch ??= new Float64Array(9));
  for (let i = 0; i < pdeVertex.length; i += 3) {
    const p = pdeVertex[i];
    const a = pdeVertex[i + 1];
    if (a === p) {
      out[i] = restNormals ? restNormals[i] : 0;
      out[i + 1] = restNormals ? restNormals[i + 1] : 0;
      out[i + 2] = restNormals ? restNormals[i + 2] : 1;
      continue;
    }
    triangleFrame(clipPositions, p, a, pdeVertex[i + 2], fr);
    const x = pdeNormalFrame[i];
    const y = pdeNormalFrame[i + 1];
    const z = pdeNormalFrame[i + 2];
    out[i] = x * fr[0] + y * fr[3] + z * fr[6];
    out[i + 1] = x * fr[1] + y * fr[4] + z * fr[7];
    out[i + 2] = x * fr[2] + y * fr[5] + z * fr[8];
  }
  return out;
}
export { glslHeader, glslPassMain, patchVertexShader } from './glsl.js';
