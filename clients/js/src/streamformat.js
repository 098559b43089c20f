// Read the streamable layout of a dynamic-PDE coefficients part (format 1.2, feature "stream", docs/format.md
// §3.10): a head (the usual header with a "stream" index, the per-clip arrays) followed by the time windows in
// time order, each a container of its own that decodes with the head alone. The head decodes into a "shell"
// (everything but the per-segment data) and each window into a dynamic clip of its own (stream.js plays them).

import { ClipFormatError, MAGIC, checkBounded, checkFormatVersion, decodeContainer } from './container.js';
import { decodeBones, hasBones } from './bones.js';
import { clampedSplineTangents, parts, vertexBase } from './dynamic.js';

const { need, count, topologyArrays, curveOfVertices, toVertexOrder, nondecreasing, familyOf, timeModelOf, checkFinite } = parts;

/** The feature a streamable coefficients part requires. */
export const STREAM_FEATURE = 'stream';

/** Whether a coefficients (or CLIP file) header is of the streamable layout. */
export function isStreamHeader(header) {
  return Array.isArray(header?.required) && header.required.includes(STREAM_FEATURE);
}

/**
 * The prefix of container bytes: {headerLength H, dataStart 16 + H} once the first 16 bytes are in (null
 * before), checked (magic, version).
 */
export function containerPrefix(data) {
  const bytes = asBytes(data);
  if (bytes.byteLength < 16) return null;
  for (let i = 0; i < 8; i++) {
    if (bytes[i] !== MAGIC.charCodeAt(i)) throw new ClipFormatError('not a pdeanim container (bad magic bytes)');
  }
  const view = new DataView(bytes.buffer, bytes.byteOffset, 16);
  if (view.getUint32(8, true) !== 1) throw new ClipFormatError(`unsupported container version ${view.getUint32(8, true)}`);
  const H = view.getUint32(12, true);
  return { headerLength: H, dataStart: 16 + H };
}

/** The JSON header of container bytes holding at least its first 16 + H bytes. */
export function containerHeader(data) {
  const bytes = asBytes(data);
  const { dataStart } = containerPrefix(bytes);
  let header;
  try {
    header = JSON.parse(new TextDecoder('utf-8', { fatal: true }).decode(bytes.subarray(16, dataStart)));
  } catch (err) {
    throw new ClipFormatError(`container header is not valid JSON: ${err.message}`);
  }
  if (header === null || typeof header !== 'object' || Array.isArray(header)) {
    throw new ClipFormatError('container header is not a JSON object');
  }
  return header;
}

/**
 * The window index of a streamable coefficients header (§3.10), checked: [{index, array, offset, nbytes
 * (the window's bytes: data start + offset ..), t0, t1, a, b (first and last knot), boneKnots}]. Throws
 * ClipFormatError ("damaged stream index") for an index that breaks its rules.
 */
export function streamIndex(header) {
  const bad = (why) => new ClipFormatError(`damaged stream index: ${why}`);
  const st = header?.stream;
  const S = header?.n_segments;
  if (!st || typeof st !== 'object' || !Array.isArray(st.windows)) throw bad("no 'stream' object with 'windows'");
  const W = st.windows.length;
  if (!(W >= 1) || st.n_windows !== W) throw bad(`n_windows ${JSON.stringify(st.n_windows)} for ${W} windows`);
  if (!Number.isInteger(S) || S < 1) throw bad(`n_segments must be a positive integer, got ${JSON.stringify(S)}`);
  const table = header.arrays ?? {};
  const out = [];
  for (let i = 0; i < W; i++) {
    const w = st.windows[i];
    const [t0, t1] = Array.isArray(w?.t) ? w.t : [];
    const [a, b] = Array.isArray(w?.knots) ? w.knots : [];
    const entry = table[w?.array];
    if (w?.array !== `window_${i}`) throw bad(`window ${i} is not in array window_${i}`);
    if (!entry || entry.dtype !== '<u1' || Object.hasOwn(entry, 'encoding') || entry.offset !== w.offset || entry.nbytes !== w.nbytes) {
      throw bad(`window ${i}'s offset and size do not match its array`);
    }
    if (!Number.isInteger(w.offset) || !Number.isInteger(w.nbytes) || w.offset < 0 || w.nbytes < 16) {
      throw bad(`window ${i} has a bad offset or size`);
    }
    if (!Number.isInteger(a) || !Number.isInteger(b) || !(b > a)) throw bad(`window ${i}'s knots must be integers a < b`);
    if (!(typeof t0 === 'number' && typeof t1 === 'number' && t0 < t1)) throw bad(`window ${i}'s times must rise`);
    const prev = out[i - 1];
    if (prev) {
      if (a !== prev.b || t0 !== prev.t1) throw bad(`window ${i} does not start where window ${i - 1} ends`);
      if (w.offset <= prev.offset) throw bad(`window ${i} lies before window ${i - 1}`);
    } else if (a !== 0 || t0 !== 0) throw bad('window 0 must start at knot 0 and t = 0');
    out.push({ index: i, array: w.array, offset: w.offset, nbytes: w.nbytes, t0, t1, a, b, boneKnots: w.bone_knots ?? null });
  }
  const last = out[W - 1];
  if (last.b !== S || last.t1 !== 1) throw bad(`the last window must end at knot ${S} and t = 1`);
  return out;
}

