// GPU evaluation data (no three.js import): float textures, per-vertex attributes, per-frame uniforms and
// the GLSL that evaluates a clip in a vertex shader (docs/format.md has the math; this mirrors the CPU path).

import { CyclicEvaluator } from './cyclic.js';
import { DynamicEvaluator, naturalSplineTangents, vertexBasis } from './dynamic.js';

export const TEXTURE_WIDTH = 4096;
export const FIELDS_BUDGET_BYTES = 64 * 1024 * 1024;

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
 * Textures and constants of a decoded clip for the vertex shader (independent of the mesh):
 * {kind, mode, rigid, spline, nCurves, nVertices, nSegments, curveTexels, textures: {vertex,
 * field | knot, tangent?, curve}, maxHeight, evaluator}. The `curve` texture is the per-frame table that
 * timeUniforms() rewrites: per curve the time pairs (phi0 xyz, phi1 xyz) of the current segment and, for
 * rigid clips, the rows of R with the centroid (R row i, c_i), all computed in float64 by the CPU evaluator's
 * own code (a few us per frame). Clips with items on the natural spline (docs/format.md §3.5: `spline` true)
 * carry four weights per item instead of the pair (texels w_0 xyz, w_1 xyz, w_2 xyz, w_3 xyz: the weights of
 * T_s, P_s, P_s+1, T_s+1, or 0, phi0, phi1, 0 for an item off the spline), then the rigid rows; their
 * `tangent` texture holds the tangents T_j of every knot in the layout of the `field` or `knot` texture (the
 * spline's tridiagonal solve applied to the per-vertex fields, or to the knot coefficients, once per clip).
 *
 * mode "fields" (the default while (S+1) x V texels, twice that with natural-spline tangents, fit
 * fieldsBudget bytes) stores every knot's per-vertex contribution P_k = knots_k . S(u) (the CPU evaluator's
 * float32 fields), so the shader only forms base + phi0 P_s + phi1 P_s+1; mode "coefficients" stores the
 * knots and the per-vertex space basis (far
 * smaller, but the shader then sums knot x basis terms in float32, and fitted clips' terms can be ~1e3 times
 * the result: ~1e-5 of the diagonal instead of ~1e-7).
 */
export function gpuLayout(
  clip,
  { width = TEXTURE_WIDTH, mode = 'auto', fieldsBudget = FIELDS_BUDGET_BYTES, evaluator = null } = {},
) {
  width = pow2Width(width);
  if (clip.kind === 'cyclic-spine') return cyclicLayout(clip, width);
  const { nVertices: V, nCurves: C, nSegments: S, curveOf, knots, rigid } = clip;
  if (!['auto', 'fields', 'coefficients'].includes(mode)) throw new RangeError(`unknown GPU mode ${mode}`);
  const ev = evaluator ?? new DynamicEvaluator(clip);
  const spline = ev.spline !== null;
  // natural-spline clips keep a tangent texture of the same size beside the fields
  const fieldBytes = (S + 1) * V * 16 * (spline ? 2 : 1);
  const useFields = mode === 'fields' || (mode === 'auto' && fieldBytes <= fieldsBudget);
  const base = ev.base;
  let textures;
  if (useFields) {
    const vertex = texture(V, width); // per vertex: (curve, base xyz)
    for (let v = 0; v < V; v++) {
      vertex.data[v * 4] = curveOf[v];
      vertex.data.set(base.subarray(v * 3, v * 3 + 3), v * 4 + 1);
    }
    const field = texture((S + 1) * V, width); // per (knot, vertex): P xyz
    for (let i = 0; i < (S + 1) * V; i++) field.data.set(ev.fields.subarray(i * 3, i * 3 + 3), i * 4);
    textures = { vertex, field };
  } else {
    const B = vertexBasis(clip);
    const vertex = texture(V * 4, width); // per vertex: (curve, base xyz), basis x, basis y, basis z
    for (let v = 0; v < V; v++) {
      const o = v * 16;
      vertex.data[o] = curveOf[v];
      vertex.data.set(base.subarray(v * 3, v * 3 + 3), o + 1);
      vertex.data.set(B.subarray(v * 12, v * 12 + 12), o + 4);
    }
    const knot = texture((S + 1) * C * 3, width); // per (knot, curve, coordinate): 4 space coefficients
    knot.data.set(knots);
    textures = { vertex, knot };
  }
  if (spline) {
    // natural-spline tangents of every knot, in the layout of the field or knot texture
    if (useFields) {
      const tangent = texture((S + 1) * V, width); // per (knot, vertex): T xyz
      const T = ev.tangentFields;
      for (let i = 0; i < (S + 1) * V; i++) tangent.data.set(T.subarray(i * 3, i * 3 + 3), i * 4);
      textures.tangent = tangent;
    } else {
      const tangent = texture((S + 1) * C * 3, width); // per (knot, curve, coordinate): 4 coefficients
      naturalSplineTangents(clip.segmentT, knots, C * 12, tangent.data);
      textures.tangent = tangent;
    }
  }
  const weightTexels = spline ? 4 : 2;
  const curveTexels = weightTexels + (rigid ? 3 : 0);
  textures.curve = texture(C * curveTexels, width);
  return {
    kind: clip.kind,
    mode: useFields ? 'fields' : 'coefficients',
    rigid: Boolean(rigid),
    spline,
    nCurves: C,
    nVertices: V,
    nSegments: S,
    weightTexels,
    width,
    curveTexels,
    textures,
    clip,
    evaluator: ev,
    maxHeight: Math.max(...Object.values(textures).map((x) => x.height)),
  };
}

