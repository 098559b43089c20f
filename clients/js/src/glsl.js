// The GLSL that evaluates a clip on the GPU (WebGL 2 through three.js): the evaluation of one clip vertex
// from the data textures of gpu.js, the vertex-stage code that places a mesh vertex and turns its normal, and
// the evaluation pass's fragment shader. The math is docs/format.md's; gpu.js's CPU helpers mirror it.

/** The #defines of a layout and the shader variant. */
function defines(layout, { normals, stage, pass, cpu, slots, knotWidth }) {
  const defs = [layout.kind === 'cyclic-spine' ? '#define PDEANIM_CYCLIC' : '#define PDEANIM_DYNAMIC'];
  if (stage === 'vertex') defs.push('#define PDEANIM_VERTEX_STAGE');
  if (pass) defs.push('#define PDEANIM_PASS');
  if (cpu) defs.push('#define PDEANIM_CPU');
  if (slots && stage === 'vertex') defs.push('#define PDEANIM_SLOTS');
  if (knotWidth && stage === 'vertex') {
    defs.push('#define PDEANIM_KNOTS');
    defs.push(`#define PDEANIM_KNOT_SHIFT ${Math.log2(knotWidth)}`);
    defs.push(`#define PDEANIM_KNOT_MASK ${knotWidth - 1}`);
  }
  if (normals === 'rest') defs.push('#define PDEANIM_REST_NORMALS');
  if (layout.rigid) defs.push('#define PDEANIM_RIGID');
  if (layout.bones) defs.push('#define PDEANIM_BONES');
  defs.push(`#define PDEANIM_VERTEX_TEXELS ${layout.vertexTexels ?? 4}`);
  defs.push(`#define PDEANIM_CURVE_TEXELS ${layout.curveTexels ?? 0}`);
  defs.push(`#define PDEANIM_COEFFICIENT_TEXELS ${layout.coefficientTexels ?? 0}`);
  defs.push(`#define PDEANIM_WIDTH_SHIFT ${Math.log2(layout.width)}`);
  defs.push(`#define PDEANIM_WIDTH_MASK ${layout.width - 1}`);
  return defs.join('\n');
}

const DECLARATIONS = `
#ifdef PDEANIM_VERTEX_STAGE
in vec3 pdeVertex;
in vec3 pdeNormalFrame;
uniform bool pdeEnabled;
uniform float pdeInfluence;
uniform mat4 pdeClipToLocal;
uniform mat3 pdeNormalToLocal;
uniform highp sampler2D pdeRingTex;
#ifdef PDEANIM_CPU
in vec3 pdeCpuPosition;
in vec3 pdeCpuNormal;
#endif
#endif
#ifdef PDEANIM_SLOTS
in float pdeSlot;
#endif
#if defined(PDEANIM_SLOTS) || defined(PDEANIM_KNOTS)
uniform int pdeSlotTexels;
uniform int pdeFrameOffset;
int pdeFrameBase;
#else
#define pdeFrameBase 0
#endif
#ifdef PDEANIM_KNOTS
uniform highp sampler2D pdeKnotTex;
uniform int pdeKnotCurves;
uniform int pdeKnotTangents;
uniform int pdeMuTexel;
uniform int pdeTimeTexel;
uniform int pdeRigidTexel;
uniform int pdeRigidKnots;
uniform int pdeRigidMu;
uniform int pdeDirectTexel;
#endif
#ifdef PDEANIM_PASS
uniform highp sampler2D pdePosTex;
#endif
uniform highp sampler2D pdeVertexTex;
uniform int pdeVertices;
#if defined(PDEANIM_DYNAMIC) || defined(PDEANIM_SLOTS)
uniform highp sampler2D pdeFrameTex;
#endif
#ifdef PDEANIM_DYNAMIC
uniform int pdeDirect;
#endif
#ifdef PDEANIM_BONES
uniform int pdeBones;
uniform int pdeSkinOnly;
uniform int pdeSkinTexel;
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
#if defined(PDEANIM_DYNAMIC) || defined(PDEANIM_SLOTS)
// texel i of the per-frame table shown (an instanced crowd: this instance's slot's)
vec4 pdeFrame(int i) {
  return pdeFetch(pdeFrameTex, i + pdeFrameBase);
}
#endif
`;

