// Per-frame JavaScript of the GPU path of the JavaScript client (clients/js): timeUniforms(), which rewrites
// the per-frame table (each curve's coefficients of the frame, short curves' positions, rigid rotations) the shader reads, on dynamic-PDE clips with thousands of
// curves. Median of 3 runs of 2000 pseudo-random t (each run's median per call), after a JIT warm-up; also
// the cost when t moves within a frame but maps to the same segment and tau (a paused or clamped clip).
// Run: node benchmarks/js_table_speed.mjs CLIP [CLIP...]   (CLIP: a .clip file written by the Python library, or
// TOPOLOGY,COEFFICIENTS: the two part files, e.g. the service's blobs)

import { readFileSync } from 'node:fs';
import { cpus, loadavg } from 'node:os';
import { basename } from 'node:path';
import { performance } from 'node:perf_hooks';
import { decodeClip, decodeClipFile } from '../clients/js/src/index.js';
import { gpuLayout, timeUniforms } from '../clients/js/src/gpu.js';

const load = () =>
  loadavg()
    .map((x) => x.toFixed(2))
    .join(' ');
const median = (xs) => [...xs].sort((a, b) => a - b)[Math.floor(xs.length / 2)];

let seed = 12345; // a small LCG: the same times on every run
const rand = () => (seed = (seed * 1103515245 + 12345) % 2147483648) / 2147483648;

if (process.argv.length < 3) {
  console.error('usage: node benchmarks/js_table_speed.mjs CLIP [CLIP...]');
  process.exit(2);
}
console.log(`node ${process.version}, ${cpus().length} CPUs, load average ${load()} (shared machine)`);
for (const path of process.argv.slice(2)) {
  const parts = path.split(',');
  const clip =
    parts.length === 2
      ? decodeClip(readFileSync(parts[0]), readFileSync(parts[1]))
      : decodeClipFile(readFileSync(path));
  if (clip.kind !== 'dynamic-pde') continue;
  const layout = gpuLayout(clip);
  // times the clip takes: any for a looping clip, [0, 1] otherwise (others are refused)
  const ts = Array.from({ length: 2000 }, () => (clip.looping ? rand() * 1.2 - 0.1 : rand()));
  for (const t of ts.slice(0, 300)) timeUniforms(layout, t); // warm-up (JIT)
  const runs = [];
  for (let r = 0; r < 3; r++) {
    const per = ts.map((t) => {
      const a = performance.now();
      timeUniforms(layout, t);
      return performance.now() - a;
    });
    runs.push(median(per));
  }
  // the same segment and tau as the previous call (a paused clip; one period later for a looping one)
  const same = [];
  for (let i = 0; i < 2000; i++) {
    const a = performance.now();
    timeUniforms(layout, clip.looping ? 0.5 + i : 0.5);
    same.push(performance.now() - a);
  }
  console.log(
    `${parts.map((x) => basename(x).slice(0, 12)).join(',')}: ${clip.nVertices} vertices, ${clip.nCurves} curves, ${clip.nSegments} segments, ` +
      `${clip.motion}${clip.looping ? ', looping' : ''}`,
  );
  const each = runs.map((x) => x.toFixed(4)).join(', ');
  console.log(
    `  timeUniforms per frame: median ${median(runs).toFixed(4)} ms (runs ${each});` +
      ` unchanged segment/tau: ${median(same).toFixed(4)} ms`,
  );
}
console.log(`load average after: ${load()}`);