function cyclicLayout(clip, width) {
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
    mode: 'cyclic',
    rigid: false,
    spline: false,
    nCurves: 0,
    nVertices: V,
    nSegments: 0,
    width,
    textures: { vertex },
    clip,
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
  if (layout.rigid) {
    const { rot, trans } = ev;
    const R = layout.weightTexels * 4; // the rigid rows follow the weights
    for (let c = 0, o = R; c < C; c++, o += K) {
      for (let i = 0; i < 3; i++) {
        d[o + i * 4] = rot[c * 9 + i * 3];
        d[o + 1 + i * 4] = rot[c * 9 + i * 3 + 1];
        d[o + 2 + i * 4] = rot[c * 9 + i * 3 + 2];
        d[o + 3 + i * 4] = trans[c * 3 + i];
      }
    }
  }
  return { seg, sw: 0, cw: 0, changed: true };
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
  const corner = index ? (k) => index[k] : (k) => k;
  const e = new Float64Array(6);
  for (let f = 0; f < nTri; f++) {
    for (let r = 0; r < 3; r++) {
      const p = corner(f * 3 + r);
      const a = corner(f * 3 + ((r + 1) % 3));
      const b = corner(f * 3 + ((r + 2) % 3));
      const q = triangleQuality(positions, p, a, b, e);
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

/** Shape quality of triangle (p, a, b): |e1 x e2| / (|e1|^2 + |e2|^2), 0 when degenerate. */
function triangleQuality(pos, p, a, b, e) {
  for (let w = 0; w < 3; w++) {
    e[w] = pos[a * 3 + w] - pos[p * 3 + w];
    e[3 + w] = pos[b * 3 + w] - pos[p * 3 + w];
  }
  const cx = e[1] * e[5] - e[2] * e[4];
  const cy = e[2] * e[3] - e[0] * e[5];
  const cz = e[0] * e[4] - e[1] * e[3];
  const den = e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3] + e[4] * e[4] + e[5] * e[5];
  return den > 0 ? Math.hypot(cx, cy, cz) / den : 0;
}

/**
 * Orthonormal frame (rows t1, t2, n) of triangle (p, a, b) of positions (any vertex indexing) into out (9):
 * t1 along p->a, n the triangle normal, t2 = n x t1. The shader builds the same frame from evaluated
 * positions.
 */
export function triangleFrame(pos, p, a, b, out) {
  const e1 = [0, 1, 2].map((w) => pos[a * 3 + w] - pos[p * 3 + w]);
  const e2 = [0, 1, 2].map((w) => pos[b * 3 + w] - pos[p * 3 + w]);
  const l1 = Math.hypot(...e1) || 1;
  const t1 = e1.map((x) => x / l1);
  let nn = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
  const ln = Math.hypot(...nn) || 1;
  nn = nn.map((x) => x / ln);
  const t2 = [nn[1] * t1[2] - nn[2] * t1[1], nn[2] * t1[0] - nn[0] * t1[2], nn[0] * t1[1] - nn[1] * t1[0]];
  out.set([...t1, ...t2, ...nn]);
  return out;
}

/**
 * CPU counterpart of the shader's normals: mesh normals (n * 3) from clip positions (V * 3) and the mesh
 * attributes of meshAttributes(); vertices without a frame keep restNormals. Allocation-free (per frame).
 */
export function frameNormals(clipPositions, attrs, restNormals, out) {
  const { pdeVertex, pdeNormalFrame } = attrs;
  const P = clipPositions;
  for (let i = 0; i < pdeVertex.length; i += 3) {
    const p = pdeVertex[i] * 3;
    const a = pdeVertex[i + 1] * 3;
    const b = pdeVertex[i + 2] * 3;
    if (a === p) {
      out[i] = restNormals ? restNormals[i] : 0;
      out[i + 1] = restNormals ? restNormals[i + 1] : 0;
      out[i + 2] = restNormals ? restNormals[i + 2] : 1;
      continue;
    }
    const e1x = P[a] - P[p];
    const e1y = P[a + 1] - P[p + 1];
    const e1z = P[a + 2] - P[p + 2];
    const e2x = P[b] - P[p];
    const e2y = P[b + 1] - P[p + 1];
    const e2z = P[b + 2] - P[p + 2];
    const l1 = Math.hypot(e1x, e1y, e1z) || 1;
    const t1x = e1x / l1;
    const t1y = e1y / l1;
    const t1z = e1z / l1;
    let nx = e1y * e2z - e1z * e2y;
    let ny = e1z * e2x - e1x * e2z;
    let nz = e1x * e2y - e1y * e2x;
    const ln = Math.hypot(nx, ny, nz) || 1;
    nx /= ln;
    ny /= ln;
    nz /= ln;
    const t2x = ny * t1z - nz * t1y;
    const t2y = nz * t1x - nx * t1z;
    const t2z = nx * t1y - ny * t1x;
    const x = pdeNormalFrame[i];
    const y = pdeNormalFrame[i + 1];
    const z = pdeNormalFrame[i + 2];
    out[i] = x * t1x + y * t2x + z * nx;
    out[i + 1] = x * t1y + y * t2y + z * ny;
    out[i + 2] = x * t1z + y * t2z + z * nz;
  }
  return out;
}

/**
 * GLSL main() of the evaluation pass: one fragment per clip vertex (row-major in a texture of layout.width
 * columns) writes its position; the mesh shaders (compiled with pass: true) then read three positions per
 * vertex instead of evaluating them.
 */
export function glslPassMain() {
  return `void main() {
  int v = (int(gl_FragCoord.y) << PDEANIM_WIDTH_SHIFT) + int(gl_FragCoord.x);
  gl_FragColor = v < pdeVertices ? vec4(pdeEval(v), 1.0) : vec4(0.0);
}
`;
}

/** GLSL declarations and functions (inserted after three.js's `#include <common>`). */
export function glslHeader(layout, { normals = 'frame', stage = 'vertex', pass = false } = {}) {
  const defs = [layout.kind === 'cyclic-spine' ? '#define PDEANIM_CYCLIC' : '#define PDEANIM_DYNAMIC'];
  if (stage === 'vertex') defs.push('#define PDEANIM_VERTEX_STAGE');
  if (pass) defs.push('#define PDEANIM_PASS');
  if (normals === 'rest') defs.push('#define PDEANIM_REST_NORMALS');
  if (layout.rigid) defs.push('#define PDEANIM_RIGID');
  if (layout.spline) defs.push('#define PDEANIM_SPLINE');
  if (layout.mode === 'fields') defs.push('#define PDEANIM_FIELDS');
  defs.push(`#define PDEANIM_CURVE_TEXELS ${layout.curveTexels ?? 0}`);
  defs.push(`#define PDEANIM_WEIGHT_TEXELS ${layout.weightTexels ?? 0}`);
  defs.push(`#define PDEANIM_WIDTH_SHIFT ${Math.log2(layout.width)}`);
  defs.push(`#define PDEANIM_WIDTH_MASK ${layout.width - 1}`);
  return `${defs.join('\n')}
#ifdef PDEANIM_VERTEX_STAGE
in vec3 pdeVertex;
in vec3 pdeNormalFrame;
#endif
#ifdef PDEANIM_PASS
uniform highp sampler2D pdePosTex;
#endif
uniform highp sampler2D pdeVertexTex;
uniform bool pdeEnabled;
uniform int pdeSeg;
uniform int pdeCurves;
uniform int pdeVertices;
uniform mat4 pdeClipToLocal;
uniform mat3 pdeNormalToLocal;
#ifdef PDEANIM_DYNAMIC
uniform highp sampler2D pdeCurveTex;
#ifdef PDEANIM_FIELDS
uniform highp sampler2D pdeFieldTex;
#else
uniform highp sampler2D pdeKnotTex;
#endif
#ifdef PDEANIM_SPLINE
uniform highp sampler2D pdeTangentTex;
#endif
#endif
#ifdef PDEANIM_CYCLIC
uniform float pdeSinWt;
uniform float pdeCosWt;
uniform vec3 pdeAxis;
uniform vec3 pdeBend;
uniform bool pdeRotate;
#endif
vec3 pdePosition;
vec3 pdeNormal;
vec4 pdeFetch(highp sampler2D tex, int i) {
  return texelFetch(tex, ivec2(i & PDEANIM_WIDTH_MASK, i >> PDEANIM_WIDTH_SHIFT), 0);
}
#ifdef PDEANIM_DYNAMIC
vec3 pdeEval(int v) {
#ifdef PDEANIM_FIELDS
  vec4 head = pdeFetch(pdeVertexTex, v);
#else
  vec4 head = pdeFetch(pdeVertexTex, v * 4);
#endif
  int c = int(head.x + 0.5);
#ifdef PDEANIM_SPLINE
  // natural spline: weights of T_s, P_s, P_s+1, T_s+1 (0, phi0, phi1, 0 for items off the spline)
  int sl = pdeSeg;
  int sh = pdeSeg + 1;
  vec3 fl = pdeFetch(pdeCurveTex, c * PDEANIM_CURVE_TEXELS).xyz;
  vec3 f0 = pdeFetch(pdeCurveTex, c * PDEANIM_CURVE_TEXELS + 1).xyz;
  vec3 f1 = pdeFetch(pdeCurveTex, c * PDEANIM_CURVE_TEXELS + 2).xyz;
  vec3 fh = pdeFetch(pdeCurveTex, c * PDEANIM_CURVE_TEXELS + 3).xyz;
#ifdef PDEANIM_FIELDS
  vec3 p = head.yzw + (((fl * pdeFetch(pdeTangentTex, sl * pdeVertices + v).xyz
    + f0 * pdeFetch(pdeFieldTex, pdeSeg * pdeVertices + v).xyz)
    + f1 * pdeFetch(pdeFieldTex, (pdeSeg + 1) * pdeVertices + v).xyz)
    + fh * pdeFetch(pdeTangentTex, sh * pdeVertices + v).xyz);
#else
  vec3 p = head.yzw;
  for (int w = 0; w < 3; w++) {
    vec4 kl = pdeFetch(pdeTangentTex, (sl * pdeCurves + c) * 3 + w);
    vec4 k0 = pdeFetch(pdeKnotTex, (pdeSeg * pdeCurves + c) * 3 + w);
    vec4 k1 = pdeFetch(pdeKnotTex, ((pdeSeg + 1) * pdeCurves + c) * 3 + w);
    vec4 kh = pdeFetch(pdeTangentTex, (sh * pdeCurves + c) * 3 + w);
    p[w] += dot(fl[w] * kl + f0[w] * k0 + f1[w] * k1 + fh[w] * kh, pdeFetch(pdeVertexTex, v * 4 + 1 + w));
  }
#endif
#else
  vec3 f0 = pdeFetch(pdeCurveTex, c * PDEANIM_CURVE_TEXELS).xyz;
  vec3 f1 = pdeFetch(pdeCurveTex, c * PDEANIM_CURVE_TEXELS + 1).xyz;
#ifdef PDEANIM_FIELDS
  vec3 p = head.yzw + f0 * pdeFetch(pdeFieldTex, pdeSeg * pdeVertices + v).xyz
    + f1 * pdeFetch(pdeFieldTex, (pdeSeg + 1) * pdeVertices + v).xyz;
#else
  vec3 p = head.yzw;
  for (int w = 0; w < 3; w++) {
    vec4 k0 = pdeFetch(pdeKnotTex, (pdeSeg * pdeCurves + c) * 3 + w);
    vec4 k1 = pdeFetch(pdeKnotTex, ((pdeSeg + 1) * pdeCurves + c) * 3 + w);
    p[w] += dot(f0[w] * k0 + f1[w] * k1, pdeFetch(pdeVertexTex, v * 4 + 1 + w));
  }
#endif
#endif
#ifdef PDEANIM_RIGID
  vec4 r0 = pdeFetch(pdeCurveTex, c * PDEANIM_CURVE_TEXELS + PDEANIM_WEIGHT_TEXELS);
  vec4 r1 = pdeFetch(pdeCurveTex, c * PDEANIM_CURVE_TEXELS + PDEANIM_WEIGHT_TEXELS + 1);
  vec4 r2 = pdeFetch(pdeCurveTex, c * PDEANIM_CURVE_TEXELS + PDEANIM_WEIGHT_TEXELS + 2);
  p = vec3(dot(r0.xyz, p) + r0.w, dot(r1.xyz, p) + r1.w, dot(r2.xyz, p) + r2.w);
#endif
  return p;
}
#endif
#ifdef PDEANIM_CYCLIC
vec3 pdeEval(int v) {
  vec4 a = pdeFetch(pdeVertexTex, v * 3);
  vec4 w = pdeFetch(pdeVertexTex, v * 3 + 1);
  float rl = pdeFetch(pdeVertexTex, v * 3 + 2).x;
  float ca = 0.0;
  float cl = w.x * pdeSinWt + w.y * pdeCosWt;
  if (pdeRotate) {
    float g = w.z * pdeSinWt + w.w * pdeCosWt;
    float c = 1.0 / sqrt(1.0 + g * g);
    float sn = g * c;
    ca = (c - 1.0) * a.w - sn * rl;
    cl += sn * a.w + (c - 1.0) * rl;
  }
  return a.xyz + ca * pdeAxis + cl * pdeBend;
}
#endif
#ifdef PDEANIM_VERTEX_STAGE
// a clip vertex's position: read from the pass's texture, or evaluated here
vec3 pdeAt(int v) {
#ifdef PDEANIM_PASS
  return pdeFetch(pdePosTex, v).xyz;
#else
  return pdeEval(v);
#endif
}
void pdeCompute() {
  int v = int(pdeVertex.x + 0.5);
  int va = int(pdeVertex.y + 0.5);
  int vb = int(pdeVertex.z + 0.5);
  vec3 p = pdeAt(v);
  pdePosition = (pdeClipToLocal * vec4(p, 1.0)).xyz;
  pdeNormal = normal;
#ifndef PDEANIM_REST_NORMALS
  if (va != v) {
    vec3 e1 = pdeAt(va) - p;
    vec3 e2 = pdeAt(vb) - p;
    vec3 t1 = normalize(e1);
    vec3 n = normalize(cross(e1, e2));
    pdeNormal = normalize(pdeNormalToLocal * (pdeNormalFrame.x * t1 + pdeNormalFrame.y * cross(n, t1)
      + pdeNormalFrame.z * n));
  }
#endif
}
#endif
`;
}
