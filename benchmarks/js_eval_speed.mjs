// CPU evaluation speed of the JavaScript client (clients/js) on 15k-vertex clips: one frame per call into a
// preallocated Float32Array, median of 2000 random t after a warm-up (goal < 2 ms per frame), plus the
// one-off decode + precompute time and the per-frame JavaScript of the GPU path (uniforms + curve table).
// Clips come from benchmarks/js_eval_clips.py (run through .venv/bin/python when missing).
// Run: node benchmarks/js_eval_speed.mjs [CLIPDIR]

import { execFileSync } from 'node:child_process';
import { existsSync, readFileSync } from 'node:fs';
import { cpus, loadavg, tmpdir } from 'node:os';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';
import { performance } from 'node:perf_hooks';
import { createEvaluator, decodeClipFile } from '../clients/js/src/index.js';
import { gpuLayout, timeUniforms } from '../clients/js/src/gpu.js';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..');
const dir = process.argv[2] ?? join(tmpdir(), 'pdeanim-js-bench');
const NAMES = ['torus15k-displacement', 'torus15k-rigid', 'torus15k-loop', 'eel23k-cyclic'];

if (!NAMES.every((n) => existsSync(join(dir, `${n}.clip`)))) {
  console.log(`making the clips in ${dir} ...`);
  execFileSync(join(ROOT, '.venv', 'bin', 'python'), [join(ROOT, 'benchmarks', 'js_eval_clips.py'), dir], {
    stdio: 'inherit',
  });
}

function stats(samples) {
  const s = [...samples].sort((a, b) => a - b);
  const q = (p) => s[Math.min(s.length - 1, Math.floor(p * s.length))];
  return { median: q(0.5), p10: q(0.1), p90: q(0.9) };
}

// deterministic pseudo-random times (a small LCG) so runs are comparable
let seed = 12345;
const rand = () => (seed = (seed * 1103515245 + 12345) % 2147483648) / 2147483648;

console.log(
  `node ${process.version}, ${cpus().length} CPUs, load average ${loadavg()
    .map((x) => x.toFixed(2))
    .join(' ')}` + ' (shared machine)',
);
for (const name of NAMES) {
  const bytes = readFileSync(join(dir, `${name}.clip`));
  const t0 = performance.now();
  const clip = decodeClipFile(bytes);
  const t1 = performance.now();
  const ev = createEvaluator(clip);
  const t2 = performance.now();
  const out = new Float32Array(clip.nVertices * 3);
  const ts = Array.from({ length: 2000 }, () => rand() * 1.2 - 0.1);
  for (const t of ts.slice(0, 200)) ev.evaluate(t, out); // warm-up (JIT)
  const samples = ts.map((t) => {
    const a = performance.now();
    ev.evaluate(t, out);
    return performance.now() - a;
  });
  const s = stats(samples);
  const t3 = performance.now();
  const layout = gpuLayout(clip);
  const t4 = performance.now();
  const uni = ts.map((t) => {
    const a = performance.now();
    timeUniforms(layout, t);
    return performance.now() - a;
  });
  const extra =
    clip.kind === 'dynamic-pde'
      ? `, ${clip.nCurves} curves, ${clip.nSegments} segments, ${clip.motion}` +
        `${clip.looping ? ', looping' : ''}`
      : ', cyclic-spine';
  console.log(`${name}: ${clip.nVertices} vertices${extra}`);
  console.log(
    `  CPU evaluate one frame: median ${s.median.toFixed(3)} ms, p10 ${s.p10.toFixed(3)} ms, ` +
      `p90 ${s.p90.toFixed(3)} ms (goal < 2 ms)`,
  );
  console.log(
    `  decode ${(t1 - t0).toFixed(1)} ms, precompute ${(t2 - t1).toFixed(1)} ms, GPU textures ` +
      `${(t4 - t3).toFixed(1)} ms; GPU-path JS per frame (uniforms + per-curve table): ` +
      `median ${(stats(uni).median * 1e3).toFixed(2)} us`,
  );
}
console.log(
  `load average after: ${loadavg()
    .map((x) => x.toFixed(2))
    .join(' ')}`,
);
