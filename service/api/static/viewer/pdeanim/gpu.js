// GPU evaluation data (no three.js import): float textures, per-vertex attributes and per-frame uniforms of a
// clip (docs/format.md has the math; this mirrors the CPU path). The GLSL is in glsl.js.

import { CyclicEvaluator } from './cyclic.js';
import { DynamicEvaluator, clampedSplineTangents, timeIndex, vertexBase } from './dynamic.js';
import { ringNormals, triangleFrame, triangleQuality, vertexRings } from './geometry.js';
import { orthonormalBases } from './orthobasis.js';

export const TEXTURE_WIDTH = 4096;

/** The largest power of two <= width (texel addressing in the shader is then a shift and a mask). */
function pow2Width(width) {
  if (!(width >= 1)) throw new RangeError(`texture width must be >= 1, got ${width}`);
  return 2 ** Math.floor(Math.log2(width));
}

/**
 * The row length of a clip's textures: the smallest power of two at least the square root of the largest
 * texture's texels (so that a row of padding is small against the texture), at most width.
 */
export function fittedWidth(nTexels, width = TEXTURE_WIDTH) {
  const most = pow2Width(width);
  return Math.min(most, 2 ** Math.ceil(Math.log2(Math.max(1, Math.sqrt(nTexels)))));
}

/** A float RGBA texture of n texels, rows of w (a power of two): {data (padded), width, height}. */
function texture(nTexels, width) {
  const h = Math.max(1, Math.ceil(nTexels / width));
  return { data: new Float32Array(width * h * 4), width, height: h };
}

/**
 * The data textures and constants of a decoded clip (independent of the mesh and of three.js; plain typed
 * arrays, so that a Web Worker can build them and transfer them): {kind, rigid, spline, nCurves, nVertices,
 * nSegments, width, nDirect, coefficientTexels, curveTexels, gpuIndex, gpuCurve, textures: {vertex, frame},
 * r, tangents, direct: {q, base, curve}, maxHeight} (cyclic clips: {kind, nVertices, width, textures:
 * {vertex}, axis, bend, rotate, maxHeight}). width is at most the option's (fittedWidth).
 *
 * Dynamic clips. The GPU numbers the clip vertices gpuIndex[v] (the pdeVertex attribute and the evaluation
 * pass use these numbers): first the nDirect vertices of short curves (at most curveTexels vertices: their
 * positions take no more texels than the curve's coefficients would), whose positions the CPU writes into
 * the per-frame table each frame; then the others, with 4 texels each in the `vertex` texture: (GPU curve
 * gpuCurve[c], base xyz) and the row of each coordinate's orthonormal space basis (orthobasis.js). The
 * `frame` texture is the per-frame table that timeUniforms() rewrites: a position per direct vertex, then per
 * GPU curve and coordinate the four coefficients of the current frame in that basis (the time weights
 * applied to the segment's knots, and R, in float64 on the CPU), then for rigid clips the rows of R with the
 * centroid (R row i, c_i). The knots stay on the CPU (the clip's own array): the GPU holds one frame, not
 * every knot. r (Float64Array, C * 3 * 16) is each item's R; tangents (or null) the natural-spline tangents of
 * every knot's coefficients in the orthonormal bases (orthonormalTangents) for clips with items on the spline
 * (docs/format.md §3.5); direct the basis rows (q, nDirect * 12), bases (nDirect * 3) and curves of the
 * direct vertices in GPU order; timeIndex the CPU evaluator's index of time constants (dynamic.js).
 *
 * Clips with bones (format 1.1): every GPU vertex has two more texels (vertexTexels 6), the bone indices and
 * the normalised weights of its (up to 4) influences (unused ones weight 0), and the per-frame table ends,
 * from texel boneTexel, with 3 texels per bone: the rows [R_b | c_b + T_b - R_b c_b] of its transform at the
 * frame (evaluated on the CPU, B bones); the shader skins the rest position with them and adds the residual.
 * The vertices of curves whose residual is zero (every knot 0) cost no residual tables: numbered last, from
 * skinOnly, they have 3 texels each from texel skinTexel (rest, indices, weights), no basis rows, no curve
 * coefficients and no direct positions. A clip whose residual is zero everywhere (residual false) has only
 * those.
 */
export function gpuTables(clip, { width = TEXTURE_WIDTH, directMax = null } = {}) {
  if (clip.kind === 'cyclic-spine') {
    const rings = vertexRings(clip.faces, clip.rest);
    const ring = ringTable(rings);
    return cyclicTables(clip, fittedWidth(Math.max(clip.nVertices * 3, Math.ceil(ring.length / 4)), width), rings, ring);
  }
  const { nVertices: V, nCurves: C, nSegments: S, curveOf, offsets, rigid } = clip;
  const bones = clip.bones ?? null;
  const residual = bones === null || bones.residual;
  const spline = residual && (clip.timeModel ?? null) !== null; // null unless some item is on the natural spline
  const coefficientTexels = 3;
  const curveTexels = coefficientTexels + (rigid ? 3 : 0);
  // curves without residual (bone clips only; a streaming clip's head has no knots: none skipped)
  const zero = bones && clip.knots ? zeroCurves(clip.knots, C) : null;
  // directMax (tests): the most vertices of a direct curve (default: curveTexels, where they cost no more)
  const numbering = gpuNumbering(curveOf, offsets, directMax ?? curveTexels, zero);
  const { gpuIndex, gpuCurve, nDirect, nGpuCurves, skinOnly } = numbering;
  const vertexTexels = 4 + (bones ? 2 : 0);
  const skinTexel = (skinOnly - nDirect) * vertexTexels;
  const boneTexel = nDirect + nGpuCurves * curveTexels;
  const frameTexels = boneTexel + (bones ? bones.nBones * 3 : 0);
  const vertexTexelsAll = skinTexel + (V - skinOnly) * SKIN_TEXELS;
  const rings = vertexRings(clip.faces, clip.rest);
  const ring = ringTable(rings, gpuIndex);
  width = fittedWidth(Math.max(vertexTexelsAll, frameTexels, Math.ceil(ring.length / 4)), width);
  const base = vertexBase(clip);
  const { q, r } = residual ? orthonormalBases(clip) : { q: null, r: null };
  // per GPU vertex: (curve, base xyz), basis x, y, z, with bones its bone indices and weights; then the
  // skin-only vertices: (0, rest xyz), bone indices, bone weights
  const vertex = texture(vertexTexelsAll, width);
  const direct = vertexRows(clip, { ...numbering, vertexTexels, skinTexel, base, q }, vertex.data);
  // a streaming clip's (no knots in its head): tangents and time index per window (windowTables)
  const tangents = spline && clip.knots ? orthonormalTangents(clip, r) : null;
  const textures = { vertex, frame: texture(frameTexels, width), ring: ringTexture(ring, width) };
  return {
    kind: clip.kind,
    rigid: Boolean(rigid),
    spline,
    bones: bones !== null,
    residual,
    nBones: bones ? bones.nBones : 0,
    vertexTexels,
    skinOnly,
    skinTexel,
    boneTexel,
    nCurves: C,
    nVertices: V,
    nSegments: S,
    nDirect,
    coefficientTexels,
    width,
    curveTexels,
    gpuIndex,
    gpuCurve,
    textures,
    r,
    tangents,
    direct,
    rings,
    timeIndex: clip.knots ? timeIndex(clip) : null, // for the CPU evaluator (a worker makes it off the main thread)
    maxHeight: Math.max(...Object.values(textures).map((x) => x.height)),
  };
}

