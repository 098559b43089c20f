// Test helpers for the streamable layout (docs/format.md §3.10): write a clip's coefficients in that layout
// from its decoded arrays (integer knots on one step per item, carried from window to window; time-pair
// items), to build long clips and
// stream them over HTTP in tests. The Python writer (pdeanim.model.streamlayout) makes the conformance
// fixtures; this one follows the same specification so that the JS tests can make clips of any length.

import { createServer } from 'node:http';
import { decodeClip, decodeContainer } from '../src/index.js';
import { encodeContainer } from './helpers.mjs';

const zig = (d) => (d < 0 ? -2 * d - 1 : 2 * d) >>> 0;

/**
 * A streamable coefficients part: src {header (a 1.0 coefficients header to copy the keys of), C, segT
 * (S+1 float64), frameTimes, spaceKind (C*3), D (C*3), m (S*C*3 signed), q (integer knots (S+1) x C*12),
 * steps (C*3, powers of two), rigid (the rigid_* arrays of a rigid clip, or null)}, cut into windows of
 * `per` segments.
 */
export function streamPart(src, per) {
  const { C, segT, q, steps } = src;
  const S = segT.length - 1;
  const n = C * 12;
  const head = {
    frame_times: { dtype: '<f8', shape: [src.frameTimes.length], data: Float64Array.from(src.frameTimes) },
    space_kind: { dtype: '<u1', shape: [C, 3], data: Uint8Array.from(src.spaceKind) },
    time_model: { dtype: '<u1', shape: [C, 3], data: new Uint8Array(C * 3) },
    D: { dtype: '<f4', shape: [C, 3], data: Float32Array.from(src.D) },
    knot_step: { dtype: '<f4', shape: [C, 3], data: Float32Array.from(steps) },
    ...(src.rigid ?? {}),
  };
  const windows = {};
  const index = [];
  for (let a = 0, i = 0; a < S; a += per, i++) {
    const b = Math.min(S, a + per);
    const Si = b - a;
    // the clip's difference tracks (order 1), columns first .. b: knot a of a later window is carried
    const first = i === 0 ? 0 : a + 1;
    const cols = b - first + 1;
    const codes = new Uint32Array(n * cols);
    for (let k = 0; k < n; k++) {
      for (let j = 0; j < cols; j++) {
        const s = first + j;
        codes[k * cols + j] = zig(q[s * n + k] - (s > 0 ? q[(s - 1) * n + k] : 0));
      }
    }
    const inner = encodeContainer(
      { part: 'coefficients-window', format_version: '1.2', window: i, first_knot: a, last_knot: b },
      {
        segment_t: { dtype: '<f8', shape: [Si + 1], data: segT.slice(a, b + 1) },
        m: { dtype: '<f4', shape: [Si, C, 3], data: Float32Array.from(src.m.subarray(a * C * 3, b * C * 3)) },
        knots: { dtype: '<u4', shape: [C, 3, 4, cols], data: codes, encoding: 'zstd' },
      },
    );
    windows[`window_${i}`] = { dtype: '<u1', shape: [inner.length], data: inner };
    index.push({ array: `window_${i}`, t: [segT[a], segT[b]], knots: [a, b] });
  }
  const header = { ...src.header };
  delete header.arrays;
  for (const k of ['segment_t', 'knot_windows']) delete header[k];
  Object.assign(header, {
    format_version: '1.2',
    required: ['stream'],
    n_segments: S,
    n_frames: src.frameTimes.length,
    knot_differences: 1,
    knot_rank: 0,
  });
  const arrays = { ...head, ...windows };
  const first = encodeContainer(header, arrays);
  const table = decodeContainerTable(first);
  for (const w of index) Object.assign(w, { offset: table[w.array].offset, nbytes: table[w.array].nbytes });
  return encodeContainer({ ...header, stream: { n_windows: index.length, windows: index } }, arrays);
}

function decodeContainerTable(bytes) {
  const H = new DataView(bytes.buffer, bytes.byteOffset).getUint32(12, true);
  return JSON.parse(new TextDecoder().decode(bytes.subarray(16, 16 + H))).arrays;
}

