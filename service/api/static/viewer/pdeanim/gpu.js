// GPU evaluation data (no three.js import): float textures, per-vertex attributes, per-frame uniforms and
// the GLSL that evaluates a clip in a vertex shader (docs/format.md has the math; this mirrors the CPU path).

import { CyclicEvaluator } from './cyclic.js';
import { vertexBase, vertexBasis } from './dynamic.js';
import { locate } from './basis.js';

export const TEXTURE_WIDTH = 4096;
export const FIELDS_BUDGET_BYTES = 64 * 1024 * 1024;

/** A float RGBA texture of n texels, width w: {data (Float32Array n*4, padded), width, height}. */
function texture(nTexels, width = TEXTURE_WIDTH) {
  const w = Math.max(1, Math.min(width, nTexels));
  const h = Math.max(1, Math.ceil(nTexels / w));
  return { data: new Float32Array(w * h * 4), width: w, height: h };
}

/**
 * Textures and constants of a decoded clip for the vertex shader (independent of t and of the mesh):
 * {kind, mode, rigid, nCurves, nVertices, textures: {vertex, field?, knot?, mu?, rigid?}, maxHeight}.
 *
 * mode "fields" (dynamic clips; the default while (S+1) x V texels fit fieldsBudget bytes) stores every
 * knot's per-vertex contribution P_k = knots_k . S(u), computed in float64 like the CPU path, so the shader
 * only forms base + phi0 P_s + phi1 P_s+1; mode "coefficients" stores the knots and the per-vertex basis
 * (far smaller, but the shader then sums knot x basis terms in float32, and fitted clips' terms can be ~1e3
 * times the result: ~1e-4 of the diagonal instead of ~1e-7).
 */
export function gpuLayout(
  clip,
  { width = TEXTURE_WIDTH, mode = 'auto', fieldsBudget = FIELDS_BUDGET_BYTES } = {},
) {
  if (clip.kind === 'cyclic-spine') return cyclicLayout(clip, width);
  const { nVertices: V, nCurves: C, nSegments: S, curveOf, knots, family, m, rigid } = clip;
  if (!['auto', 'fields', 'coefficients'].includes(mode)) throw new RangeError(`unknown GPU mode ${mode}`);
  const useFields = mode === 'fields' || (mode === 'auto' && (S + 1) * V * 16 <= fieldsBudget);
  const B = vertexBasis(clip);
  const base = vertexBase(clip);
  const mu = texture(S * C, width); // per (segment, curve): signed time constants x, y, z
  for (let i = 0; i < S * C; i++) {
    for (let w = 0; w < 3; w++) mu.data[i * 4 + w] = (family[i * 3 + w] >= 2 ? -1 : 1) * m[i * 3 + w];
  }
  let textures;
  if (useFields) {
    const vertex = texture(V, width); // per vertex: (curve, base xyz)
    for (let v = 0; v < V; v++) {
      vertex.data[v * 4] = curveOf[v];
      vertex.data.set(base.subarray(v * 3, v * 3 + 3), v * 4 + 1);
    }
    const field = texture((S + 1) * V, width); // per (knot, vertex): P xyz
    for (let s = 0; s <= S; s++) {
      for (let v = 0; v < V; v++) {
        const kc = (s * C + curveOf[v]) * 12;
        const o = (s * V + v) * 4;
        for (let w = 0; w < 3; w++) {
          const b = v * 12 + w * 4;
          const k = kc + w * 4;
          field.data[o + w] =
            B[b] * knots[k] + B[b + 1] * knots[k + 1] + B[b + 2] * knots[k + 2] + B[b + 3] * knots[k + 3];
        }
      }
    }
    textures = { vertex, field, mu };
  } else {
    const vertex = texture(V * 4, width); // per vertex: (curve, base xyz), basis x, basis y, basis z
    for (let v = 0; v < V; v++) {
      const o = v * 16;
      vertex.data[o] = curveOf[v];
      vertex.data.set(base.subarray(v * 3, v * 3 + 3), o + 1);
      vertex.data.set(B.subarray(v * 12, v * 12 + 12), o + 4);
    }
    const knot = texture((S + 1) * C * 3, width); // per (knot, curve, coordinate): 4 space coefficients
    knot.data.set(knots);
    textures = { vertex, knot, mu };
  }
  if (rigid) {
    const Sr = rigid.segmentT.length - 1;
    const rt = texture((Sr + 1) * C * 2, width); // per (knot, curve): (rotvec, rot mu), (centroid, trans mu)
    for (let s = 0; s <= Sr; s++) {
      for (let c = 0; c < C; c++) {
        const o = (s * C + c) * 2 * 4;
        const k = (s * C + c) * 3;
        rt.data.set(rigid.rotKnots.subarray(k, k + 3), o);
        rt.data.set(rigid.transKnots.subarray(k, k + 3), o + 4);
        rt.data[o + 3] = s < Sr ? rigid.rotMu[s * C + c] : 0;
        rt.data[o + 7] = s < Sr ? rigid.transMu[s * C + c] : 0;
      }
    }
    textures.rigid = rt;
  }
  return {
    kind: clip.kind,
    mode: useFields ? 'fields' : 'coefficients',
    rigid: Boolean(rigid),
    nCurves: C,
    nVertices: V,
    textures,
    clip,
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
    nCurves: 0,
    nVertices: V,
    textures: { vertex },
    clip,
    maxHeight: vertex.height,
    axis: ev.axis,
    bend: ev.bend,
    rotate: ev.rotate,
  };
}