/**
 * Decode the head of a streamable coefficients part (its first `16 + H + index[0].offset` bytes at least, or
 * the whole part) with its topology part into the clip's shell: the decoded dynamic clip less its
 * per-segment data (segmentT, m, family, knots are per window), with `index` (streamIndex) and `header`.
 */
export function decodeStreamHead(topology, head) {
  const topo = decodeContainer(topology);
  if (topo.header.part !== 'topology') {
    throw new ClipFormatError(`expected a topology part, got ${JSON.stringify(topo.header.part)}`);
  }
  const full = containerHeader(head);
  const index = streamIndex(full);
  const coef = decodeContainer(head, { skip: (name) => /^window_\d+$/.test(name) });
  const ch = coef.header;
  if (ch.part !== 'coefficients') throw new ClipFormatError(`expected a coefficients part, got ${JSON.stringify(ch.part)}`);
  if (ch.kind !== 'dynamic-pde') throw new ClipFormatError(`a streamable clip must be dynamic-pde, got ${JSON.stringify(ch.kind)}`);
  checkFormatVersion(topo.header, 'topology');
  checkFormatVersion(ch, 'coefficients');
  const th = topo.header;
  const V = count(th, 'n_vertices', 'topology');
  const t = topologyArrays(th, topo.arrays, V);
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
  const ca = coef.arrays;
  const S = count(ch, 'n_segments', 'coefficients');
  const motion = parts.motionOf(ch);
  const spaceKind = need(ca, 'space_kind', [C, 3], 'coefficients', ['<u1']).data;
  for (let i = 0; i < spaceKind.length; i++) if (spaceKind[i] > 1) throw new ClipFormatError('space kinds must be 0 or 1');
  const timeModel = need(ca, 'time_model', [C, 3], 'coefficients', ['<u1']).data;
  if (timeModel.some((x) => x > 1)) throw new ClipFormatError('coefficients time_model must be 0 (paper) or 1 (natural spline)');
  const r = ch.knot_rank;
  if (!Number.isInteger(r) || r < 0 || r > S + 1) {
    throw new ClipFormatError(`coefficients knot_rank must be an integer in 0..${S + 1}, got ${JSON.stringify(r)}`);
  }
  const shell = {
    kind: 'dynamic-pde',
    windowed: true,
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
    frameTimes: need(ca, 'frame_times', [null], 'coefficients', ['<f8']).data,
    spaceKind,
    // the family of the first segment (space kind only): vertexBasis and the GPU's bases read family % 2
    family: Uint8Array.from(spaceKind),
    D: need(ca, 'D', [C, 3], 'coefficients', ['<f4']).data,
    timeModel: timeModel.includes(1) ? timeModel : null,
    knotWeights: r ? need(ca, 'knot_weights', [r, C, 3, 4], 'coefficients', ['<u4']).data : null,
    // one knot step for the whole clip (else each window has its own, (2, C, 3))
    knotStep: ca.knot_step ? need(ca, 'knot_step', [C, 3], 'coefficients', ['<f4']).data : null,
    knotDifferences: knotDifferences(ch),
    motion,
    looping: Boolean(ch.looping),
    rigid: motion === 'rigid' ? parts.rigidTracks(ca, C) : null,
    bones: null,
    header: ch,
    topologyHeader: th,
    topologyId: ch.topology_id ?? null,
    index,
  };
  if (hasBones(ch)) Object.assign(shell, headBones(ch, ca, V, motion));
  shell.base = vertexBase(shell);
  return shell;
}

