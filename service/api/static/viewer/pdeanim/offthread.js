// Decode clips in a Web Worker (worker.js): the zstd decoding, the format decoding and the GPU tables run
// off the main thread, and the results come back as transferred buffers (no copy). Where workers cannot run
// (node) or the worker does not start (its file not served or bundled), the same work runs here instead, with a
// console warning in the second case.

import { ClipFormatError } from './container.js';
import { loadClip, sha256Hex, splitClipFile } from './clip.js';
import { gpuTables, windowTables } from './gpu.js';
import { decodeStreamHead, decodeStreamWindow, joinWindow } from './streamformat.js';
import './zstd.js';

let workerStart = null; // Promise of the started decoder worker, or of null when none could start
let nextId = 0;
let nextStream = 0;
const pending = new Map();
let warned = false;

/** Say once, on the console, why clips are decoded on the main thread although Web Workers exist. */
function warnMainThread(reason) {
  if (warned) return;
  warned = true;
  console.warn(`pdeanim: decoding clips on the main thread: ${reason}`);
}

/** Why clips cannot be decoded in a Web Worker here (null when they can). */
export function workerUnavailableReason() {
  if (typeof Worker === 'undefined') return 'no Web Workers here';
  return null;
}

/**
 * fzstd's URL as this page resolves it (an import map, no bundler), or null. A bundled worker imports fzstd
 * itself; an unbundled one cannot resolve the bare specifier, and imports it from this URL instead.
 */
function fzstdUrl() {
  try {
    return typeof import.meta.resolve === 'function' ? import.meta.resolve('fzstd') : null;
  } catch {
    return null;
  }
}

function settle({ data }) {
  const job = pending.get(data.id);
  if (!job) return;
  pending.delete(data.id);
  if (data.error) {
    const Err = data.error.name === 'ClipFormatError' ? ClipFormatError : Error;
    job.reject(new Err(data.error.message));
  } else job.resolve(data.stream || data.windowed ? data : data.clip);
}

/**
 * Start the decoder worker (the pattern bundlers recognise: new Worker(new URL('./worker.js',
 * import.meta.url), {type: 'module'})) and wait for its first message, which says its modules loaded.
 * Resolves to null, with a console warning saying why, when it cannot start: nothing is handed to a worker
 * that may not exist.
 */
function startWorker() {
  return new Promise((resolve) => {
    let w;
    try {
      w = new Worker(new URL('./worker.js', import.meta.url), { type: 'module', name: 'pdeanim-decoder' });
    } catch (err) {
      warnMainThread(`the decoder worker could not be created (${err.message})`);
      resolve(null);
      return;
    }
    w.onmessage = ({ data }) => {
      if (!data?.ready) return;
      w.onmessage = settle;
      w.onerror = (e) => {
        for (const job of pending.values()) job.reject(new Error(`the pdeanim decoder worker failed: ${e.message}`));
        pending.clear();
        workerStart = null;
      };
      resolve(w);
    };
    w.onerror = (e) => {
      e.preventDefault?.();
      const detail = e.message || 'its module did not load: is src/worker.js served or bundled beside the page?';
      warnMainThread(`the decoder worker did not start (${detail})`);
      w.terminate();
      resolve(null);
    };
  });
}

function copyOf(data) {
  if (data instanceof ArrayBuffer) return data;
  const bytes = ArrayBuffer.isView(data) ? data : new Uint8Array(data);
  return bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
}

/**
 * Decode a clip (parts {topology, coefficients} or {file}: ArrayBuffers or typed arrays, handed over to the
 * worker) and, with tables (default true), build its GPU tables (clip.gpuTables) for data textures width
 * texels wide (default 4096), in a Web Worker where one can run, else here. Resolves to the decoded clip
 * (topology_id checked where WebCrypto is available).
 */