/**
 * The vertex texture's rows of the GPU vertices into d (vertexTexels per vertex: (GPU curve, base xyz), the
 * basis rows q when the clip has a residual, the bone texels with bones); returns the direct vertices' data
 * {q, base, curve, vertex} in GPU order.
 */
function vertexRows(clip, { gpuIndex, gpuCurve, nDirect, skinOnly, vertexTexels, skinTexel, base, q }, d) {
  const { curveOf, bones } = clip;
  const direct = {
    q: new Float32Array(nDirect * 12),
    base: new Float32Array(nDirect * 3),
    curve: new Int32Array(nDirect),
    vertex: new Int32Array(nDirect), // the clip vertex (bones: the CPU skins it each frame)
  };
  for (let v = 0; v < clip.nVertices; v++) {
    const g = gpuIndex[v];
    if (g < nDirect) {
      direct.curve[g] = curveOf[v];
      direct.vertex[g] = v;
      direct.base.set(base.subarray(v * 3, v * 3 + 3), g * 3);
      direct.q.set(q.subarray(v * 12, v * 12 + 12), g * 12);
      continue;
    }
    const skin = g >= skinOnly; // no residual: rest and bone texels only
    const o = skin ? (skinTexel + (g - skinOnly) * SKIN_TEXELS) * 4 : (g - nDirect) * vertexTexels * 4;
    d[o] = skin ? 0 : gpuCurve[curveOf[v]];
    d[o + 1] = base[v * 3];
    d[o + 2] = base[v * 3 + 1];
    d[o + 3] = base[v * 3 + 2];
    if (!skin) for (let k = 0; k < 12; k++) d[o + 4 + k] = q[v * 12 + k];
    if (bones) boneTexels(bones, v, d, o + ((skin ? SKIN_TEXELS : vertexTexels) - 2) * 4);
  }
  return direct;
}

/** Vertex v's bone indices, then its normalised weights (4 each, unused influences 0) into d[o..o+7]. */
function boneTexels(bones, v, d, o) {
  const K = bones.influences;
  for (let k = 0; k < K; k++) {
    d[o + k] = bones.index[v * K + k];
    d[o + 4 + k] = bones.weight[v * K + k];
  }
}

/**
 * The ring table (the area-weighted normals' one-rings, geometry.js vertexRings) in GPU vertex numbers
 * (gpuIndex; null: the clip's), as float32 values: values 2g, 2g + 1 are GPU vertex g's (first, count). A
 * closed fan (count > 0: each neighbour starts one triangle and ends one, in one cycle: an inner vertex of a
 * manifold mesh, seam duplicates counted as one vertex) lists its count neighbours n_i from value first, its
 * triangles being (g, n_i, n_i+1 mod count); any other ring (count < 0) lists its -count triangles' (a, b)
 * pairs. About 4 bytes per triangle corner and 8 per vertex.
 */
export function ringTable({ offset, pairs, group }, gpuIndex = null) {
  const V = offset.length - 1;
  const gpu = (v) => (gpuIndex ? gpuIndex[v] : v);
  const head = new Float32Array(V * 2);
  const body = [];
  const fan = [];
  for (let v = 0; v < V; v++) {
    const g = gpu(v);
    head[g * 2] = V * 2 + body.length;
    if (closedFan(pairs, offset[v] * 2, offset[v + 1] * 2, group, group[v], fan)) {
      head[g * 2 + 1] = fan.length;
      for (const n of fan) body.push(gpu(n));
    } else {
      head[g * 2 + 1] = -(offset[v + 1] - offset[v]);
      for (let j = offset[v] * 2; j < offset[v + 1] * 2; j++) body.push(gpu(pairs[j]));
    }
  }
  const values = new Float32Array(V * 2 + body.length);
  if (values.length >= 2 ** 24) throw new RangeError(`the clip's vertex rings need ${values.length} values (float32 indices: < 2^24)`);
  values.set(head);
  values.set(body, V * 2);
  return values;
}

/**
 * Whether the pairs [lo, hi) of a ring (vertices compared by group, none the centre's group p) make one
 * closed fan; if so its neighbours (group representatives), in order, are put in fan.
 */
function closedFan(pairs, lo, hi, group, p, fan) {
  fan.length = 0;
  const next = new Map();
  for (let j = lo; j < hi; j += 2) {
    const a = group[pairs[j]];
    const b = group[pairs[j + 1]];
    if (a === p || b === p || a === b || next.has(a)) return false;
    next.set(a, b);
  }
  const k = (hi - lo) / 2;
  if (k < 3) return false;
  let n = group[pairs[lo]];
  for (let i = 0; i < k; i++) {
    fan.push(n);
    n = next.get(n);
    if (n === undefined) return false;
  }
  // one cycle through all k: back at the start, every neighbour seen once
  return n === fan[0] && new Set(fan).size === k;
}