// one clip vertex v (the GPU's numbering, gpu.js): a direct vertex's position from the per-frame table,
// else base (with bones: the rest position skinned by the bone rows at the end of the per-frame table) + per
// coordinate the frame's coefficients of its curve (from the per-frame table, after the direct positions)
// dotted with the vertex's basis row, then the curve's rigid motion; with bones, the vertices from
// pdeSkinOnly on (curves without residual) are their skinned rest position alone
const DYNAMIC_EVAL = `
#ifdef PDEANIM_DYNAMIC
#ifdef PDEANIM_KNOTS
vec4 pdeKnot(int i) {
  return texelFetch(pdeKnotTex, ivec2(i & PDEANIM_KNOT_MASK, i >> PDEANIM_KNOT_SHIFT), 0);
}
#endif
// texel i of a vertex record: the vertex texture's, or in a crowd a direct vertex's in the knot table
vec4 pdeRecord(bool direct, int i) {
#ifdef PDEANIM_KNOTS
  if (direct) return pdeKnot(i);
#endif
  return pdeFetch(pdeVertexTex, i);
}
#ifdef PDEANIM_BONES
vec3 pdeSkin(int r, vec3 rest, bool direct) {
  vec4 index = pdeRecord(direct, r);
  vec4 weight = pdeRecord(direct, r + 1);
  vec4 x = vec4(rest, 1.0);
  vec3 acc = vec3(0.0);
  for (int k = 0; k < 4; k++) {
    if (weight[k] == 0.0) continue;
    int b = pdeBones + int(index[k] + 0.5) * 3;
    acc += weight[k] * vec3(dot(pdeFrame(b), x), dot(pdeFrame(b + 1), x),
      dot(pdeFrame(b + 2), x));
  }
  return acc;
}
#endif
#ifdef PDEANIM_KNOTS
// a crowd (gpu.js knotTables, crowdRow): coordinate w's coefficients of GPU curve c at this player's time,
// its time pair (or the spline's cubic weights cw) applied to the shared knots of segment seg
vec4 pdeCoefficients(int c, int w, int seg, vec4 mu, vec4 cw) {
  int a = (seg * pdeKnotCurves + c) * 3 + w;
  int b = a + pdeKnotCurves * 3;
  float k = mu[w];
  if (k < -0.5) {
    return cw.x * pdeKnot(pdeKnotTangents + a) + cw.y * pdeKnot(a) + cw.z * pdeKnot(b)
      + cw.w * pdeKnot(pdeKnotTangents + b);
  }
  int j = int(k + 0.5);
  vec4 pair = pdeFrame(pdeTimeTexel + 2 + (j >> 1));
  vec2 phi = (j & 1) == 0 ? pair.xy : pair.zw;
  return phi.x * pdeKnot(a) + phi.y * pdeKnot(b);
}
#ifdef PDEANIM_RIGID
// e^x - 1 without cancellation (a series below |x| 0.5)
float pdeExpm1(float x) {
  if (abs(x) < 0.5) {
    return x * (1.0 + x * (0.5 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * (1.0 / 120.0 + x * (1.0 / 720.0
      + x * (1.0 / 5040.0 + x / 40320.0)))))));
  }
  return exp(x) - 1.0;
}
// sin to float32 precision (GPUs' own sin can be off by 1e-5): x folded into [-pi/2, pi/2] with a two-part
// pi, then its Taylor polynomial to x^15 (remainder < 1e-9)
float pdeSin(float x) {
  const float PI_HI = 3.1415927;
  const float PI_LO = -8.742278e-8; // pi - PI_HI
  x -= 6.2831855 * floor(x / 6.2831855 + 0.5);
  if (x > 1.5707964) x = (PI_HI - x) + PI_LO;
  else if (x < -1.5707964) x = (-PI_HI - x) - PI_LO;
  float x2 = x * x;
  return x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362880.0
    + x2 * (-1.0 / 39916800.0 + x2 * (1.0 / 6227020800.0 + x2 * (-1.0 / 1307674368000.0))))))));
}
// the rigid tracks' time pair (basis.js rigidTimePair: mu < 0 trig, tiny mu linear, else exponential)
vec2 pdeRigidPair(float tau, float mu) {
  if (mu < 0.0) {
    float m = min(-mu, 2.984513020910303); // basis.js MU_TRIG_MAX, 0.95 pi
    float u = 1.0 - tau;
    if (m < 1e-2) return vec2(u * (1.0 + m * m * (1.0 - u * u) / 6.0), tau * (1.0 + m * m * (1.0 - tau * tau) / 6.0));
    float inv = 1.0 / pdeSin(m);
    return vec2(pdeSin(m * u) * inv, pdeSin(m * tau) * inv);
  }
  if (mu < 1e-12) return vec2(1.0 - tau, tau);
  float inv = 1.0 / pdeExpm1(-2.0 * mu);
  return vec2(exp(-mu * tau) * pdeExpm1(-2.0 * mu * (1.0 - tau)) * inv,
    exp(mu * (tau - 1.0)) * pdeExpm1(-2.0 * mu * tau) * inv);
}
// p moved by GPU curve c's rigid motion at this player's rigid segment and time (the row's texel
// pdeRigidTexel): R p + centroid, R the Rodrigues rotation of the rotation vector (dynamic.js rodrigues)
vec3 pdeRigid(int c, vec3 p) {
  vec4 at = pdeFrame(pdeRigidTexel);
  int s = int(at.x + 0.5);
  vec4 mu = pdeKnot(pdeRigidMu + s * pdeKnotCurves + c);
  vec2 pr = pdeRigidPair(at.y, mu.x);
  vec2 pt = pdeRigidPair(at.y, mu.y);
  int k0 = pdeRigidKnots + (s * pdeKnotCurves + c) * 2;
  int k1 = k0 + pdeKnotCurves * 2;
  vec3 r = pr.x * pdeKnot(k0).xyz + pr.y * pdeKnot(k1).xyz;
  vec3 t = pt.x * pdeKnot(k0 + 1).xyz + pt.y * pdeKnot(k1 + 1).xyz;
  float th2 = dot(r, r);
  float th = sqrt(th2);
  float a;
  float b;
  if (th < 1e-2) {
    a = 1.0 - th2 / 6.0 + th2 * th2 / 120.0;
    b = 0.5 - th2 / 24.0 + th2 * th2 / 720.0;
  } else {
    float h = pdeSin(0.5 * th);
    a = pdeSin(th) / th;
    b = 2.0 * h * h / th2;
  }
  vec3 k = cross(r, p);
  return p + a * k + b * cross(r, k) + t;
}
#endif
#endif
vec3 pdeEval(int v) {
#ifdef PDEANIM_KNOTS
  // a crowd: the direct vertices too (their records and curves in the knot table)
  bool direct = v < pdeDirect;
#else
  if (v < pdeDirect) return pdeFrame(v).xyz;
  bool direct = false;
#endif
#ifdef PDEANIM_BONES
  if (v >= pdeSkinOnly) {
    int s = pdeSkinTexel + (v - pdeSkinOnly) * 3;
    return pdeSkin(s + 1, pdeFetch(pdeVertexTex, s).yzw, false);
  }
#endif
#ifdef PDEANIM_KNOTS
  int r = direct ? pdeDirectTexel + v * PDEANIM_VERTEX_TEXELS : (v - pdeDirect) * PDEANIM_VERTEX_TEXELS;
#else
  int r = (v - pdeDirect) * PDEANIM_VERTEX_TEXELS;
#endif
  vec4 head = pdeRecord(direct, r);
  vec3 p = head.yzw;
#ifdef PDEANIM_BONES
  p = pdeSkin(r + PDEANIM_VERTEX_TEXELS - 2, p, direct);
#endif
#ifdef PDEANIM_KNOTS
  int cg = int(head.x + 0.5);
  int seg = int(pdeFrame(pdeTimeTexel).x + 0.5);
  vec4 cw = pdeFrame(pdeTimeTexel + 1);
  // (no time-pair indices when every item is on the spline: the cubic weights for all)
  vec4 mu = pdeMuTexel < 0 ? vec4(-1.0) : pdeKnot(pdeMuTexel + seg * pdeKnotCurves + cg);
  for (int w = 0; w < 3; w++) p[w] += dot(pdeCoefficients(cg, w, seg, mu, cw), pdeRecord(direct, r + 1 + w));
#ifdef PDEANIM_RIGID
  p = pdeRigid(cg, p);
#endif
#else
  int c = pdeDirect + int(head.x + 0.5) * PDEANIM_CURVE_TEXELS;
  for (int w = 0; w < 3; w++) p[w] += dot(pdeFrame(c + w), pdeFetch(pdeVertexTex, r + 1 + w));
#ifdef PDEANIM_RIGID
  vec4 r0 = pdeFrame(c + PDEANIM_COEFFICIENT_TEXELS);
  vec4 r1 = pdeFrame(c + PDEANIM_COEFFICIENT_TEXELS + 1);
  vec4 r2 = pdeFrame(c + PDEANIM_COEFFICIENT_TEXELS + 2);
  p = vec3(dot(r0.xyz, p) + r0.w, dot(r1.xyz, p) + r1.w, dot(r2.xyz, p) + r2.w);
#endif
#endif
  return p;
}
#endif
`;