function asBytes(data) {
  if (data instanceof Uint8Array) return data;
  if (data instanceof ArrayBuffer) return new Uint8Array(data);
  if (ArrayBuffer.isView(data)) return new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  throw new ClipFormatError('expected an ArrayBuffer or a typed array');
}

/** The byte range [from, to) of window i in the part (offsets from the part's first byte). */
export function windowRange(headerLength, w) {
  const from = 16 + headerLength + w.offset;
  return [from, from + w.nbytes];
}

const BONE_HEAD = ['bone_pivot', 'bone_index', 'bone_weight', 'bone_time_model', 'bone_step'];

/** A probe of the bone tracks' shapes: §3.9's checks run on the head's arrays with these (B bones, Sb segments). */
function boneProbe(head, B, Sb, m = null, knots = null) {
  return {
    ...head,
    bone_segment_t: { dtype: '<f8', shape: [Sb + 1], data: Float64Array.from({ length: Sb + 1 }, (_, j) => j / Sb) },
    bone_m: m ?? { dtype: '<f4', shape: [Sb, B, 6], data: new Float32Array(Sb * B * 6) },
    bone_knots: knots ?? { dtype: '<u4', shape: [B, 6, Sb + 1], data: new Uint32Array(B * 6 * (Sb + 1)) },
  };
}

/**
 * The head's bone layer (format 1.1 with "stream"): its per-clip arrays checked as §3.9 checks them; the
 * tracks are per window. The residual counts as present (the GPU tables of every window are then alike).
 */
function headBones(ch, ca, V, motion) {
  const head = Object.fromEntries(BONE_HEAD.filter((k) => ca[k]).map((k) => [k, ca[k]]));
  const B = ch.n_bones;
  if (!Number.isInteger(B) || B < 1) throw new ClipFormatError(`bone layer header key 'n_bones' must be a positive integer, got ${JSON.stringify(B)}`);
  const layer = decodeBones(ch, boneProbe(head, B, 1), V, motion, new Float32Array(0));
  return { bones: { ...layer, residual: true, segmentT: null, m: null, knots: null, tangents: null }, boneHead: head };
}

/** Window i's bone layer (its own bone tracks, self-contained; spline channels with both ends known). */
function windowBones(shell, w, wh, wa, label) {
  const [j0, j1] = Array.isArray(w.boneKnots) ? w.boneKnots : [];
  if (!(Number.isInteger(j0) && Number.isInteger(j1) && j1 > j0) || wh.first_bone_knot !== j0 || wh.last_bone_knot !== j1) {
    throw new ClipFormatError(`damaged stream index: ${label}'s bone knots disagree with the index`);
  }
  const B = shell.bones.nBones;
  const Sb = j1 - j0;
  const seg = need(wa, 'bone_segment_t', [Sb + 1], label, ['<f8']).data;
  let rising = seg[0] <= w.t0 && seg[Sb] >= w.t1;
  for (let j = 1; j <= Sb && rising; j++) rising = seg[j] > seg[j - 1];
  if (!rising) throw new ClipFormatError(`${label}'s bone_segment_t must increase strictly and cover ${w.t0}..${w.t1}`);
  const ch = shell.header;
  const layer = decodeBones(ch, boneProbe(shell.boneHead, B, Sb, wa.bone_m, wa.bone_knots), shell.nVertices, shell.motion, new Float32Array(0));
  layer.segmentT = Float64Array.from(seg);
  layer.residual = true;
  if (layer.tangents) {
    const n = B * 6;
    const ends = need(wa, 'bone_tangents', [2, B, 6], label, ['<f8']).data;
    layer.tangents = clampedSplineTangents(layer.segmentT, layer.knots, n, ends.slice(0, n), ends.slice(n, 2 * n));
  }
  return layer;
}