/** The integer knots, steps and time data of a decoded 1.0 fixture clip (knot_rank 0, no knot windows, no spline). */
export function sourceOf(parts) {
  const clip = decodeClip(parts.topology, parts.coefficients);
  const { arrays } = decodeContainer(parts.coefficients);
  if (clip.timeModel || clip.bones || arrays.knot_windows || clip.header.knot_rank !== 0) {
    throw new Error('sourceOf takes clips of time-pair items, knot rank 0, no knot windows, no bones');
  }
  const C = clip.nCurves;
  const steps = arrays.knot_step.data;
  const n = C * 12;
  const q = new Float64Array(clip.knots.length);
  for (let i = 0; i < q.length; i++) q[i] = clip.knots[i] / steps[(i % n) >> 2];
  const m = new Float32Array(clip.m.length);
  for (let i = 0; i < m.length; i++) m[i] = clip.family[i] >= 2 ? -clip.m[i] : clip.m[i];
  const rigid = clip.rigid
    ? Object.fromEntries(Object.entries(arrays).filter(([k]) => k.startsWith('rigid_')))
    : null;
  return {
    header: clip.header,
    C,
    segT: Float64Array.from(clip.segmentT),
    frameTimes: clip.frameTimes,
    spaceKind: Uint8Array.from({ length: C * 3 }, (_, i) => clip.family[i] % 2),
    D: clip.D,
    m,
    q,
    steps: Float32Array.from(steps),
    rigid,
    clip,
  };
}

/**
 * A long clip (S segments, S+1 frames at 30 per second) on a fixture's topology: its first knot plus a
 * travelling wave of integers on every track, the fixture's first segment's time constants in every segment.
 */
export function longSource(parts, S) {
  const src = sourceOf(parts);
  const { C } = src;
  const n = C * 12;
  const q = new Float64Array((S + 1) * n);
  for (let s = 0; s <= S; s++) {
    for (let k = 0; k < n; k++) q[s * n + k] = src.q[k] + Math.round(40 * Math.sin(0.05 * s + 0.7 * k));
  }
  const m = new Float32Array(S * C * 3);
  for (let s = 0; s < S; s++) m.set(src.m.subarray(0, C * 3), s * C * 3);
  const segT = Float64Array.from({ length: S + 1 }, (_, s) => s / S);
  const frameTimes = Float64Array.from({ length: S + 1 }, (_, s) => s / 30);
  return { ...src, header: { ...src.header, looping: false }, segT, frameTimes, m, q, rigid: null };
}

/** A CLIP file (container "clip-file") of a topology part and a coefficients part. */
export function clipFile(topology, coefficients, topologyId, extra = {}) {
  return encodeContainer(
    { part: 'clip-file', format_version: '1.2', required: ['stream'], topology_id: topologyId, report: {}, ...extra },
    {
      topology: { dtype: '<u1', shape: [topology.length], data: topology },
      coefficients: { dtype: '<u1', shape: [coefficients.length], data: coefficients },
    },
  );
}

/**
 * A node HTTP server of in-memory files that answers Range requests (206), logs every request ({url, range,
 * status, sent, done}) and sends bodies in chunks of `chunk` bytes, pausing when the client reads no more (its
 * write buffer full). hold {at, release}: the first whole-body response stops before byte `at` until the
 * Promise release settles (a client that needed the last bytes before playing would wait forever). files:
 * path → bytes.
 */
export function rangeServer(files, { chunk = 4096, hold = null } = {}) {
  const log = [];
  const server = createServer((req, res) => {
    const body = files[req.url.split('?')[0]];
    const entry = { url: req.url, range: req.headers.range ?? null, status: 0, sent: 0 };
    log.push(entry);
    if (!body) {
      entry.status = 404;
      res.writeHead(404).end();
      return;
    }
    let from = 0;
    let to = body.length;
    const m = /^bytes=(\d+)-(\d*)$/.exec(req.headers.range ?? '');
    if (m) {
      from = Number(m[1]);
      to = m[2] ? Math.min(body.length, Number(m[2]) + 1) : body.length;
      if (from >= body.length) {
        entry.status = 416;
        res.writeHead(416, { 'Content-Range': `bytes */${body.length}` }).end();
        return;
      }
      entry.status = 206;
      res.writeHead(206, {
        'Content-Type': 'application/octet-stream',
        'Content-Length': to - from,
        'Content-Range': `bytes ${from}-${to - 1}/${body.length}`,
        'Accept-Ranges': 'bytes',
      });
    } else {
      entry.status = 200;
      res.writeHead(200, { 'Content-Type': 'application/octet-stream', 'Content-Length': body.length, 'Accept-Ranges': 'bytes' });
    }
    let o = from;
    const pump = () => {
      while (o < to) {
        // hold: {at, release} the first response stops before byte `at` until release (a Promise) settles
        if (hold && !hold.used && o < hold.at && o + chunk >= hold.at && from === 0) {
          const part = Buffer.from(body.subarray(o, hold.at));
          o = hold.at;
          entry.sent = o - from;
          hold.used = true;
          res.write(part);
          hold.release.then(pump);
          return;
        }
        const part = Buffer.from(body.subarray(o, Math.min(to, o + chunk)));
        o += part.length;
        entry.sent = o - from;
        if (!res.write(part)) {
          res.once('drain', pump);
          return;
        }
      }
      res.end();
      entry.done = true;
    };
    res.on('close', () => {
      entry.closed = true;
    });
    pump();
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve({ server, log, url: `http://127.0.0.1:${server.address().port}` })));
}
