// Progressive playback of streamable clips (docs/format.md §3.10): the response is read chunk by chunk (fetch
// body reader), each time window is decoded as soon as its bytes are in (in the Web Worker), playback starts
// with the first window, and only a bounded number of windows stay decoded (evicted behind the play head,
// fetched again from their byte offset, with an HTTP Range request, when the play head comes back to them).

import { ClipFormatError } from './container.js';
import { DynamicEvaluator } from './dynamic.js';
import { containerPrefix, decodeStreamHead, decodeStreamWindow, windowRange } from './streamformat.js';

/** A node-or-browser progress event (node has no ProgressEvent: a plain object with the same fields). */
export function progressEvent(type, init) {
  return typeof ProgressEvent === 'function' ? new ProgressEvent(type, init) : { type, ...init };
}

/** An Error with the server's message for a non-2xx response (its JSON error body where there is one). */
export async function responseError(res, url) {
  let detail = '';
  let code = null;
  try {
    const body = await res.json();
    detail = body?.error?.message ? `: ${body.error.message}` : '';
    code = body?.error?.code ?? null;
  } catch {
    /* not JSON */
  }
  return Object.assign(new Error(`GET ${url} answered ${res.status}${detail}`), { status: res.status, code });
}

/**
 * The byte range a response's body starts at: 0 for a 200, the first byte of Content-Range for a 206 (a
 * server that ignores Range answers 200 with the whole body: the caller skips to its offset).
 */
export function bodyStart(res) {
  if (res.status !== 206) return 0;
  const m = /^bytes\s+(\d+)-\d+\/(\d+|\*)$/i.exec(res.headers.get('Content-Range') ?? '');
  if (!m) throw new Error('a 206 response without a valid Content-Range');
  return Number(m[1]);
}

/** The full length of a response's resource (Content-Length of a 200, the total of a 206's range), or 0. */
export function resourceLength(res) {
  if (res.status === 206) {
    const m = /\/(\d+)$/.exec(res.headers.get('Content-Range') ?? '');
    return m ? Number(m[1]) : 0;
  }
  return Number(res.headers.get('Content-Length')) || 0;
}

/**
 * A growing byte buffer over the chunks of a body: append() chunks, take(n) the first n bytes (one copy, only
 * when they span chunks), skip(n); `length` bytes are held, `position` is the resource offset of the first.
 */
export class ByteQueue {
  constructor(position = 0) {
    this.chunks = [];
    this.length = 0;
    this.position = position;
  }

  append(chunk) {
    if (chunk.byteLength) {
      this.chunks.push(chunk);
      this.length += chunk.byteLength;
    }
  }

  /** The first n bytes (n <= length) without consuming them. */
  peek(n) {
    if (n > this.length) throw new RangeError(`peek(${n}) with ${this.length} bytes held`);
    if (this.chunks.length && this.chunks[0].byteLength >= n) return this.chunks[0].subarray(0, n);
    const out = new Uint8Array(n);
    let o = 0;
    for (const c of this.chunks) {
      if (o >= n) break;
      const part = c.subarray(0, Math.min(c.byteLength, n - o));
      out.set(part, o);
      o += part.byteLength;
    }
    return out;
  }

  /** Consume and return the first n bytes (a copy of its own: it can be transferred to a worker). */
  take(n) {
    const first = this.chunks[0];
    const out = first && first.byteLength === n && first.byteOffset === 0 && first.buffer.byteLength === n
      ? first
      : this.peek(n).slice();
    this.skip(n);
    return out;
  }

  /** Drop the first n bytes (at most length). */
  skip(n) {
    let left = Math.min(n, this.length);
    this.length -= left;
    this.position += left;
    while (left > 0) {
      const c = this.chunks[0];
      if (c.byteLength <= left) {
        this.chunks.shift();
        left -= c.byteLength;
      } else {
        this.chunks[0] = c.subarray(left);
        left = 0;
      }
    }
  }
}

/**
 * GET url from byte offset `from` (a Range request when from > 0; a server that answers 200 has its leading
 * bytes skipped), returning {reader, queue, total, start}: read the body with reader.read() into queue.
 */
export async function openRange(url, from, { headers = {}, credentials, signal, fetch: fetchFn = globalThis.fetch } = {}) {
  const h = { Accept: 'application/octet-stream', ...headers };
  if (from > 0) h.Range = `bytes=${from}-`;
  const res = await fetchFn(url, { headers: h, credentials, signal });
  if (!res.ok) throw await responseError(res, url);
  if (!res.body) throw new Error(`GET ${url}: the response has no body stream`);
  const start = bodyStart(res);
  if (start > from) throw new Error(`GET ${url}: asked for bytes from ${from}, the server sent from ${start}`);
  return { reader: res.body.getReader(), queue: new ByteQueue(start), total: resourceLength(res), start, response: res };
}