const CYCLIC_EVAL = `
#ifdef PDEANIM_CYCLIC
vec3 pdeEval(int v) {
  vec4 a = pdeFetch(pdeVertexTex, v * 3);
  vec4 w = pdeFetch(pdeVertexTex, v * 3 + 1);
  float rl = pdeFetch(pdeVertexTex, v * 3 + 2).x;
#ifdef PDEANIM_SLOTS
  vec2 phase = pdeFrame(0).xy; // this instance's slot: sin and cos of its swim phase
#else
  vec2 phase = vec2(pdeSinWt, pdeCosWt);
#endif
  float ca = 0.0;
  float cl = w.x * phase.x + w.y * phase.y;
  if (pdeRotate) {
    float g = w.z * phase.x + w.w * phase.y;
    float c = 1.0 / sqrt(1.0 + g * g);
    float sn = g * c;
    ca = (c - 1.0) * a.w - sn * rl;
    cl += sn * a.w + (c - 1.0) * rl;
  }
  return a.xyz + ca * pdeAxis + cl * pdeBend;
}
#endif
`;

// the mesh vertex: its clip vertex's position (read from the pass's texture, or evaluated here) in the
// mesh's frame; a smooth vertex (pdeVertex.y -1) gets the area-weighted normal of its clip vertex's ring
// (gpu.js ringTable: a closed fan of neighbours, or the (a, b) pairs of its triangles), any other its normal
// turned with the frame of its triangle (p, a, b)
const VERTEX_STAGE = `
#ifdef PDEANIM_VERTEX_STAGE
vec3 pdeAt(int v) {
#ifdef PDEANIM_PASS
  return pdeFetch(pdePosTex, v).xyz;
#else
  return pdeEval(v);
#endif
}
float pdeRingValue(int i) {
  vec4 t = pdeFetch(pdeRingTex, i >> 2);
  int c = i & 3;
  return c == 0 ? t.x : c == 1 ? t.y : c == 2 ? t.z : t.w;
}
vec3 pdeRingAt(int i, vec3 p) {
  return pdeAt(int(pdeRingValue(i) + 0.5)) - p;
}
vec3 pdeRingNormal(int v, vec3 p) {
  int first = int(pdeRingValue(2 * v) + 0.5);
  int count = int(pdeRingValue(2 * v + 1));
  vec3 n = vec3(0.0);
  if (count > 0) {
    vec3 e0 = pdeRingAt(first, p);
    vec3 ea = e0;
    for (int k = 1; k < count; k++) {
      vec3 eb = pdeRingAt(first + k, p);
      n += cross(ea, eb);
      ea = eb;
    }
    return n + cross(ea, e0);
  }
  for (int k = first; k < first - 2 * count; k += 2) n += cross(pdeRingAt(k, p), pdeRingAt(k + 1, p));
  return n;
}
void pdeCompute() {
#ifdef PDEANIM_CPU
  // the CPU evaluated this vertex (positions and normals in the mesh's frame)
  pdePosition = pdeCpuPosition;
  pdeNormal = pdeCpuNormal;
#else
#if defined(PDEANIM_SLOTS)
  pdeFrameBase = pdeFrameOffset + int(pdeSlot + 0.5) * pdeSlotTexels;
#elif defined(PDEANIM_KNOTS)
  pdeFrameBase = pdeFrameOffset;
#endif
  int v = int(pdeVertex.x + 0.5);
  int va = int(pdeVertex.y + 0.5);
  int vb = int(pdeVertex.z + 0.5);
  vec3 p = pdeAt(v);
  pdePosition = (pdeClipToLocal * vec4(p, 1.0)).xyz;
  pdeNormal = normal;
#ifndef PDEANIM_REST_NORMALS
  if (pdeVertex.y < -0.5) {
    vec3 n = pdeRingNormal(v, p);
    if (dot(n, n) > 0.0) pdeNormal = normalize(pdeNormalToLocal * n);
  } else if (va != v) {
    vec3 e1 = pdeAt(va) - p;
    vec3 e2 = pdeAt(vb) - p;
    vec3 t1 = normalize(e1);
    vec3 n = normalize(cross(e1, e2));
    pdeNormal = normalize(pdeNormalToLocal * (pdeNormalFrame.x * t1 + pdeNormalFrame.y * cross(n, t1)
      + pdeNormalFrame.z * n));
  }
#endif
#endif
}
#endif
`;

