// Per-frame cost of the bone layer (format 1.1) in the JavaScript client (clients/js): CPU evaluation of a
// frame (skinning + residual) and the GPU path's per-frame JavaScript (timeUniforms: the B bone transforms
// evaluated and written as rows of the per-frame table, plus the residual's table), against the same clip
// without bones (1.0), and the GPU tables' bytes. The bone clips are made from a 1.0 CLIP file by adding a
// bone layer of B bones with K influences per vertex (clients/js/test/bonehelpers.mjs: pivots spread over the
// rest pose, mixed spline / pair channels on 4 bone segments), with the clip's curves as the residual, on every
// other curve only, or with a zero residual. Median of 3 runs of 500 pseudo-random t each (the run's median per call), after a warm-up.
// Run: node benchmarks/js_bones_speed.mjs CLIP [B] [K]   (e.g. the torus15k-displacement clip of
// benchmarks/js_eval_clips.py)

import { readFileSync } from 'node:fs';
import { cpus, loadavg } from 'node:os';
import { basename } from 'node:path';
import { performance } from 'node:perf_hooks';
import { createEvaluator, decodeClip, splitClipFile } from '../clients/js/src/index.js';
import { gpuLayout, textureBytes, timeUniforms } from '../clients/js/src/gpu.js';
import { withBones } from '../clients/js/test/bonehelpers.mjs';

const median = (xs) => [...xs].sort((a, b) => a - b)[Math.floor(xs.length / 2)];
let seed = 12345;
const rand = () => (seed = (seed * 1103515245 + 12345) % 2147483648) / 2147483648;

/** Median over 3 runs of the per-call median time (ms) of fn(t) over ts, after a warm-up. */
function timeIt(fn, ts) {
  for (const t of ts.slice(0, 100)) fn(t);
  const runs = [];
  for (let r = 0; r < 3; r++) {
    const each = ts.map((t) => {
      const t0 = performance.now();
      fn(t);
      return performance.now() - t0;
    });
    runs.push(median(each));
  }
  return median(runs);
}

const [path, B = '32', K = '4'] = process.argv.slice(2);
if (!path) {
  console.error('usage: node benchmarks/js_bones_speed.mjs CLIP [B] [K]');
  process.exit(2);
}
console.log(`node ${process.version}, ${cpus().length} CPUs, load average ${loadavg().map((x) => x.toFixed(2)).join(' ')}`);
const parts = splitClipFile(readFileSync(path));
const plain = decodeClip(parts.topology, parts.coefficients);
if (plain.kind !== 'dynamic-pde' || plain.motion !== 'displacement') {
  console.error('the clip must be a dynamic-pde clip of motion "displacement"');
  process.exit(2);
}
const options = { B: Number(B), K: Number(K), Sb: 4 };
const clips = {
  '1.0 (no bones)': plain,
  [`bones B=${B} K=${K} + residual`]: decodeClip(parts.topology, withBones(parts.coefficients, plain.rest, options)),
  [`bones B=${B} K=${K} + residual on every other curve`]: decodeClip(
    parts.topology,
    withBones(parts.coefficients, plain.rest, { ...options, zeroCurve: (c) => c % 2 === 1 }),
  ),
  [`bones B=${B} K=${K}, zero residual`]: decodeClip(
    parts.topology,
    withBones(parts.coefficients, plain.rest, { ...options, residual: false }),
  ),
};
const ts = Array.from({ length: 500 }, () => rand());
console.log(`${basename(path)}: ${plain.nVertices} vertices, ${plain.nCurves} curves, ${plain.nSegments} segments`);
for (const [name, clip] of Object.entries(clips)) {
  const ev = createEvaluator(clip);
  const out = new Float32Array(clip.nVertices * 3);
  const cpu = timeIt((t) => ev.evaluate(t, out), ts);
  const layout = gpuLayout(clip);
  const gpu = timeIt((t) => timeUniforms(layout, t), ts);
  const mib = (textureBytes(layout) / 2 ** 20).toFixed(2);
  console.log(`  ${name}: CPU frame ${cpu.toFixed(3)} ms, GPU per-frame JS ${gpu.toFixed(3)} ms, textures ${mib} MiB`);
}