/** The uniforms that depend on t: segment and local time (and the rigid ones), or the wave phase. */
export function timeUniforms(layout, t) {
  if (!Number.isFinite(t)) throw new RangeError(`clip time must be a finite number, got ${t}`);
  const clip = layout.clip;
  if (clip.kind === 'cyclic-spine') {
    const wt = 2 * Math.PI * clip.swim.frequency * (t * clip.period);
    return { seg: 0, tau: 0, rseg: 0, rtau: 0, sw: Math.sin(wt), cw: Math.cos(wt) };
  }
  const [seg, tau, tw] = locate(clip.segmentT, t, clip.looping);
  let rseg = 0;
  let rtau = 0;
  if (clip.rigid) [rseg, rtau] = locate(clip.rigid.segmentT, tw, false);
  return { seg, tau, rseg, rtau, sw: 0, cw: 0 };
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
 * attributes of meshAttributes(); vertices without a frame keep restNormals.
 */
export function frameNormals(clipPositions, attrs, restNormals, out) {
  const { pdeVertex, pdeNormalFrame } = attrs;
  const fr = new Float64Array(9);
  for (let i = 0; i < pdeVertex.length; i += 3) {
    const p = pdeVertex[i];
    const a = pdeVertex[i + 1];
    const b = pdeVertex[i + 2];
    if (a === p) {
      out[i] = restNormals ? restNormals[i] : 0;
      out[i + 1] = restNormals ? restNormals[i + 1] : 0;
      out[i + 2] = restNormals ? restNormals[i + 2] : 1;
      continue;
    }
    triangleFrame(clipPositions, p, a, b, fr);
    const [x, y, z] = [pdeNormalFrame[i], pdeNormalFrame[i + 1], pdeNormalFrame[i + 2]];
    for (let w = 0; w < 3; w++) out[i + w] = x * fr[w] + y * fr[3 + w] + z * fr[6 + w];
  }
  return out;
}

/** GLSL declarations and functions (inserted after three.js's `#include <common>`). */
export function glslHeader(layout) {
  const defs = [layout.kind === 'cyclic-spine' ? '#define PDEANIM_CYCLIC' : '#define PDEANIM_DYNAMIC'];
  if (layout.rigid) defs.push('#define PDEANIM_RIGID');
  if (layout.mode === 'fields') defs.push('#define PDEANIM_FIELDS');
  return `${defs.join('\n')}
in vec3 pdeVertex;
in vec3 pdeNormalFrame;
uniform highp sampler2D pdeVertexTex;
uniform bool pdeEnabled;
uniform int pdeSeg;
uniform float pdeTau;
uniform int pdeCurves;
uniform int pdeVertices;
uniform mat4 pdeClipToLocal;
uniform mat3 pdeNormalToLocal;
#ifdef PDEANIM_DYNAMIC
uniform highp sampler2D pdeMuTex;
#ifdef PDEANIM_FIELDS
uniform highp sampler2D pdeFieldTex;
#else
uniform highp sampler2D pdeKnotTex;
#endif
#endif
#ifdef PDEANIM_RIGID
uniform highp sampler2D pdeRigidTex;
uniform int pdeRSeg;
uniform float pdeRTau;
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
  int w = textureSize(tex, 0).x;
  return texelFetch(tex, ivec2(i - (i / w) * w, i / w), 0);
}
// sinh(m x) / sinh(m) for m > 0 (series of sinh(y) / y below m = 0.5, no cancellation in float32)
float pdeSinhRatio(float x, float m) {
  if (m < 0.5) {
    float a = m * x * m * x;
    float b = m * m;
    float sa = 1.0 + a * (1.0 / 6.0 + a * (1.0 / 120.0 + a * (1.0 / 5040.0 + a / 362880.0)));
    float sb = 1.0 + b * (1.0 / 6.0 + b * (1.0 / 120.0 + b * (1.0 / 5040.0 + b / 362880.0)));
    return x * sa / sb;
  }
  return exp(m * (x - 1.0)) * (1.0 - exp(-2.0 * m * x)) / (1.0 - exp(-2.0 * m));
}
// sin(m x) / sin(m) for 0 < m < pi
float pdeSinRatio(float x, float m) {
  if (m < 0.5) {
    float a = m * x * m * x;
    float b = m * m;
    float sa = 1.0 - a * (1.0 / 6.0 - a * (1.0 / 120.0 - a * (1.0 / 5040.0 - a / 362880.0)));
    float sb = 1.0 - b * (1.0 / 6.0 - b * (1.0 / 120.0 - b * (1.0 / 5040.0 - b / 362880.0)));
    return x * sa / sb;
  }
  return sin(m * x) / sin(m);
}
vec2 pdeTimePair(float tau, float mu) {
  if (mu > 1e-12) return vec2(pdeSinhRatio(1.0 - tau, mu), pdeSinhRatio(tau, mu));
  if (mu < -1e-12) {
    float m = min(-mu, ${(0.95 * Math.PI).toFixed(9)});
    return vec2(pdeSinRatio(1.0 - tau, m), pdeSinRatio(tau, m));
  }
  return vec2(1.0 - tau, tau);
}
#ifdef PDEANIM_DYNAMIC
#ifndef PDEANIM_FIELDS
float pdeCoord(int v, int c, int w, vec4 b) {
  float mu = pdeFetch(pdeMuTex, pdeSeg * pdeCurves + c)[w];
  vec2 ph = pdeTimePair(pdeTau, mu);
  vec4 k0 = pdeFetch(pdeKnotTex, (pdeSeg * pdeCurves + c) * 3 + w);
  vec4 k1 = pdeFetch(pdeKnotTex, ((pdeSeg + 1) * pdeCurves + c) * 3 + w);
  return dot(ph.x * k0 + ph.y * k1, b);
}
#endif
#ifdef PDEANIM_RIGID
mat3 pdeRodrigues(vec3 r) {
  float t2 = dot(r, r);
  float th = sqrt(t2);
  float a = th < 0.05 ? 1.0 - t2 / 6.0 + t2 * t2 / 120.0 : sin(th) / th;
  float b = th < 0.05 ? 0.5 - t2 / 24.0 + t2 * t2 / 720.0 : (1.0 - cos(th)) / t2;
  mat3 K = mat3(0.0, r.z, -r.y, -r.z, 0.0, r.x, r.y, -r.x, 0.0); // column-major
  return mat3(1.0) + a * K + b * (K * K);
}
vec2 pdeRigidPair(float tau, float mu) {
  if (mu < 0.0) {
    float m = min(-mu, ${(0.95 * Math.PI).toFixed(9)});
    return vec2(pdeSinRatio(1.0 - tau, m), pdeSinRatio(tau, m));
  }
  if (mu < 1e-12) return vec2(1.0 - tau, tau);
  return vec2(pdeSinhRatio(1.0 - tau, mu), pdeSinhRatio(tau, mu));
}
#endif
vec3 pdeEval(int v) {
#ifdef PDEANIM_FIELDS
  vec4 head = pdeFetch(pdeVertexTex, v);
  int c = int(head.x + 0.5);
  vec3 mu = pdeFetch(pdeMuTex, pdeSeg * pdeCurves + c).xyz;
  vec2 px = pdeTimePair(pdeTau, mu.x);
  vec2 py = pdeTimePair(pdeTau, mu.y);
  vec2 pz = pdeTimePair(pdeTau, mu.z);
  vec3 p = head.yzw + vec3(px.x, py.x, pz.x) * pdeFetch(pdeFieldTex, pdeSeg * pdeVertices + v).xyz
    + vec3(px.y, py.y, pz.y) * pdeFetch(pdeFieldTex, (pdeSeg + 1) * pdeVertices + v).xyz;
#else
  vec4 head = pdeFetch(pdeVertexTex, v * 4);
  int c = int(head.x + 0.5);
  vec3 p = head.yzw + vec3(pdeCoord(v, c, 0, pdeFetch(pdeVertexTex, v * 4 + 1)),
                           pdeCoord(v, c, 1, pdeFetch(pdeVertexTex, v * 4 + 2)),
                           pdeCoord(v, c, 2, pdeFetch(pdeVertexTex, v * 4 + 3)));
#endif
#ifdef PDEANIM_RIGID
  vec4 r0 = pdeFetch(pdeRigidTex, (pdeRSeg * pdeCurves + c) * 2);
  vec4 c0 = pdeFetch(pdeRigidTex, (pdeRSeg * pdeCurves + c) * 2 + 1);
  vec4 r1 = pdeFetch(pdeRigidTex, ((pdeRSeg + 1) * pdeCurves + c) * 2);
  vec4 c1 = pdeFetch(pdeRigidTex, ((pdeRSeg + 1) * pdeCurves + c) * 2 + 1);
  vec2 pr = pdeRigidPair(pdeRTau, r0.w);
  vec2 pt = pdeRigidPair(pdeRTau, c0.w);
  p = pdeRodrigues(pr.x * r0.xyz + pr.y * r1.xyz) * p + (pt.x * c0.xyz + pt.y * c1.xyz);
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
void pdeCompute() {
  int v = int(pdeVertex.x + 0.5);
  int va = int(pdeVertex.y + 0.5);
  int vb = int(pdeVertex.z + 0.5);
  vec3 p = pdeEval(v);
  pdePosition = (pdeClipToLocal * vec4(p, 1.0)).xyz;
  pdeNormal = normal;
  if (va != v) {
    vec3 e1 = pdeEval(va) - p;
    vec3 e2 = pdeEval(vb) - p;
    vec3 t1 = normalize(e1);
    vec3 n = normalize(cross(e1, e2));
    pdeNormal = normalize(pdeNormalToLocal * (pdeNormalFrame.x * t1 + pdeNormalFrame.y * cross(n, t1)
      + pdeNormalFrame.z * n));
  }
}
`;
}
