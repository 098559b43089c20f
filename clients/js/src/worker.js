// The Web Worker that decodes a clip and builds its GPU tables off the main thread (offthread.js starts it).
// Messages in: {id, fzstd (URL of fzstd's ES module: a worker cannot resolve bare specifiers), topology and
// coefficients (ArrayBuffers) or file (a CLIP file), tables (build gpuTables), width}; out: {id, clip} with
// every typed array's buffer transferred, or {id, error: {name, message}}.

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

self.onmessage = async ({ data }) => {
  const { id } = data;
  try {
    zstd ??= import(data.fzstd).then((m) => setZstdDecompress(m.Decompress));
    await zstd;
    const parts = data.file ? splitClipFile(data.file) : data;
    const clip = await loadClip(parts.topology, parts.coefficients);
    if (data.tables) clip.gpuTables = gpuTables(clip, { width: data.width });
    self.postMessage({ id, clip }, [...transferables(clip)]);
  } catch (err) {
    self.postMessage({ id, error: { name: err?.name ?? 'Error', message: String(err?.message ?? err) } });
  }
};