/** The `ring` texture of ringTable() values: four values a texel (value i: texel i / 4, component i % 4). */
function ringTexture(values, width) {
  const tex = texture(Math.ceil(values.length / 4), width);
  tex.data.set(values);
  return tex;
}

/** Texels per skin-only vertex (bone clips, a curve without residual): (0, rest xyz), indices, weights. */
const SKIN_TEXELS = 3;

/** Per curve (C) 1 when every knot of its items is 0 (knots (S+1, C, 3, 4)): it adds no residual. */
function zeroCurves(knots, C) {
  const zero = new Uint8Array(C).fill(1);
  for (let i = 0; i < knots.length; i++) if (knots[i] !== 0) zero[Math.floor(i / 12) % C] = 0;
  return zero;
}

/**
 * The GPU's numbering of a clip's vertices and curves: curves of at most `short` vertices are direct (the
 * CPU places their vertices), numbered first in clip order; the others follow in clip order, and their
 * curves get GPU curve numbers 0.. (gpuCurve, -1 for direct curves); last, from skinOnly, the vertices of
 * the curves zero marks (bone clips: no residual; gpuCurve -1 too).
 */
function gpuNumbering(curveOf, offsets, short, zero = null) {
  const V = curveOf.length;
  const C = offsets.length - 1;
  const gpuCurve = new Int32Array(C);
  const kind = new Uint8Array(C); // 0 direct, 1 GPU curve, 2 skin only
  const counts = [0, 0, 0];
  let nGpuCurves = 0;
  for (let c = 0; c < C; c++) {
    const n = offsets[c + 1] - offsets[c];
    kind[c] = zero?.[c] ? 2 : n <= short ? 0 : 1;
    gpuCurve[c] = kind[c] === 1 ? nGpuCurves++ : -1;
    counts[kind[c]] += n;
  }
  const next = [0, counts[0], counts[0] + counts[1]];
  const gpuIndex = new Int32Array(V);
  for (let v = 0; v < V; v++) gpuIndex[v] = next[kind[curveOf[v]]]++;
  return { gpuIndex, gpuCurve, nDirect: counts[0], nGpuCurves, skinOnly: counts[0] + counts[1] };
}

/**
 * The natural-spline tangents (docs/format.md §3.5) of every knot's coefficients in the items' orthonormal
 * bases, R k (Float32Array in the layout of clip.knots; one tridiagonal solve per clip, in float64). In that
 * basis they are on the scale of the values: the raw knots of ill-conditioned items can be 1e3 times larger
 * than R k, and float32 tangents of those would lose that factor when R is applied.
 */
function orthonormalTangents(clip, r) {
  const { knots, segmentT } = clip;
  // a streamable clip's window (docs/format.md §3.10): its known end tangents (null: a natural end)
  const ends = [clip.tangentFirst ?? null, clip.tangentLast ?? null];
  const cols = r.length / 4; // C * 3 items (R: 16 numbers each) of 4 coefficients: one track per coefficient
  const n = knots.length / cols;
  const out = new Float32Array(knots.length);
  // a block of tracks at a time (a float64 copy of every knot would be 8 bytes per knot coefficient)
  const B = Math.min(cols, 1024);
  const rk = new Float64Array(n * B);
  const tb = new Float64Array(n * B);
  for (let t0 = 0; t0 < cols; t0 += B) {
    const nb = Math.min(B, cols - t0);
    const values = nb === B ? rk : rk.subarray(0, n * nb);
    for (let s = 0; s < n; s++) {
      for (let k = 0; k < nb; k += 4) {
        const o = s * cols + t0 + k; // 4 coefficients of one item at knot s
        const R = ((t0 + k) / 4) * 16;
        for (let i = 0; i < 4; i++) {
          let acc = 0;
          for (let j = i; j < 4; j++) acc += r[R + i * 4 + j] * knots[o + j];
          values[s * nb + k + i] = acc;
        }
      }
    }
    const into = nb === B ? tb : tb.subarray(0, n * nb);
    const [first, last] = ends.map((e) => (e === null ? null : orthonormalEnds(e, r, t0, nb)));
    const tangents = clampedSplineTangents(segmentT, values, nb, first, last, into);
    for (let s = 0; s < n; s++) {
      for (let k = 0; k < nb; k++) out[s * cols + t0 + k] = tangents[s * nb + k];
    }
  }
  return out;
}

/** R Tc of one end's tangent coefficients (C x 3 x 4 float64) on tracks t0 .. t0 + nb - 1 (nb values). */
function orthonormalEnds(ends, r, t0, nb) {
  const out = new Float64Array(nb);
  for (let k = 0; k < nb; k += 4) {
    const o = t0 + k;
    const R = ((t0 + k) / 4) * 16;
    for (let i = 0; i < 4; i++) {
      let acc = 0;
      for (let j = i; j < 4; j++) acc += r[R + i * 4 + j] * ends[o + j];
      out[k + i] = acc;
    }
  }
  return out;
}

/**
 * The per-window tables of a streaming clip's window (a dynamic clip of its own, stream.js) given the
 * orthonormal bases r of its head's gpuTables(): {timeIndex, tangents (spline clips, else null)}.
 */
export function windowTables(windowClip, r, spline) {
  // (without mu, S x C x 3 float64 that the evaluators do not read: 7 MB a window on a 34k-vertex clip)
  const index = timeIndex(windowClip);
  delete index.mu;
  return { timeIndex: index, tangents: spline && r ? orthonormalTangents(windowClip, r) : null };
}

/**
 * The tables of gpuTables() with the clip and its CPU evaluator (whose per-segment time state fills the
 * per-curve table): what timeUniforms() and the shaders need. tables: gpuTables(clip) made elsewhere (in a
 * Web Worker), else made here; evaluator: the clip's, when the caller has one.
 */
