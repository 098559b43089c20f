// A crowd of one clip in headless Chromium (SwiftShader, software WebGL 2): 100 players of the 15k-vertex
// looping torus clip in one scene, as 100 meshes (one attached player and 99 clone()s) and as an
// InstancedMesh with a time offset per instance (100 and 10 distinct offsets). Prints the GPU bytes the
// first player takes and each extra one adds (goal: at most 1% of the first's), and per frame the
// main-thread milliseconds of the 100 players' setTime and of renderer.render (goal: at most 2 ms for all
// 100), medians of `frames` frames, the median of RUNS runs; with the load (uptime) before and after.
// Clips come from benchmarks/js_eval_clips.py (made when missing).
// Run: node benchmarks/js_crowd.mjs [DIR]

import { execFileSync } from 'node:child_process';
import { createServer } from 'node:http';
import { existsSync, readFileSync, statSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, extname, join, normalize } from 'node:path';
import { fileURLToPath } from 'node:url';
import { launchChromium } from '../tests/browser/chromium.mjs';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..');
const dir = process.argv[2] ?? join(tmpdir(), 'pdeanim-js-bench');
const CLIP = 'torus15k-loop.clip';
const N = 100;
const FRAMES = Number(process.env.FRAMES ?? 10);
const RUNS = Number(process.env.RUNS ?? 3);
// 'rest': one evaluation per vertex (SwiftShader draws 100 x 15k vertices per frame on the CPU)
const NORMALS = process.env.NORMALS ?? 'rest';
const VARIANTS = ['single', 'meshes', `instanced${N}`, 'instanced10'];

if (!existsSync(join(dir, CLIP))) {
  console.log(`making the clips in ${dir} ...`);
  const python = process.env.PDEANIM_PYTHON ?? join(ROOT, '.venv', 'bin', 'python');
  execFileSync(python, [join(ROOT, 'benchmarks', 'js_eval_clips.py'), dir], { stdio: 'inherit' });
}

function file(urlPath) {
  if (urlPath === '/page.html') return join(ROOT, 'benchmarks', 'js_crowd.html');
  if (urlPath.startsWith('/js/')) return normalize(join(ROOT, 'clients', 'js', urlPath.slice(4)));
  if (urlPath.startsWith('/clips/')) return normalize(join(dir, urlPath.slice(7)));
  return null;
}

const server = createServer((req, res) => {
  const path = file(new URL(req.url, 'http://x').pathname);
  try {
    if (!path || !statSync(path).isFile()) throw new Error();
    const types = { '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript' };
    res.writeHead(200, { 'Content-Type': types[extname(path)] ?? 'application/octet-stream' });
    res.end(readFileSync(path));
  } catch {
    res.writeHead(404).end();
  }
});
await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));

const uptime = () => execFileSync('uptime', { encoding: 'utf8' }).trim();
const median = (xs) => [...xs].sort((a, b) => a - b)[xs.length >> 1];
console.log(`before: ${uptime()}`);
const runs = [];
const browser = await launchChromium();
try {
  for (let r = 0; r < RUNS; r++) {
    const page = await browser.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(String(e)));
    await page.goto(`http://127.0.0.1:${server.address().port}/page.html`, { waitUntil: 'load' });
    await page.waitForFunction('window.ready === true', { timeout: 120_000 });
    const run = {};
    for (const variant of VARIANTS) {
      const job = { clipName: CLIP, frames: FRAMES, n: N, variant, normals: NORMALS };
      Object.assign(run, await page.evaluate((j) => window.crowd(j), job));
    }
    runs.push(run);
    if (errors.length) throw new Error(errors.join('\n'));
    await page.close();
  }
} finally {
  await browser.close();
  server.close();
}

const first = runs[0];
const m = (path) => median(runs.map((x) => path.split('.').reduce((o, k) => o[k], x))).toFixed(2);
const pct = (a, b) => ((100 * a) / b).toFixed(2);
const M = first.meshes;
console.log(`${CLIP}: ${first.vertices} vertices, ${first.curves} curves; ${first.renderer}`);
console.log(`${N} players (normals '${NORMALS}'), medians of ${FRAMES} frames, median of ${RUNS} runs (setTime / render call / frame with sync):`);
console.log(`  one player alone: ${m('single.setTimeMs')} / ${m('single.renderMs')} / ${m('single.frameMs')} ms`);
console.log(
  `  ${N} meshes (1 player + ${N - 1} clone()s): first player ${M.firstBytes} GPU bytes (data texture ` +
    `${M.sharedBytes}, per-frame table ${M.frameBytes}, attributes ${M.attributeBytes}); each extra adds ` +
    `${M.frameBytes} bytes (${pct(M.frameBytes, M.firstBytes)}% of the first's; ${M.textures} data texture, ` +
    `${M.geometries} geometry for all); all ${N}: ${M.totalBytes} bytes vs ${N * M.firstBytes} unshared`,
);
console.log(`    per frame: ${m('meshes.setTimeMs')} / ${m('meshes.renderMs')} / ${m('meshes.frameMs')} ms`);
for (const k of [N, 10]) {
  const I = first[`instanced${k}`];
  const perExtra = I.slotBytes / N + (k === N ? I.frameBytes / N : 0);
  console.log(
    `  InstancedMesh, ${k} distinct offsets: ${I.gpuBytes} GPU bytes (data texture ${I.sharedBytes}, ${k} ` +
      `per-frame tables ${I.frameBytes}, attributes ${I.attributeBytes} incl. pdeSlot ${I.slotBytes}); ` +
      `~${perExtra.toFixed(0)} bytes per extra instance (${pct(perExtra, M.firstBytes)}% of one player's)`,
  );
  console.log(`    per frame: ${m(`instanced${k}.setTimeMs`)} / ${m(`instanced${k}.renderMs`)} / ${m(`instanced${k}.frameMs`)} ms`);
}
console.log(`after: ${uptime()}`);
