// Read the streamable layout of a dynamic-PDE coefficients part (format 1.2, feature "stream", docs/format.md
// §3.10): a head (the usual header with a "stream" index, the per-clip arrays) followed by the time windows in
// time order, each a container of its own that decodes with the head alone. The head decodes into a "shell"
// (everything but the per-segment data) and each window into a dynamic clip of its own (stream.js plays them).

import { ClipFormatError, MAGIC, checkFormatVersion, decodeContainer } from './container.js';
import { hasBones } from './bones.js';
import { parts, vertexBase } from './dynamic.js';

const { need, count, topologyArrays, curveOfVertices, toVertexOrder, nondecreasing, familyOf, timeModelOf } = parts;

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
  if (hasBones(ch)) {
    throw new ClipFormatError('streamable clips with a bone layer are not played by this reader yet (feature "stream" with "bones")');
  }
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
    knotWeights: r ? need(ca, 'knot_weights', [r, C, 3, 4], 'coefficients', ['<u4']) : null,
    motion,
    looping: Boolean(ch.looping),
    rigid: motion === 'rigid' ? parts.rigidTracks(ca, C) : null,
    bones: null,
    header: ch,
    topologyHeader: th,
    topologyId: ch.topology_id ?? null,
    index,
  };
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

/**
 * Decode window i of a streamable clip (its inner container's bytes) with the clip's shell into a dynamic
 * clip of its own: the shell's static data, segments a .. b - 1 (nSegments b - a, segmentT the clip's
 * boundaries there), knots a .. b, and for clips with spline items tangentEnds (2 x C x 3 x 4 float64: the
 * tangent coefficients at knots a and b).
 */
export function decodeStreamWindow(shell, bytes, i) {
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
  const ch = shell.header;
  const r = ch.knot_rank;
  const steps = need(wa, 'knot_step', [2, C, 3], label, ['<f4']);
  const ka = { knots: wa.knots };
  if (r === 0) {
    // row 0 steps knots a .. b - 1, row 1 knot b: the knot windows [0, S, S + 1] of §3.4
    ka.knot_step = steps;
    ka.knot_windows = { dtype: '<u4', shape: [3], data: Uint32Array.of(0, S, S + 1) };
  } else {
    ka.knot_step = { dtype: '<f4', shape: [C, 3], data: steps.data.subarray(0, C * 3) };
    ka.knot_weights = shell.knotWeights;
    ka.knot_basis = wa.knot_basis;
  }
  const knots = parts.decodeKnots(ch, ka, S, C, Number.MAX_SAFE_INTEGER);
  let tangentEnds = null;
  if (timeModel) {
    const g = need(wa, 'tangents', [2, C, 3, 4], label, ['<u4']).data;
    const bits = wh.tangent_bits;
    if (!Number.isInteger(bits) || bits < 0 || bits > 30) {
      throw new ClipFormatError(`${label}: tangent_bits must be an integer in 0..30, got ${JSON.stringify(bits)}`);
    }
    const scale = 2 ** -bits;
    const delta = [segT[1] - segT[0], segT[S] - segT[S - 1]];
    tangentEnds = new Float64Array(2 * C * 12);
    const h = steps.data;
    for (let e = 0; e < 2; e++) {
      for (let j = 0; j < C * 12; j++) {
        const q = g[e * C * 12 + j];
        const d = (q >>> 1) ^ -(q & 1);
        tangentEnds[e * C * 12 + j] = ((d * h[e * C * 3 + (j >> 2)]) * scale) / delta[e];
      }
    }
  }
  return joinWindow(shell, {
    window: i,
    s0: w.a,
    s1: w.b,
    nSegments: S,
    segmentT: segT,
    family,
    m,
    knots,
    tangentEnds,
  });
}

/** The arrays and counts of a decoded window that are its own (a worker sends these, not the shell's). */
export const WINDOW_FIELDS = Object.freeze(['window', 's0', 's1', 'nSegments', 'segmentT', 'family', 'm', 'knots', 'tangentEnds']);

/** A decoded window's own fields (WINDOW_FIELDS). */
export function windowFields(clip) {
  return Object.fromEntries(WINDOW_FIELDS.map((k) => [k, clip[k]]));
}

/** The window clip of a shell and a window's own fields: a dynamic clip of segments s0 .. s1 - 1. */
export function joinWindow(shell, fields) {
  const clip = { ...shell, ...fields };
  delete clip.index;
  return clip;
}