/** The index of the window holding normalised time tw (t0s: the windows' first times, rising from 0). */
export function windowOfTime(t0s, tw) {
  let lo = 0;
  let hi = t0s.length - 1;
  while (lo < hi) {
    const mid = (lo + hi + 1) >> 1;
    if (t0s[mid] <= tw) lo = mid;
    else hi = mid - 1;
  }
  return lo;
}

/** Thrown by a streaming clip's evaluator for a time whose window is not decoded (yet, or any more). */
export class WindowPendingError extends Error {
  constructor(index) {
    super(`window ${index} of the clip is not decoded (it is being fetched)`);
    this.name = 'WindowPendingError';
    this.window = index;
  }
}

/**
 * The CPU evaluator of a windowed clip: the evaluator of the window that holds t (DynamicEvaluator of the
 * window clip, made on first use), with the DynamicEvaluator interface. locate(t) selects that window
 * (`current`) and returns its location (segment numbers local to the window); a streaming clip throws
 * WindowPendingError for a window not decoded.
 */
export class WindowedEvaluator {
  constructor(clip) {
    this.clip = clip;
    this.nVertices = clip.nVertices;
    this.current = null; // the window evaluator of the last locate()
    this.index = -1;
  }

  /** The evaluator of window i (made on first use). */
  windowEvaluator(i) {
    const w = this.clip.windowData(i);
    if (!w.evaluator) {
      w.evaluator = new DynamicEvaluator(w.clip, w.tables?.timeIndex ?? null);
      // the GPU path's tangents of the window, when the worker made them (else gpu.js makes them on use)
      if (w.tables?.tangents) w.evaluator.windowTangents = w.tables.tangents;
    }
    return w.evaluator;
  }

  locate(t) {
    const i = this.clip.windowAt(t);
    this.current = this.windowEvaluator(i);
    this.index = i;
    return this.current.locate(t);
  }

  get loc() {
    return this.current.loc;
  }

  segmentState() {
    return this.current.segmentState();
  }

  prepare(t) {
    this.locate(t);
    return this.current.prepare(t);
  }

  evaluate(t, out = new Float32Array(this.nVertices * 3)) {
    this.locate(t);
    return this.current.evaluate(t, out);
  }
}

/**
 * A windowed clip (the streamable layout, docs/format.md §3.10) held in memory: its shell (decodeStreamHead)
 * and the bytes of its windows, each decoded when first evaluated; at most maxWindows stay decoded (the
 * least recently used is dropped). Looks like a decoded dynamic clip to the evaluators and players
 * (`windowed` true).
 */
export class WindowedClip extends EventTarget {
  constructor(shell, { maxWindows = 4 } = {}) {
    super();
    Object.assign(this, shell);
    this.shell = shell;
    this.windowed = true;
    this.nWindows = shell.index.length;
    this.t0s = Float64Array.from(shell.index, (w) => w.t0);
    if (!(maxWindows >= 2)) throw new RangeError(`maxWindows must be at least 2, got ${maxWindows}`);
    this.maxWindows = maxWindows;
    /** The decoded windows: index → {clip, tables, evaluator}, in the order of their last use. */
    this.decoded = new Map();
    /** The state each window decoded so far hands to the next (docs/format.md §3.10: knots are carried). */
    this.states = new Map();
  }

  /** The window index of normalised time t (§3.10: the last window starting at or before the wrapped time). */
  windowAt(t) {
    const tw = this.looping ? t - Math.floor(t) : Math.min(Math.max(t, 0), 1);
    return windowOfTime(this.t0s, tw);
  }

  /** Whether a frame at t can be evaluated now (always, in memory). */
  ready() {
    return true;
  }

  /** The play head moved to t (nothing to fetch in memory); returns whether its window can be evaluated. */
  setPlayhead() {
    return true;
  }

  /** Window i's decoded data {clip, tables, evaluator}, decoded now when it is not. */
  windowData(i) {
    let w = this.decoded.get(i);
    if (w) {
      this.decoded.delete(i); // most recently used last
    } else {
      // from the last window whose start state is known (window 0's is), decoding the ones between
      let j = i;
      while (j > 0 && !this.states.has(j - 1)) j--;
      let clip = null;
      for (; j <= i; j++) {
        const out = decodeStreamWindow(this.shell, this.windowBytes(j), j, j > 0 ? this.states.get(j - 1) : null);
        this.states.set(j, out.state);
        clip = out.clip;
      }
      w = { clip, tables: null, evaluator: null };
      while (this.decoded.size >= this.maxWindows) this.decoded.delete(this.decoded.keys().next().value);
    }
    this.decoded.set(i, w);
    return w;
  }