/** The coefficients header's knot_differences (1 or 2). */
function knotDifferences(ch) {
  const order = ch.knot_differences;
  if (order !== 1 && order !== 2) {
    throw new ClipFormatError(`coefficients knot_differences must be 1 or 2, got ${JSON.stringify(order)}`);
  }
  return order;
}

const unzig = (q) => (q >>> 1) ^ -(q & 1);

/**
 * The state window i hands to window i + 1 (docs/format.md §3.10), or that a window holds itself (start_*
 * arrays): {codes (C*12 integers p at its last knot), slopes (order 2: p[b] - p[b-1], else null), knot (C*12
 * float32 knot values there), tangent (spline clips: C*12 float64 tangent coefficients there, else null)}.
 */
function ownState(shell, wa, label) {
  if (wa.start_codes === undefined) return null;
  const n = shell.nCurves * 12;
  const shape = [shell.nCurves, 3, 4];
  const codes = Float64Array.from(need(wa, 'start_codes', shape, label, ['<u4']).data, unzig);
  const slopes = shell.knotDifferences === 2 ? Float64Array.from(need(wa, 'start_slopes', shape, label, ['<u4']).data, unzig) : null;
  const knot = Float32Array.from(need(wa, 'start_knot', shape, label, ['<f4']).data);
  const tangent = shell.timeModel ? Float64Array.from(need(wa, 'start_tangents', shape, label, ['<f8']).data) : null;
  if (codes.length !== n) throw new ClipFormatError(`${label}: bad start state`);
  return { codes, slopes, knot, tangent };
}

/**
 * Decode window i of a streamable clip (its inner container's bytes) with the clip's shell and the state of
 * window i - 1 (null for window 0, or a window that holds its own start state; docs/format.md §3.10) into
 * {clip, state}: clip a dynamic clip of its own (the shell's static data, segments a .. b - 1 with the clip's
 * boundaries, knots a .. b, for spline clips tangentFirst / tangentLast: the known end tangent coefficients,
 * C*12 float64, or null for a natural end), state what it hands to window i + 1.
 */
export function decodeStreamWindow(shell, bytes, i, carried = null) {
  const w = shell.index[i];
  if (!w) throw new ClipFormatError(`the clip has no window ${i} (it has ${shell.index.length})`);
  const { header: wh, arrays: wa } = decodeContainer(bytes);
  const label = `window ${i}`;
  if (wh.part !== 'coefficients-window') throw new ClipFormatError(`${label}: expected a coefficients-window part, got ${JSON.stringify(wh.part)}`);
  checkFormatVersion(wh, label);
  if (wh.window !== i || wh.first_knot !== w.a || wh.last_knot !== w.b) {
    throw new ClipFormatError(`${label}: its header (window ${wh.window}, knots ${wh.first_knot}..${wh.last_knot}) disagrees with the index`);
  }
  const C = shell.nCurves;
  const S = w.b - w.a;
  const segT = need(wa, 'segment_t', [S + 1], label, ['<f8']).data;
  if (!nondecreasing(segT) || segT[0] !== w.t0 || segT[S] !== w.t1) {
    throw new ClipFormatError(`${label}: segment_t must rise from ${w.t0} to ${w.t1}`);
  }
  const { family, m } = familyOf({ space_kind: { dtype: '<u1', shape: [C, 3], data: shell.spaceKind }, m: wa.m }, S, C);
  const timeModel = shell.timeModel
    ? timeModelOf({ time_model: { dtype: '<u1', shape: [C, 3], data: shell.timeModel } }, C, m, S, segT)
    : null;
  const state = i === 0 ? null : (ownState(shell, wa, label) ?? carried);
  if (i > 0 && state === null) {
    throw new ClipFormatError(`${label} continues window ${i - 1}: decode that one first, or fetch it with its start state`);
  }
  const steps = wa.knot_step
    ? need(wa, 'knot_step', [2, C, 3], label, ['<f4']).data
    : shell.knotStep
      ? Float32Array.from([...shell.knotStep, ...shell.knotStep])
      : null;
  if (steps === null) throw new ClipFormatError(`${label} has no knot_step, nor has the head`);
  if (steps.some((x) => !(x > 0))) throw new ClipFormatError(`${label}'s knot steps must be positive`);
  const first = i === 0 ? 0 : 1; // the window's first stored knot (knot a of a later window is carried)
  const n = S + 1 - first;
  const tracks = need(wa, 'knots', [C, 3, 4, n], label, ['<u4']).data;
  const r = shell.header.knot_rank;
  const basis = r ? need(wa, 'knot_basis', [r, n], label, ['<f4']).data : null;
  const { knots, end } = windowKnots(shell, { tracks, steps, basis, n, first, S, state });
  checkFinite(knots, `${label} knots`);
  checkBounded(knots, `${label} knots`);
  let tangentLast = null;
  if (timeModel && i < shell.index.length - 1) {
    const g = need(wa, 'tangents', [C, 3, 4], label, ['<u4']).data;
    const bits = wh.tangent_bits;
    if (!Number.isInteger(bits) || bits < 0 || bits > 30) {
      throw new ClipFormatError(`${label}: tangent_bits must be an integer in 0..30, got ${JSON.stringify(bits)}`);
    }
    const scale = 2 ** -bits;
    const delta = segT[S] - segT[S - 1];
    tangentLast = new Float64Array(C * 12);
    for (let j = 0; j < C * 12; j++) tangentLast[j] = ((unzig(g[j]) * steps[C * 3 + (j >> 2)]) * scale) / delta;
  }
  const clip = joinWindow(shell, {
    bones: shell.bones ? windowBones(shell, w, wh, wa, label) : null,
    window: i,
    s0: w.a,
    s1: w.b,
    nSegments: S,
    segmentT: segT,
    family,
    m,
    knots,
    tangentFirst: timeModel && i > 0 ? state.tangent : null,
    tangentLast,
  });
  return { clip, state: { ...end, tangent: tangentLast } };
}