export function gpuLayout(clip, { width = TEXTURE_WIDTH, tables = null, evaluator = null } = {}) {
  const t = tables ?? gpuTables(clip, { width });
  if (clip.kind === 'cyclic-spine') return { ...t, clip };
  return { ...t, clip, evaluator: evaluator ?? new DynamicEvaluator(clip, t.timeIndex), tableAt: [-1, NaN, NaN] };
}

/** Texels of one per-frame table of a layout (1 for cyclic clips: the swim phase's sine and cosine). */
export function frameTexels(layout) {
  if (layout.kind === 'cyclic-spine') return 1;
  return layout.boneTexel + layout.nBones * 3;
}

/**
 * A view of layout whose per-frame table is data (Float32Array of frameTexels(layout) * 4 or more): what
 * timeUniforms() needs to keep one more table at its own time (a player, or a slot of an instanced crowd),
 * sharing everything else, the CPU evaluator and the segment rows included.
 */
export function frameView(layout, data = null) {
  // (a crowd's view, without a table, reads no knot rows on the CPU)
  if (layout.kind !== 'cyclic-spine' && data !== null) {
    // made once on the layout, so that views read them instead of making their own
    // (a streaming clip's rows are made per view and window: its knots come and go)
    const streaming = Boolean(layout.clip.windowed);
    if (layout.residual && !streaming) segmentRows(layout, layout.rows?.seg >= 0 ? layout.rows.seg : 0);
    // a second view (another player's time): make every knot's row once rather than two per table switch
    layout.views = (layout.views ?? 0) + 1;
    if (layout.residual && layout.views === 2 && !streaming) layout.allRows = allKnotRows(layout);
    if (layout.bones) layout.boneRows ??= new Float64Array(layout.nBones * 12);
    if (layout.bones) layout.skinScratch ??= new Float64Array(3);
  }
  const view = Object.create(layout);
  view.tableAt = [-1, NaN, NaN];
  if (layout.clip.windowed) view.rows = null;
  if (data !== null) {
    view.textures = { ...layout.textures, frame: { data, width: layout.width, height: data.length / 4 / layout.width } };
  }
  return view;
}

/** GPU curves of a dynamic layout (curves with coefficients in the per-frame table: neither direct nor skin-only). */
function gpuCurveCount(layout) {
  return layout.curveTexels > 0 ? (layout.boneTexel - layout.nDirect) / layout.curveTexels : 0;
}

/**
 * The crowd's shared knot table of a dynamic layout, so that players at distinct times need no per-curve
 * table each: per knot j and GPU curve c the three texels of its coordinates' knot coefficients in the items'
 * orthonormal bases (R k, texel (j * curves + c) * 3 + w), for clips with spline items the same for the
 * spline tangents from tangentTexel, then per segment s and GPU curve c a texel giving each coordinate's time
 * pair: the index of its constant among the segment's distinct ones (the per-player time row holds their
 * pairs), -1 for spline items (the row's cubic weights); rigid clips then have per rigid knot and GPU curve
 * two texels (rotation vector, centroid) from rigidKnotTexel and per rigid segment and GPU curve (rotation
 * constant, centroid constant) from rigidMuTexel: the shader forms each curve's rigid motion (docs/format.md
 * §3.6). The direct vertices (whose per-frame table holds positions) are evaluated like the others in a
 * crowd: their curves follow the GPU curves, and their records (as the vertex texture's) start at
 * directTexel. {data, width, height, curves, tangentTexel, muTexel, rigidKnotTexel, rigidMuTexel,
 * directTexel, texels} (width: fittedWidth at most maxWidth; muTexel -1: every item on the spline, no indices). A frame's coefficients are then phi0 a + phi1 b
 * (or the cubic's four terms) in float32 on the GPU, where the per-player table has them in float64.
 */
export function knotTables(layout, maxWidth = TEXTURE_WIDTH) {
  const plan = knotTablePlan(layout, maxWidth);
  const tex = texture(plan.texels, plan.width);
  const table = { ...plan, ...tex };
  if (plan.curves > 0) writeKnotTable(layout, table, crowdCurves(layout));
  return table;
}

/**
 * The layout of knotTables() without its values: {curves, tangentTexel, muTexel, rigidKnotTexel,
 * rigidMuTexel, directTexel, texels, width, height, bytes}. muTexel is -1 when every item is on the natural
 * spline (no time pair to index: the shader takes the cubic weights for all).
 */
export function knotTablePlan(layout, maxWidth = TEXTURE_WIDTH) {
  const { nSegments: S, nDirect } = layout;
  // the crowd's curve numbers: the GPU curves', then the direct curves' (their vertices read records here)
  const curves = layout.residual ? gpuCurveCount(layout) + directCurves(layout).length : 0;
  const spline = layout.residual && layout.tangents !== null;
  const knotTexels = (S + 1) * curves * 3;
  const tangentTexel = knotTexels;
  const muStart = knotTexels * (spline ? 2 : 1);
  // the per-segment time-pair indices: not needed when every item is on the spline
  const items = spline ? layout.evaluator.spline : null;
  const mu = items === null || items.some((x) => x !== 1);
  const muTexel = mu ? muStart : -1;
  // rigid clips: per rigid knot and curve its rotation vector and centroid, per rigid segment their constants
  const rg = layout.rigid ? layout.clip.rigid : null;
  const Sr = rg ? rg.segmentT.length - 1 : 0;
  const rigidKnotTexel = muStart + (mu ? S * curves : 0);
  const rigidMuTexel = rigidKnotTexel + (rg ? (Sr + 1) * curves * 2 : 0);
  // the direct vertices' records, as the vertex texture's (vertexTexels each: curve and base, basis rows, bones)
  const directTexel = rigidMuTexel + Sr * curves;
  const VT = layout.vertexTexels ?? 4;
  const texels = Math.max(1, directTexel + (curves > 0 ? nDirect * VT : 0));
  const width = fittedWidth(texels, maxWidth);
  const height = Math.ceil(texels / width);
  const bytes = width * height * 16;
  return { curves, tangentTexel, muTexel, rigidKnotTexel, rigidMuTexel, directTexel, texels, width, height, bytes };
}