  /** The bytes of window i (set by the constructor's caller: the part's bytes in memory). */
  windowBytes() {
    throw new Error('a WindowedClip needs windowBytes');
  }
}

/**
 * A streamable coefficients part decoded in memory (its topology part beside it): a WindowedClip over the
 * part's bytes.
 */
export function decodeWindowedClip(topology, coefficients, options = {}) {
  const bytes = asBytes(coefficients);
  const shell = decodeStreamHead(topology, bytes);
  const H = containerPrefix(bytes).headerLength;
  const clip = new WindowedClip(shell, options);
  clip.windowBytes = (i) => {
    const [from, to] = windowRange(H, shell.index[i]);
    if (to > bytes.byteLength) throw new ClipFormatError(`window ${i} lies outside the part (truncated file?)`);
    return bytes.subarray(from, to);
  };
  return clip;
}

function asBytes(data) {
  if (data instanceof Uint8Array) return data;
  if (data instanceof ArrayBuffer) return new Uint8Array(data);
  if (ArrayBuffer.isView(data)) return new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  throw new ClipFormatError('expected an ArrayBuffer or a typed array');
}

/** Resolvers of a promise made outside its executor. */
function deferred() {
  let resolve;
  let reject;
  const promise = new Promise((res, rej) => {
    resolve = res;
    reject = rej;
  });
  return { promise, resolve, reject };
}

/**
 * A windowed clip played while it downloads: its shell (the head) and its time windows, decoded one by one
 * as their bytes arrive. At most `maxWindows` windows are decoded at once: the window at the play head
 * (setPlayhead, which the players' setTime call), the next ones, and `behind` (default 1) behind it; the
 * others are evicted and fetched again (from their byte offset) when needed. The download waits
 * (backpressure) while the next window is not wanted yet: memory stays flat whatever the clip's length.
 *
 * Events (an EventTarget): 'window' (a window was decoded: detail {index, s0, s1, t0, t1, decoded: how many
 * are now}), 'evict' (detail {index}), 'progress' (detail {loaded: bytes read by the current request,
 * position: the resource offset reached}), 'error' (detail {error}), 'end' (the download reached the end).
 *
 * windows: the shell's index with {offset, length}: each window's byte range in the resource. fetcher:
 * {open(from) → Promise of openRange()'s {reader, queue}, decode(index, bytes) → Promise of {clip, tables},
 * forget(indices) (optional: drop the states those windows carry on), close()}.
 */
export class StreamingClip extends WindowedClip {
  constructor(shell, windows, fetcher, { maxWindows = 4, behind = 1 } = {}) {
    super(shell, { maxWindows });
    this.streaming = true;
    this.windows = windows;
    this.behind = Math.max(0, Math.min(behind, maxWindows - 2));
    this.inflight = new Map(); // index → Promise of the decoded window
    this.stateSent = new Set(); // windows handed to the decoder (it holds the state each hands on)
    this.checkpointStride = 1; // states kept for seeks: windows a multiple of this apart (_forgetStates)
    this.fetcher = fetcher;
    this.playhead = 0; // the window index of the play head
    this.stream = null; // the current sequential read: {reader, queue, next (the window it delivers next)}
    this.closed = false;
    this.firstWindow = deferred();
    this.firstWindow.promise.catch(() => {}); // (awaited by the loader; an error also goes to 'error')
    this.ended = false;
    this._wake = null;
    this._failed = null;
  }

  /** Whether the window of t is decoded (a frame at t can be shown now). */
  ready(t) {
    return this.decoded.has(this.windowAt(t));
  }

  /** Window i's decoded data; WindowPendingError when it is not decoded. */
  windowData(i) {
    const w = this.decoded.get(i);
    if (!w) throw new WindowPendingError(i);
    return w;
  }

  /** The windows to hold now, in the order they are needed: the play head's, then the next ones (wrapping for looping clips). */
  wanted() {
    const out = [];
    const W = this.nWindows;
    const ahead = this.maxWindows - this.behind;
    for (let k = 0; k < ahead; k++) {
      let i = this.playhead + k;
      if (i >= W) {
        if (!this.looping) break;
        i -= W;
      }
      if (!out.includes(i)) out.push(i);
    }
    return out;
  }

