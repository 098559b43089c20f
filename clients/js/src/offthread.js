// Decode clips in a Web Worker (worker.js): the zstd decoding, the format decoding and the GPU tables run
// off the main thread, and the results come back as transferred buffers (no copy). Where workers cannot run
// (node, a bundler that cannot resolve 'fzstd' for the worker), the same work runs here instead.

import { ClipFormatError } from './container.js';
import { loadClip, splitClipFile } from './clip.js';
import { gpuTables } from './gpu.js';
import './zstd.js';

let worker = null;
let nextId = 0;
const pending = new Map();

/** Why clips cannot be decoded in a Web Worker here (null when they can). */
export function workerUnavailableReason() {
  if (typeof Worker === 'undefined') return 'no Web Workers here';
  try {
    fzstdUrl();
  } catch (err) {
    return `the worker cannot load fzstd (${err.message})`;
  }
  return null;
}

function fzstdUrl() {
  if (typeof import.meta.resolve !== 'function') throw new Error('import.meta.resolve is unavailable');
  return import.meta.resolve('fzstd');
}

function startWorker() {
  const w = new Worker(new URL('./worker.js', import.meta.url), { type: 'module', name: 'pdeanim-decoder' });
  w.onmessage = ({ data }) => {
    const job = pending.get(data.id);
    if (!job) return;
    pending.delete(data.id);
    if (data.error) {
      const Err = data.error.name === 'ClipFormatError' ? ClipFormatError : Error;
      job.reject(new Err(data.error.message));
    } else job.resolve(data.clip);
  };
  w.onerror = (e) => {
    for (const job of pending.values()) job.reject(new Error(`the pdeanim decoder worker failed: ${e.message}`));
    pending.clear();
    worker = null;
  };
  return w;
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
  if (!useWorker || workerUnavailableReason() !== null) {
    const p = parts.file ? splitClipFile(parts.file) : parts;
    const clip = await loadClip(p.topology, p.coefficients);
    if (tables) clip.gpuTables = gpuTables(clip, { width });
    return clip;
  }
  worker ??= startWorker();
  const id = nextId++;
  const message = { id, fzstd: fzstdUrl(), tables, width };
  for (const k of ['topology', 'coefficients', 'file']) if (parts[k]) message[k] = copyOf(parts[k]);
  const transfer = ['topology', 'coefficients', 'file'].filter((k) => message[k]).map((k) => message[k]);
  return new Promise((resolve, reject) => {
    pending.set(id, { resolve, reject });
    worker.postMessage(message, transfer);
  });
}