/** The values of knotTables() into table.data (crowdCurve: each clip curve's number in the table). */
function writeKnotTable(layout, table, crowdCurve) {
  const { nCurves: C, nSegments: S, nDirect } = layout;
  const { data: d, curves, tangentTexel, muTexel, rigidKnotTexel, rigidMuTexel, directTexel } = table;
  const spline = layout.tangents !== null;
  const rg = layout.rigid ? layout.clip.rigid : null;
  const Sr = rg ? rg.segmentT.length - 1 : 0;
  const VT = layout.vertexTexels ?? 4;
  const { knots } = layout.clip;
  const row = new Float64Array(C * 12);
  for (let j = 0; j <= S; j++) {
    orthonormalRow(layout.r, knots, j * C * 12, row);
    for (let c = 0; c < C; c++) {
      const cg = crowdCurve[c];
      if (cg < 0) continue;
      const o = (j * curves + cg) * 12;
      for (let k = 0; k < 12; k++) d[o + k] = row[c * 12 + k];
      if (spline) d.set(layout.tangents.subarray((j * C + c) * 12, (j * C + c + 1) * 12), tangentTexel * 4 + o);
    }
  }
  const { muIndex } = layout.evaluator;
  const items = spline ? layout.evaluator.spline : null;
  for (let s = 0; muTexel >= 0 && s < S; s++) {
    for (let c = 0; c < C; c++) {
      const cg = crowdCurve[c];
      if (cg < 0) continue;
      const o = (muTexel + s * curves + cg) * 4;
      for (let w = 0; w < 3; w++) {
        const i = c * 3 + w;
        d[o + w] = items !== null && items[i] === 1 ? -1 : muIndex[s * C * 3 + i];
      }
    }
  }
  for (let c = 0; rg && c < C; c++) {
    const cg = crowdCurve[c];
    if (cg < 0) continue;
    for (let j = 0; j <= Sr; j++) {
      const o = (rigidKnotTexel + (j * curves + cg) * 2) * 4;
      for (let w = 0; w < 3; w++) {
        d[o + w] = rg.rotKnots[(j * C + c) * 3 + w];
        d[o + 4 + w] = rg.transKnots[(j * C + c) * 3 + w];
      }
    }
    for (let j = 0; j < Sr; j++) {
      const o = (rigidMuTexel + j * curves + cg) * 4;
      d[o] = rg.rotMu[j * C + c];
      d[o + 1] = rg.transMu[j * C + c];
    }
  }
  const { q, base, curve, vertex } = layout.direct;
  const bones = layout.bones ? layout.clip.bones : null;
  for (let g = 0; g < nDirect; g++) {
    const o = (directTexel + g * VT) * 4;
    d[o] = crowdCurve[curve[g]];
    for (let w = 0; w < 3; w++) d[o + 1 + w] = base[g * 3 + w];
    for (let k = 0; k < 12; k++) d[o + 4 + k] = q[g * 12 + k];
    if (bones) boneTexels(bones, vertex[g], d, o + (VT - 2) * 4);
  }
}

/** Per clip curve its number in a crowd's knot table: GPU curves keep theirs, direct curves follow, others -1. */
function crowdCurves(layout) {
  const out = Int32Array.from(layout.gpuCurve);
  const first = gpuCurveCount(layout);
  directCurves(layout).forEach((c, k) => {
    out[c] = first + k;
  });
  return out;
}

/**
 * The per-player time row of a dynamic layout in a crowd (players at distinct times sharing knotTables()):
 * rigid clips at rigidTexel (rigid segment, its local time, 0, 0), bone clips the bones' rows (3 texels each) from boneTexel, then at timeTexel (segment, 0, 0, 0), the
 * spline's cubic weights, and the segment's distinct time pairs, two a texel. {rigidTexel, boneTexel,
 * timeTexel, texels}.
 */
export function crowdRow(layout) {
  const rigidTexel = 0;
  const boneTexel = rigidTexel + (layout.rigid && layout.residual ? 1 : 0);
  const timeTexel = boneTexel + (layout.nBones ?? 0) * 3;
  const widest = layout.residual ? layout.evaluator.uPhi0.length : 0;
  return { rigidTexel, boneTexel, timeTexel, texels: timeTexel + 2 + Math.ceil(widest / 2) };
}

const NO_CURVES = new Int32Array(0);

/** The distinct direct curves of a layout (cached), in GPU order: a crowd numbers them after the GPU curves. */
function directCurves(layout) {
  if (!layout.directCurves) layout.directCurves = Int32Array.from(new Set(layout.direct.curve));
  return layout.directCurves;
}

/**
 * Write the time row (crowdRow() row) of layout (a frameView: its own tableAt) at t into d from value o;
 * returns whether it was rewritten (as timeUniforms: not when t maps to the state already written).
 */
export function timeRow(layout, t, row, d, o) {
  if (!Number.isFinite(t)) throw new RangeError(`clip time must be a finite number, got ${t}`);
  const ev = layout.evaluator;
  const loc = ev.locate(t);
  const seg = loc[0];
  const last = layout.tableAt;
  if (seg === last[0] && loc[1] === last[1] && ((!layout.rigid && !layout.bones) || loc[2] === last[2])) return false;
  last[0] = seg;
  last[1] = loc[1];
  last[2] = loc[2];
  // rigid clips: the shader forms every curve's rigid motion (the CPU only locates the rigid segment)
  ev.segmentState(layout.rigid ? NO_CURVES : null);
  if (layout.bones) writeBones(layout, ev, d, o / 4 + row.boneTexel);
  if (!layout.residual) return true;
  const T = o + row.timeTexel * 4;
  d[T] = seg;
  if (layout.spline) for (let i = 0; i < 4; i++) d[T + 4 + i] = ev.cubicWeights[i];
  const n = ev.muStart[seg + 1] - ev.muStart[seg];
  for (let k = 0; k < n; k++) {
    d[T + 8 + k * 2] = ev.uPhi0[k];
    d[T + 9 + k * 2] = ev.uPhi1[k];
  }
  if (layout.rigid) {
    d[o + row.rigidTexel * 4] = ev.rigidLoc[0];
    d[o + row.rigidTexel * 4 + 1] = ev.rigidLoc[1];
  }
  return true;
}