export async function decodeClipOffThread(parts, { tables = true, width = 4096, useWorker = true } = {}) {
  const worker = useWorker && workerUnavailableReason() === null ? await (workerStart ??= startWorker()) : null;
  if (worker === null) {
    const p = parts.file ? splitClipFile(parts.file) : parts;
    const clip = await loadClip(p.topology, p.coefficients);
    if (tables) clip.gpuTables = gpuTables(clip, { width });
    return clip;
  }
  const id = nextId++;
  const message = { id, fzstd: fzstdUrl(), tables, width };
  for (const k of ['topology', 'coefficients', 'file']) if (parts[k]) message[k] = copyOf(parts[k]);
  const transfer = ['topology', 'coefficients', 'file'].filter((k) => message[k]).map((k) => message[k]);
  const done = await new Promise((resolve, reject) => {
    pending.set(id, { resolve, reject });
    worker.postMessage(message, transfer);
  });
  if (!done?.windowed) return done;
  // a streamable clip held whole (docs/format.md §3.10): decoded here, its windows when first evaluated (the
  // loader streams such clips through the worker instead)
  return loadClip(done.windowed.topology, done.windowed.coefficients);
}

/** Post message to the worker and resolve with its answer (settle()). */
function call(worker, message, transfer = []) {
  const id = nextId++;
  return new Promise((resolve, reject) => {
    pending.set(id, { resolve, reject });
    worker.postMessage({ ...message, id, fzstd: fzstdUrl() }, transfer);
  });
}

/**
 * Open a streamable clip (docs/format.md §3.10) for decoding window by window, in a Web Worker where one can
 * run, else here: its topology part and head (the first bytes of its coefficients part, up to its first
 * window) are decoded (topology_id checked where WebCrypto is available) with the GPU tables every window
 * shares (tables, default true; textures width texels wide). Resolves to {shell, tables, decode(index,
 * bytes) → Promise of {clip (the window's dynamic clip), tables (its timeIndex, tangents)}, forget(indices)
 * (drop the states those windows carry on), close()}.
 */
export async function openStreamOffThread({ topology, head }, { tables = true, width = 4096, useWorker = true } = {}) {
  const worker = useWorker && workerUnavailableReason() === null ? await (workerStart ??= startWorker()) : null;
  if (worker === null) {
    const shell = decodeStreamHead(topology, head);
    if (shell.topologyId) {
      const have = await sha256Hex(topology);
      if (have !== null && have !== shell.topologyId) {
        throw new ClipFormatError('the coefficients were made for another topology part (topology_id mismatch)');
      }
    }
    const shared = tables ? gpuTables(shell, { width }) : null;
    const states = new Map(); // the state each window handed on (knots are carried, §3.10)
    return {
      shell,
      tables: shared,
      decode: async (i, bytes, keep = true) => {
        const { clip, state } = decodeStreamWindow(shell, bytes, i, i > 0 ? (states.get(i - 1) ?? null) : null);
        states.set(i, state);
        if (!keep) return null;
        return { clip, tables: shared ? windowTables(clip, shared.r, shared.spline) : null };
      },
      forget: (indices) => {
        for (const j of indices) states.delete(j);
      },
      states,
      close() {},
    };
  }
  const sid = nextStream++;
  const t = copyOf(topology);
  const h = copyOf(head);
  const opened = await call(worker, { op: 'open', sid, topology: t, head: h, tables, width }, [t, h]);
  const shell = opened.clip;
  return {
    shell,
    tables: opened.tables,
    decode: async (i, bytes, keep = true) => {
      const b = bytes.byteOffset === 0 && bytes.byteLength === bytes.buffer.byteLength ? bytes.buffer : copyOf(bytes);
      const win = await call(worker, { op: 'window', sid, index: i, bytes: b, keep }, [b]);
      return keep ? { clip: joinWindow(shell, win.clip), tables: win.tables } : null;
    },
    // (messages are handled in order: a window sent before this decodes with the state it needs)
    forget: (indices) => worker.postMessage({ op: 'forget', sid, indices }),
    close: () => worker.postMessage({ op: 'close', sid }),
  };
}