/**
 * GLSL declarations and functions (inserted after three.js's `#include <common>`). knotWidth (vertex stage):
 * the crowd variant, reading the shared knot table (gpu.js knotTables, rows of knotWidth) and a time row
 * (crowdRow) from texel pdeFrameOffset of the per-frame texture.
 */
export function glslHeader(
  layout,
  { normals = 'frame', stage = 'vertex', pass = false, cpu = false, slots = false, knotWidth = 0 } = {},
) {
  return `${defines(layout, { normals, stage, pass, cpu, slots, knotWidth })}\n${DECLARATIONS}${DYNAMIC_EVAL}${CYCLIC_EVAL}${VERTEX_STAGE}`;
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

/**
 * A three.js built-in material's vertex shader with the clip evaluation patched in: computed at the start of
 * main(), it replaces the position and normal after morphing and skinning, mixed by pdeInfluence (1: the clip
 * alone, 0: the mesh as it would be drawn without it). Throws when the shader lacks the chunks.
 */
export function patchVertexShader(vs, header) {
  for (const chunk of ['#include <common>', 'void main() {']) {
    if (!vs.includes(chunk)) throw new Error(`pdeanim: the material's vertex shader has no '${chunk}' to patch`);
  }
  // after skinning (built-in mesh materials), else after begin_vertex (points, custom shader materials)
  const place = ['#include <skinning_vertex>', '#include <begin_vertex>'].find((c) => vs.includes(c));
  if (!place) throw new Error("pdeanim: the material's vertex shader has no <skinning_vertex> or <begin_vertex> chunk");
  let out = vs
    .replace('#include <common>', `#include <common>\n${header}`)
    .replace('void main() {', 'void main() {\n\tif (pdeEnabled) pdeCompute();')
    .replace(place, `${place}\n\tif (pdeEnabled) transformed = mix(transformed, pdePosition, pdeInfluence);`);
  const normalPlace = ['#include <skinnormal_vertex>', '#include <beginnormal_vertex>'].find((c) => vs.includes(c));
  if (normalPlace) {
    out = out.replace(
      normalPlace,
      `${normalPlace}\n\tif (pdeEnabled) objectNormal = normalize(mix(objectNormal, pdeNormal, pdeInfluence));`,
    );
  }
  return out;
}