/** Bytes of the data textures of gpuTables() (what the GPU holds for the clip, whatever the mesh). */
export function textureBytes(tables) {
  return Object.values(tables.textures).reduce((n, t) => n + t.data.byteLength, 0);
}

/** Bytes of the evaluation pass's position texture (RGBA float32, a texel per clip vertex, rows of width). */
export function passBytes(layout) {
  return layout.width * Math.max(1, Math.ceil(layout.nVertices / layout.width)) * 16;
}

/** Bytes of the shader's per-vertex attributes (gpuAttributes: pdeVertex 3 float32, pdeNormalFrame 3 int16). */
export const ATTRIBUTE_BYTES_PER_VERTEX = 3 * 4 + 3 * 2;

/**
 * GPU bytes of a clip played on meshVertices mesh vertices (default: the clip's): its data textures, the
 * evaluation pass's texture (pass: default true) and the shader's attributes; what ClipPlayer.gpuBytes
 * reports for one mesh.
 */
export function gpuBytes(layout, { meshVertices = layout.nVertices, pass = true } = {}) {
  return textureBytes(layout) + (pass ? passBytes(layout) : 0) + meshVertices * ATTRIBUTE_BYTES_PER_VERTEX;
}

function cyclicTables(clip, width, rings, ring) {
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
    textures: { vertex, ring: ringTexture(ring, width) },
    rings,
    maxHeight: Math.max(vertex.height, Math.ceil(ring.length / 4 / width)),
    axis: ev.axis,
    bend: ev.bend,
    rotate: ev.rotate,
  };
}

/**
 * The state at t: returns the uniforms {seg, sw, cw} (segment of the dynamic clip; sin and cos of the swim
 * phase of a cyclic one) and `changed`: whether the per-frame table layout.textures.frame.data was rewritten
 * (dynamic clips; upload it only then). The table is left as it is when t maps to the same segment, local
 * time (and rigid time) as at the previous call; otherwise each distinct time constant of the segment is
 * evaluated once (fitted clips have a few hundred, most items are linear) and the table written (writeFrame:
 * weighted sums of the segment's knots in the orthonormal bases, segmentRows, made once per segment).
 */
export function timeUniforms(layout, t) {
  if (!Number.isFinite(t)) throw new RangeError(`clip time must be a finite number, got ${t}`);
  const clip = layout.clip;
  if (clip.kind === 'cyclic-spine') {
    const wt = 2 * Math.PI * clip.swim.frequency * (t * clip.period);
    return { seg: 0, sw: Math.sin(wt), cw: Math.cos(wt), changed: true };
  }
  const loc = layout.evaluator.locate(t);
  // a streaming clip's evaluator locates t in a window: that window's evaluator (segments numbered in it)
  const ev = layout.evaluator.current ?? layout.evaluator;
  const seg = loc[0];
  const last = layout.tableAt ?? (layout.tableAt = [-1, NaN, NaN]);
  if (seg === last[0] && loc[1] === last[1] && ev === last[3] && ((!layout.rigid && !layout.bones) || loc[2] === last[2])) {
    return { seg, sw: 0, cw: 0, changed: false };
  }
  last[0] = seg;
  last[1] = loc[1];
  last[2] = loc[2];
  last[3] = ev;
  ev.segmentState();
  writeFrame(layout, ev, seg, layout.textures.frame.data);
  return { seg, sw: 0, cw: 0, changed: true };
}

/** R k of every item's 4 knot coefficients at one knot (knots from offset o, C * 12 of them) into out (float64). */
function orthonormalRow(r, knots, o, out) {
  for (let i = 0; i < out.length; i += 4) {
    const R = i * 4; // item i / 4, 16 numbers of R each
    const k0 = knots[o + i];
    const k1 = knots[o + i + 1];
    const k2 = knots[o + i + 2];
    const k3 = knots[o + i + 3];
    out[i] = r[R] * k0 + r[R + 1] * k1 + r[R + 2] * k2 + r[R + 3] * k3;
    out[i + 1] = r[R + 5] * k1 + r[R + 6] * k2 + r[R + 7] * k3;
    out[i + 2] = r[R + 10] * k2 + r[R + 11] * k3;
    out[i + 3] = r[R + 15] * k3;
  }
  return out;
}

/**
 * What a segment's frames share, made when t enters another segment: the knots at both ends in the items'
 * orthonormal bases (a, b: C * 12 float64) and, for clips with spline items, the spline tangents there (tl,
 * th, already in that basis), so that a frame's coefficients are a weighted sum of rows per item.
 */