  /**
   * Move the play head to time t: fetches and decodes what it needs, evicts what it does not. Returns
   * whether t's window is decoded (a player keeps its last frame until it is).
   */
  setPlayhead(t) {
    const i = this.windowAt(t);
    if (i !== this.playhead) {
      this.playhead = i;
      this._evict();
      this._schedule();
    }
    return this.decoded.has(i);
  }

  /** Resolves when the window of t is decoded (after moving the play head there). */
  async whenReady(t) {
    this.setPlayhead(t);
    const i = this.windowAt(t);
    while (!this.decoded.has(i)) {
      if (this.closed) throw new Error('the streaming clip was closed');
      if (this._failed) throw this._failed;
      await new Promise((resolve) => {
        const done = () => {
          this.removeEventListener('window', done);
          this.removeEventListener('error', done);
          resolve();
        };
        this.addEventListener('window', done);
        this.addEventListener('error', done);
      });
    }
  }

  /** The windows held now: the wanted ones and the `behind` ones just behind the play head. */
  _held() {
    const keep = new Set(this.wanted());
    for (let k = 1; k <= this.behind; k++) {
      const i = this.playhead - k;
      if (i >= 0) keep.add(i);
      else if (this.looping) keep.add(i + this.nWindows);
    }
    return keep;
  }

  /** Drop decoded windows neither wanted nor among the `behind` ones just behind the play head. */
  _evict() {
    const keep = this._held();
    for (const i of [...this.decoded.keys()]) {
      if (!keep.has(i)) {
        this.decoded.delete(i);
        this.dispatchEvent(customEvent('evict', { index: i }));
      }
    }
    this._forgetStates(keep);
  }

  /**
   * Tell the decoder to drop carried states (docs/format.md §3.10, 1.7 MB each on a 34k-vertex clip) so that
   * it holds a bounded number whatever the clip's length: those the held windows start from, the one the
   * read continues from, and at most maxWindows checkpoints (windows a multiple of a stride apart, the stride
   * doubling as the clip plays on), where a seek to a window evicted meanwhile restarts the read.
   */
  _forgetStates(keep = this._held()) {
    if (!this.fetcher.forget) return;
    const needed = new Set();
    for (const i of keep) needed.add(i - 1);
    if (this.stream) needed.add(this.stream.next - 1);
    const others = [...this.stateSent].filter((j) => !needed.has(j));
    let checkpoints = others.filter((j) => j % this.checkpointStride === 0);
    while (checkpoints.length > this.maxWindows) {
      this.checkpointStride *= 2;
      checkpoints = checkpoints.filter((j) => j % this.checkpointStride === 0);
    }
    const drop = others.filter((j) => j % this.checkpointStride !== 0);
    if (drop.length === 0) return;
    for (const j of drop) this.stateSent.delete(j);
    this.fetcher.forget(drop);
  }

  /** Whether window i should be decoded now. */
  _isWanted(i) {
    return this.wanted().includes(i);
  }

  /**
   * Keep the stream where it serves the play head: the first wanted window neither decoded nor in flight
   * must come from it; when the stream would not reach it soon (it is behind, or past it), the stream is
   * restarted at that window's byte offset.
   */
  _schedule() {
    if (this.closed) return;
    const need = this.wanted().find((i) => !this.decoded.has(i) && !this.inflight.has(i));
    if (need === undefined) return this._resume();
    const s = this.stream;
    const from = this._restartPoint(need);
    if (s === null || s.next > need || from > s.next) this._restart(from);
    else this._resume();
  }

  /**
   * Where a read that must deliver window i starts: i when window i - 1's state was handed to the decoder
   * (or i is 0), else the latest window before it that can start (knots are carried from window to window).
   */
  _restartPoint(i) {
    let j = i;
    while (j > 0 && !this.stateSent.has(j - 1)) j--;
    return j;
  }

  _resume() {
    const wake = this._wake;
    this._wake = null;
    wake?.();
  }

  /** Start the sequential read anew at window i's first byte (the previous one is cancelled). */
  _restart(i) {
    const old = this.stream;
    if (old) {
      old.cancelled = true;
      old.reader?.cancel().catch(() => {});
    }
    const stream = { next: i, reader: null, queue: null, cancelled: false };
    this.stream = stream;
    this.ended = false;
    this._resume();
    this._loop = this._read(stream).catch((error) => {
      if (stream.cancelled || this.closed) return;
      this._fail(error);
    });
  }

  /** Adopt an already open stream (the loader's first request, positioned at window `next`). */
  _adopt(opened, next) {
    const stream = { next, reader: opened.reader, queue: opened.queue, cancelled: false };
    this.stream = stream;
    this._loop = this._read(stream).catch((error) => {
      if (stream.cancelled || this.closed) return;
      this._fail(error);
    });
  }

