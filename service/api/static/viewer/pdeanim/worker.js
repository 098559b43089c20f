// The Web Worker that decodes a clip and builds its GPU tables off the main thread (offthread.js starts it);
// streamable clips are decoded here window by window (streamOp below).
// Its first message is {ready: true} (its modules loaded). Messages in: {id, fzstd (fzstd's URL as the page
// resolves it, or null), topology and coefficients (ArrayBuffers) or file (a CLIP file), tables (build
// gpuTables), width}; out: {id, clip} with every typed array's buffer transferred, or {id, error: {name,
// message}}. Bundlers (Vite, webpack, esbuild with this file as an entry point) bundle fzstd into the worker
// through the import below; an unbundled worker cannot resolve the bare specifier and takes the page's URL.

import { ClipFormatError, setZstdDecompress } from './container.js';
import { loadClip, sha256Hex, splitClipFile } from './clip.js';
import { gpuTables, windowTables } from './gpu.js';
import { decodeStreamHead, decodeStreamWindow, windowFields } from './streamformat.js';

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

/** The streamable clips open here: sid → {shell, r, spline} (stream.js decodes their windows one by one). */
const streams = new Map();

/** The buffers of value's typed arrays but those of keep's (which this worker goes on using). */
function handOver(value, keep) {
  const kept = transferables(keep);
  return [...transferables(value)].filter((b) => !kept.has(b));
}

/**
 * Streamable clips (docs/format.md §3.10). {op: 'open', sid, topology, head, tables, width}: decode the head
 * (topology_id checked) and the GPU tables all windows share → {id, stream: true, clip (the shell), tables};
 * {op: 'window', sid, index, bytes, keep} → {id, stream: true, clip (the window's own fields), tables
 * (timeIndex, tangents)}, or, keep false, {id, stream: true, advanced: index} (only the state the window
 * carries on to the next is kept: windows are decoded in order); {op: 'forget', sid, indices}: drop the states
 * those windows carry on (no answer); {op: 'close', sid}.
 */
async function streamOp(data) {
  const { id } = data;
  if (data.op === 'close') {
    streams.delete(data.sid);
    return;
  }
  if (data.op === 'forget') {
    // stream.js drops the states no window it holds starts from: memory stays flat however long the clip
    const open = streams.get(data.sid);
    for (const j of data.indices ?? []) open?.states.delete(j);
    return;
  }
  if (data.op === 'open') {
    const shell = decodeStreamHead(data.topology, data.head);
    if (shell.topologyId) {
      const have = await sha256Hex(data.topology);
      if (have !== null && have !== shell.topologyId) {
        throw new ClipFormatError('the coefficients were made for another topology part (topology_id mismatch)');
      }
    }
    const tables = data.tables ? gpuTables(shell, { width: data.width }) : null;
    streams.set(data.sid, { shell, r: tables?.r ? tables.r.slice() : null, spline: Boolean(tables?.spline), states: new Map() });
    self.postMessage({ id, stream: true, clip: shell, tables }, handOver(tables, shell));
    return;
  }
  const state = streams.get(data.sid);
  if (!state) throw new Error(`no open stream ${data.sid} in the decoder worker`);
  // knots are carried from window to window: window i decodes with the state window i - 1 handed on
  const i = data.index;
  const out = decodeStreamWindow(state.shell, new Uint8Array(data.bytes), i, i > 0 ? (state.states.get(i - 1) ?? null) : null);
  state.states.set(i, out.state);
  if (!data.keep) {
    self.postMessage({ id, stream: true, advanced: i });
    return;
  }
  const clip = out.clip;
  const tables = state.r ? windowTables(clip, state.r, state.spline) : null;
  const fields = windowFields(clip);
  self.postMessage({ id, stream: true, clip: fields, tables }, handOver({ fields, tables }, state.shell));
}

self.onmessage = async ({ data }) => {
  const { id } = data;
  try {
    zstd ??= installZstd(data.fzstd);
    await zstd;
    if (data.op) {
      await streamOp(data);
      return;
    }
    const parts = data.file ? splitClipFile(data.file) : data;
    const clip = await loadClip(parts.topology, parts.coefficients);
    if (clip.windowed) {
      // the streamable layout held whole: its windows decode where it is played (the bytes go back there)
      const back = { topology: parts.topology.slice(), coefficients: parts.coefficients.slice() };
      self.postMessage({ id, windowed: back }, [back.topology.buffer, back.coefficients.buffer]);
      return;
    }
    if (data.tables) clip.gpuTables = gpuTables(clip, { width: data.width });
    self.postMessage({ id, clip }, [...transferables(clip)]);
  } catch (err) {
    self.postMessage({ id, error: { name: err?.name ?? 'Error', message: String(err?.message ?? err) } });
  }
};

self.postMessage({ ready: true });