function segmentRows(layout, seg, ev = layout.evaluator) {
  const C = layout.nCurves;
  // a streaming clip's window: its own knots and tangents (windowTables), segments numbered in the window
  const windowed = ev.clip.s0 !== undefined;
  // (a window's tangents: made by the worker with its tables, else here on first use)
  const tangents = !windowed ? layout.tangents : layout.spline ? (ev.windowTangents ??= orthonormalTangents(ev.clip, layout.r)) : null;
  const spline = layout.spline && tangents !== null;
  const rows = (layout.rows ??= {
    seg: -1,
    a: new Float64Array(C * 12),
    b: new Float64Array(C * 12),
    tl: spline ? new Float64Array(C * 12) : null,
    th: spline ? new Float64Array(C * 12) : null,
    y: new Float64Array(C * 12), // the frame's coefficients
  });
  if (rows.seg === seg && rows.ev === ev) return rows;
  if (layout.allRows && !windowed) {
    // players at other times: every knot's row made once (allKnotRows), read in place
    const n = C * 12;
    const { knots: k, tangents: tg } = layout.allRows;
    [rows.a, rows.b] = [k.subarray(seg * n, (seg + 1) * n), k.subarray((seg + 1) * n, (seg + 2) * n)];
    if (spline) [rows.tl, rows.th] = [tg.subarray(seg * n, (seg + 1) * n), tg.subarray((seg + 1) * n, (seg + 2) * n)];
    rows.seg = seg;
    rows.ev = ev;
    return rows;
  }
  const { knots } = ev.clip;
  const row = (j, out, tangentsOut) => {
    orthonormalRow(layout.r, knots, j * C * 12, out);
    // a float64 copy: every row the frame loop reads is then of one type
    if (spline) tangentsOut.set(tangents.subarray(j * C * 12, (j + 1) * C * 12));
  };
  if (rows.seg >= 0 && seg === rows.seg + 1 && rows.ev === ev) {
    // playing forward: the knot at the segment's start is the previous segment's end
    [rows.a, rows.b, rows.tl, rows.th] = [rows.b, rows.a, rows.th, rows.tl];
    row(seg + 1, rows.b, rows.th);
  } else {
    row(seg, rows.a, rows.tl);
    row(seg + 1, rows.b, rows.th);
  }
  rows.seg = seg;
  rows.ev = ev;
  return rows;
}

/**
 * Every knot's row (R k of its items, float64) and, for spline clips, its tangents in float64: what
 * segmentRows reads in place once several players show other times (memory: 2 or 4 x the knots' float32).
 */
function allKnotRows(layout) {
  const n = layout.nCurves * 12;
  const { knots } = layout.clip;
  const S1 = knots.length / n;
  const rows = new Float64Array(knots.length);
  for (let j = 0; j < S1; j++) orthonormalRow(layout.r, knots, j * n, rows.subarray(j * n, (j + 1) * n));
  return { knots: rows, tangents: layout.tangents ? Float64Array.from(layout.tangents) : null };
}

/**
 * Every item's coefficients of the frame in its orthonormal basis into rows.y (float64): phi0, phi1 on the
 * segment's knots; spline items w_0..w_3 on T_s, P_s, P_s+1, T_s+1.
 */
function frameCoefficients(layout, ev, seg, rows) {
  const n = layout.nCurves * 3;
  const { uPhi0, uPhi1, muIndex } = ev;
  const spline = layout.spline ? ev.spline : null;
  const cw = ev.cubicWeights;
  // the segment's spline weights (the same for every spline item), read once: not destructured per item
  const wl = spline !== null ? cw[0] : 0;
  const w0 = spline !== null ? cw[1] : 0;
  const w1 = spline !== null ? cw[2] : 0;
  const wh = spline !== null ? cw[3] : 0;
  const { a, b, tl, th, y } = rows;
  for (let i = 0, mu = seg * n; i < n; i++) {
    const j = i * 4;
    if (spline !== null && spline[i] === 1) {
      y[j] = wl * tl[j] + w0 * a[j] + w1 * b[j] + wh * th[j];
      y[j + 1] = wl * tl[j + 1] + w0 * a[j + 1] + w1 * b[j + 1] + wh * th[j + 1];
      y[j + 2] = wl * tl[j + 2] + w0 * a[j + 2] + w1 * b[j + 2] + wh * th[j + 2];
      y[j + 3] = wl * tl[j + 3] + w0 * a[j + 3] + w1 * b[j + 3] + wh * th[j + 3];
    } else {
      const m = muIndex[mu + i];
      const p0 = uPhi0[m];
      const p1 = uPhi1[m];
      y[j] = p0 * a[j] + p1 * b[j];
      y[j + 1] = p0 * a[j + 1] + p1 * b[j + 1];
      y[j + 2] = p0 * a[j + 2] + p1 * b[j + 2];
      y[j + 3] = p0 * a[j + 3] + p1 * b[j + 3];
    }
  }
  return y;
}

/**
 * The per-frame table d of segment seg at the evaluator's time state: each direct vertex its position (basis
 * row . the frame's coefficients + base, then its curve's rigid motion, in float64), then per GPU curve its
 * three coefficient texels and, for rigid clips, its rigid rows.
 */
function writeFrame(layout, ev, seg, d) {
  if (layout.bones) writeBones(layout, ev, d, layout.boneTexel);
  if (!layout.residual) return;
  const y = frameCoefficients(layout, ev, seg, segmentRows(layout, seg, ev));
  writeDirect(layout, ev, y, d, 0);
  const { nDirect, gpuCurve } = layout;
  const rot = layout.rigid ? ev.rot : null;
  const trans = layout.rigid ? ev.trans : null;
  const K = layout.curveTexels * 4;
  for (let c = 0; c < layout.nCurves; c++) {
    const cg = gpuCurve[c];
    if (cg < 0) continue;
    const o = nDirect * 4 + cg * K;
    for (let k = 0; k < 12; k++) d[o + k] = y[c * 12 + k];
    if (rot === null) continue;
    for (let i = 0; i < 3; i++) {
      d[o + 12 + i * 4] = rot[c * 9 + i * 3];
      d[o + 13 + i * 4] = rot[c * 9 + i * 3 + 1];
      d[o + 14 + i * 4] = rot[c * 9 + i * 3 + 2];
      d[o + 15 + i * 4] = trans[c * 3 + i];
    }
  }
}

/**
 * Each direct vertex's position (basis row . its curve's coefficients y + base, then its curve's rigid motion,
 * in float64) into d from value o (a texel per vertex).
 */
