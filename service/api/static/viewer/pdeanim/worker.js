// The Web Worker that decodes a clip and builds its GPU tables off the main thread (offthread.js starts it).
// Its first message is {ready: true} (its modules loaded). Messages in: {id, fzstd (fzstd's URL as the page
// resolves it, or null), topology and coefficients (ArrayBuffers) or file (a CLIP file), tables (build
// gpuTables), width}; out: {id, clip} with every typed array's buffer transferred, or {id, error: {name,
// message}}. Bundlers (Vite, webpack, esbuild with this file as an entry point) bundle fzstd into the worker
// through the import below; an unbundled worker cannot resolve the bare specifier and takes the page's URL.

import { setZstdDecompress } from './container.js';
import { loadClip, splitClipFile } from './clip.js';
import { gpuTables } from './gpu.js';

let zstd = null;

/** The ArrayBuffers under the typed arrays of value (objects and arrays searched a few levels deep). */
export function transferables(value, depth = 4, out = new Set()) {
  if (ArrayBuffer.isView(value)) out.add(value.buffer);
  else if (value && typeof value === 'object' && depth > 0) {
    for (const v of Object.values(value)) transferables(v, depth - 1, out);
  }
  return out;
}

/** Install fzstd: bundled with the worker where a bundler resolved it, else from the page's URL for it. */
async function installZstd(url) {
  let module;
  try {
    module = await import('fzstd');
  } catch (err) {
    if (!url) throw new Error(`the decoder worker cannot load fzstd (${err.message})`, { cause: err });
    module = await import(url);
  }
  setZstdDecompress(module.Decompress);
}

self.onmessage = async ({ data }) => {
  const { id } = data;
  try {
    zstd ??= installZstd(data.fzstd);
    await zstd;
    const parts = data.file ? splitClipFile(data.file) : data;
    const clip = await loadClip(parts.topology, parts.coefficients);
    if (data.tables) clip.gpuTables = gpuTables(clip, { width: data.width });
    self.postMessage({ id, clip }, [...transferables(clip)]);
  } catch (err) {
    self.postMessage({ id, error: { name: err?.name ?? 'Error', message: String(err?.message ?? err) } });
  }
};

self.postMessage({ ready: true });