  _fail(error) {
    this._failed = error;
    this.firstWindow.reject(error);
    this.dispatchEvent(customEvent('error', { error }));
  }

  /** Read the stream window by window: decode the wanted ones, wait (backpressure) before the ones not yet wanted. */
  async _read(stream) {
    if (stream.reader === null) {
      const w = this.windows[stream.next];
      const opened = await this.fetcher.open(w.offset);
      if (stream.cancelled) {
        opened.reader.cancel().catch(() => {});
        return;
      }
      stream.reader = opened.reader;
      stream.queue = opened.queue;
    }
    const { queue } = stream;
    let loaded = 0;
    while (!stream.cancelled && stream.next < this.nWindows) {
      const w = this.windows[stream.next];
      if (queue.position < w.offset) {
        // bytes before the window (a server that ignored Range, or a gap): skipped
        queue.skip(Math.min(queue.length, w.offset - queue.position));
      }
      if (queue.position === w.offset && queue.length >= w.length) {
        const i = stream.next;
        // backpressure: a window not wanted yet waits (its bytes held) until the play head comes near
        while (!stream.cancelled && !this._isWanted(i) && !this._behindPlayhead(i)) {
          await new Promise((resolve) => {
            this._wake = resolve;
          });
        }
        if (stream.cancelled) return;
        const bytes = queue.take(w.length);
        stream.next++;
        if (this._isWanted(i) && !this.decoded.has(i) && !this.inflight.has(i)) this._decode(i, bytes);
        else if (!this.stateSent.has(i)) this._advance(i, bytes);
        continue;
      }
      const { value, done } = await stream.reader.read();
      if (stream.cancelled) return;
      if (done) {
        if (stream.next < this.nWindows) {
          throw new ClipFormatError(`the clip's body ended inside window ${stream.next} (truncated download?)`);
        }
        break;
      }
      queue.append(value);
      loaded += value.byteLength;
      this.dispatchEvent(customEvent('progress', { loaded, position: queue.position + queue.length }));
    }
    if (!stream.cancelled) {
      if (stream.next >= this.nWindows) {
        // the rest of the body (nothing after the last window in a valid clip) is drained
        for (;;) {
          const { done } = await stream.reader.read();
          if (done || stream.cancelled) break;
        }
      }
      if (this.stream === stream) {
        this.stream = null;
        this.ended = true;
        this.dispatchEvent(customEvent('end', {}));
        this._schedule();
      }
    }
  }

  /** Whether window i lies behind the play head and is not wanted (its bytes are dropped, not held). */
  _behindPlayhead(i) {
    return i < this.playhead && !this._isWanted(i);
  }

  /** Hand window i's bytes to the decoder for the state it carries on only (a window not wanted now). */
  _advance(i, bytes) {
    this.stateSent.add(i);
    this.fetcher.decode(i, bytes, false).catch((error) => this._fail(error));
    this._forgetStates();
  }

  /** Decode window i's bytes (in the worker); on arrival it joins the decoded windows unless evicted meanwhile. */
  _decode(i, bytes) {
    this.stateSent.add(i);
    const job = this.fetcher.decode(i, bytes, true).then(
      (win) => {
        this.inflight.delete(i);
        if (this.closed) return;
        if (this._isWanted(i)) {
          this.decoded.set(i, win);
          const w = this.windows[i];
          this.dispatchEvent(
            customEvent('window', { index: i, s0: w.s0, s1: w.s1, t0: w.t0, t1: w.t1, decoded: this.decoded.size }),
          );
          if (i === this.playhead || this.decoded.size === 1) this.firstWindow.resolve(this);
          this._evict();
        }
        this._schedule();
      },
      (error) => {
        this.inflight.delete(i);
        this._fail(error);
      },
    );
    this.inflight.set(i, job);
    this._forgetStates();
  }

  /** Stop reading and drop every window (the players of the clip show nothing new). */
  close() {
    this.closed = true;
    if (this.stream) {
      this.stream.cancelled = true;
      this.stream.reader?.cancel().catch(() => {});
      this.stream = null;
    }
    this._resume();
    this.decoded.clear();
    this.fetcher.close?.();
  }
}

/** A CustomEvent (node has had it since 19; a plain Event with `detail` elsewhere). */
function customEvent(type, detail) {
  if (typeof CustomEvent === 'function') return new CustomEvent(type, { detail });
  const e = new Event(type);
  e.detail = detail;
  return e;
}