function writeDirect(layout, ev, y, d, o) {
  const { nDirect, direct } = layout;
  const { q, base, curve } = direct;
  const rot = layout.rigid ? ev.rot : null;
  const trans = layout.rigid ? ev.trans : null;
  const skinned = layout.bones ? (layout.skinScratch ??= new Float64Array(3)) : null;
  for (let g = 0; g < nDirect; g++) {
    const c = curve[g];
    const Q = g * 12;
    const Y = c * 12;
    const p = o + g * 4;
    // bones: the vertex's skinned rest position (float64) in place of its base
    const b = skinned === null ? base : ev.bones.skinVertex(layout.clip.rest, direct.vertex[g], skinned);
    const bo = skinned === null ? g * 3 : 0;
    for (let w = 0; w < 3; w++) {
      const k = Q + w * 4;
      const j = Y + w * 4;
      d[p + w] = b[bo + w] + (q[k] * y[j] + q[k + 1] * y[j + 1] + q[k + 2] * y[j + 2] + q[k + 3] * y[j + 3]);
    }
    if (rot !== null) {
      const x = d[p];
      const yy = d[p + 1];
      const z = d[p + 2];
      const R = c * 9;
      for (let i = 0; i < 3; i++) {
        d[p + i] = rot[R + i * 3] * x + rot[R + i * 3 + 1] * yy + rot[R + i * 3 + 2] * z + trans[c * 3 + i];
      }
    }
  }
}

/** The bones' rows [R_b | c_b + T_b - R_b c_b] at the evaluator's time into d from texel `texel`. */
function writeBones(layout, ev, d, texel) {
  const rows = ev.bones.affine((layout.boneRows ??= new Float64Array(layout.nBones * 12)));
  d.set(rows, texel * 4);
}

/** A mesh normal within this angle (cos) of its clip vertex's area-weighted rest normal is smooth-shaded. */
export const SMOOTH_COS = Math.cos((30 * Math.PI) / 180);

/**
 * Per mesh vertex attributes: pdeVertex (n, 3) and pdeNormalFrame (n, 3). A smooth vertex (its rest normal
 * within 30 degrees of clipNormals, its clip vertex's area-weighted rest normal: the usual smooth-shaded
 * vertex) is (clip vertex, -1, -1): its normal at a frame is its clip vertex's area-weighted normal (the ring
 * table). Any other (a hard edge's split vertex, a normal the source set by hand) is the clip vertex and two
 * neighbours (the corners of its best-shaped triangle) with pdeNormalFrame its normal in that triangle's
 * rest frame, so that it turns with the triangle. vertexMap (n) maps mesh vertices to clip vertices;
 * positions/normals (n * 3) are the mesh's; index the triangle list (null for non-indexed geometry);
 * clipNormals (V * 3, null: none smooth). A vertex without a usable triangle gets neighbours equal to itself
 * (its normal is then kept as it is).
 */
export function meshAttributes({ vertexMap, positions, normals, index, clipNormals = null }) {
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
    if (normals && clipNormals && isSmooth(normals, i, clipNormals, vertexMap[i])) {
      pdeVertex[i * 3] = vertexMap[i];
      pdeVertex[i * 3 + 1] = -1;
      pdeVertex[i * 3 + 2] = -1;
      continue;
    }
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

/** Whether mesh normal i lies within 30 degrees of clip vertex v's area-weighted rest normal. */
function isSmooth(normals, i, clipNormals, v) {
  const x = normals[i * 3];
  const y = normals[i * 3 + 1];
  const z = normals[i * 3 + 2];
  const d = x * clipNormals[v * 3] + y * clipNormals[v * 3 + 1] + z * clipNormals[v * 3 + 2];
  return d >= SMOOTH_COS * Math.hypot(x, y, z);
}

/**
 * The attributes the shader reads, from meshAttributes(): pdeVertex with the GPU's vertex numbers (gpuIndex
 * of gpuTables(); null: the clip's), and pdeNormalFrame as normalised int16 (a unit vector: 3e-5 is plenty
 * for shading, at half the bytes). {pdeVertex: Float32Array, pdeNormalFrame: Int16Array}.
 */
export function gpuAttributes(attrs, gpuIndex = null) {
  const pdeVertex = gpuIndex ? attrs.pdeVertex.map((v) => (v < 0 ? v : gpuIndex[v])) : Float32Array.from(attrs.pdeVertex);
  const pdeNormalFrame = new Int16Array(attrs.pdeNormalFrame.length);
  for (let i = 0; i < pdeNormalFrame.length; i++) {
    pdeNormalFrame[i] = Math.round(Math.max(-1, Math.min(1, attrs.pdeNormalFrame[i])) * 32767);
  }
  return { pdeVertex, pdeNormalFrame };
}

/**
 * CPU counterpart of the shader's normals: mesh normals (n * 3) from clip positions (V * 3) and the mesh
 * attributes of meshAttributes(): smooth vertices take their clip vertex's normal in clipNormals (V * 3,
 * ringNormals() of the positions; a zero one keeps the rest normal), the others turn with their triangle;
 * vertices without a frame keep restNormals. Allocation-free after the first call (per frame).
 */
export function frameNormals(clipPositions, attrs, restNormals, out, clipNormals = null) {
  const { pdeVertex, pdeNormalFrame } = attrs;
  const fr = (frameNormals.scratch ??= new Float64Array(9));
  for (let i = 0; i < pdeVertex.length; i += 3) {
    const p = pdeVertex[i];
    const a = pdeVertex[i + 1];
    const s = a < 0 ? p * 3 : -1;
    if (s >= 0 && (clipNormals[s] !== 0 || clipNormals[s + 1] !== 0 || clipNormals[s + 2] !== 0)) {
      out[i] = clipNormals[s];
      out[i + 1] = clipNormals[s + 1];
      out[i + 2] = clipNormals[s + 2];
      continue;
    }
    if (a === p || a < 0) {
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

/**
 * The clip's area-weighted vertex normals (V * 3) at positions (V * 3), over the tables' rings (only those of
 * vertices, a list of clip vertices, when given).
 */
export function clipNormals(tables, positions, out = new Float32Array(positions.length), vertices = null) {
  return ringNormals(positions, tables.rings, out, vertices);
}

/** The clip vertices of the smooth mesh vertices of meshAttributes() (each once): those frameNormals reads. */
export function smoothVertices({ pdeVertex }) {
  const seen = new Set();
  for (let i = 0; i < pdeVertex.length; i += 3) if (pdeVertex[i + 1] < 0) seen.add(pdeVertex[i]);
  return Int32Array.from(seen);
}
export { glslHeader, glslPassMain, patchVertexShader } from './glsl.js';