/**
 * The float32 knots ((S+1) x C*12) of a window and its end state {codes, slopes, knot}: the integer tracks'
 * running sums continued from state (none: from 0), float32(p x h) with h row 0 of steps for the stored knots
 * but the last (row 1), or on the shared time basis (§3.4); knot a of a later window is the carried one.
 */
function windowKnots(shell, { tracks, steps, basis, n, first, S, state }) {
  const T = shell.nCurves * 12;
  const order = shell.knotDifferences;
  const r = shell.header.knot_rank;
  const knots = new Float32Array((S + 1) * T);
  if (first === 1) knots.set(state.knot, 0);
  const codes = new Float64Array(T);
  const slopes = order === 2 ? new Float64Array(T) : null;
  const weights = r ? shell.knotWeights : null;
  for (let k = 0; k < T; k++) {
    let p = state ? state.codes[k] : 0;
    let slope = state && order === 2 ? state.slopes[k] : 0;
    const item = k >> 2;
    for (let j = 0; j < n; j++) {
      const d = unzig(tracks[k * n + j]);
      if (order === 1) p += d;
      else p += slope += d;
      const h = steps[(j === n - 1 ? shell.nCurves * 3 : 0) + item];
      const o = (first + j) * T + k;
      if (!r) knots[o] = Math.fround(p * h);
      else {
        let acc = 0;
        for (let jj = 0; jj < r; jj++) acc += (unzig(weights[jj * T + k]) * h) * basis[jj * n + j];
        knots[o] = Math.fround(acc + p * h);
      }
    }
    codes[k] = p;
    if (slopes) slopes[k] = slope;
  }
  return { knots, end: { codes, slopes, knot: knots.slice(S * T) } };
}

/** The arrays and counts of a decoded window that are its own (a worker sends these, not the shell's). */
export const WINDOW_FIELDS = Object.freeze(['bones', 'window', 's0', 's1', 'nSegments', 'segmentT', 'family', 'm', 'knots', 'tangentFirst', 'tangentLast']);

/** A decoded window's own fields (WINDOW_FIELDS). */
export function windowFields(clip) {
  return Object.fromEntries(WINDOW_FIELDS.map((k) => [k, clip[k]]));
}

/** The window clip of a shell and a window's own fields: a dynamic clip of segments s0 .. s1 - 1. */
export function joinWindow(shell, fields) {
  const clip = { ...shell, ...fields };
  delete clip.index;
  delete clip.boneHead;
  return clip;
}
