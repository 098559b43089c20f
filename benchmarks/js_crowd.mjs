// A crowd of one clip in headless Chromium (SwiftShader, software WebGL 2): 100 players of the 15k-vertex
// looping torus clip in one scene, as 100 meshes (one attached player and 99 clone()s) at distinct times and
// at one time, and as an InstancedMesh with a time offset per instance (100 and 10 distinct offsets). Prints
// the GPU bytes the first player takes alone and each extra one adds (all 100's bytes less the first's, over
// 99; goal: at most 1% of the first's), and per frame the main-thread milliseconds of the 100 players'
// setTime and of renderer.render (goal: their sum at most 2 ms for all 100), medians of FRAMES frames, the
// median of RUNS runs; with the load (uptime, os.loadavg) before and after.
// Clips come from benchmarks/js_eval_clips.py (made when missing).
// Run: [RUNS=3] [FRAMES=10] [CLIP=torus15k-loop.clip] node benchmarks/js_crowd.mjs [DIR]

import { execFileSync } from 'node:child_process';
import { createServer } from 'node:http';
import { existsSync, readFileSync, statSync } from 'node:fs';
import { loadavg, tmpdir } from 'node:os';
import { dirname, extname, join, normalize } from 'node:path';
import { fileURLToPath } from 'node:url';
import { launchChromium } from '../tests/browser/chromium.mjs';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..');
const dir = process.argv[2] ?? join(tmpdir(), 'pdeanim-js-bench');
const CLIP = process.env.CLIP ?? 'torus15k-loop.clip'; // CLIP=torus15k-rigid.clip etc. (js_eval_clips.py)
const N = 100;
const FRAMES = Number(process.env.FRAMES ?? 10);
const RUNS = Number(process.env.RUNS ?? 3);
// 'rest': one evaluation per vertex (SwiftShader draws 100 x 15k vertices per frame on the CPU)
const NORMALS = process.env.NORMALS ?? 'rest';
const VARIANTS = ['single', 'meshes', 'meshesSame', 'meshesOneTable', `instanced${N}`, 'instanced10', 'plainShared', 'plainOwn'];
const GOAL_BYTES = 1; // % of the first player's bytes per extra player
const GOAL_MS = 2; // main-thread ms per frame for all N

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

const uptime = () =>
  `${execFileSync('uptime', { encoding: 'utf8' }).trim()} (os.loadavg ${loadavg().map((x) => x.toFixed(2)).join(' ')})`;
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
const med = (path) => median(runs.map((x) => path.split('.').reduce((o, k) => o[k], x)));
const m = (path) => med(path).toFixed(2);
const pct = (a, b) => ((100 * a) / b).toFixed(2);
const verdict = (ok) => (ok ? 'met' : 'NOT met');
console.log(`${CLIP}: ${first.vertices} vertices, ${first.curves} curves; ${first.renderer}`);
console.log(`${N} players (normals '${NORMALS}'), medians of ${FRAMES} frames, median of ${RUNS} runs (setTime / render call / frame with sync):`);
console.log(`  one player alone: ${m('single.setTimeMs')} / ${m('single.renderMs')} / ${m('single.frameMs')} ms`);
const mainThread = (v) => {
  const ms = median(runs.map((x) => x[v].setTimeMs + x[v].renderMs));
  return `main thread (setTime + render call) ${ms.toFixed(2)} ms for all ${N} (goal <= ${GOAL_MS} ms: ${verdict(ms <= GOAL_MS)})`;
};
for (const [v, what] of [['meshes', 'distinct times'], ['meshesSame', 'one time']]) {
  const M = first[v];
  const extra = (M.totalBytes - M.firstBytes) / (N - 1);
  console.log(
    `  ${N} meshes (1 player + ${N - 1} clone()s), ${what}: first player alone ${M.firstBytes} GPU bytes (data ` +
      `textures ${M.aloneShared}, per-frame table ${M.aloneFrame}, attributes ${M.attributeBytes}); all ${N}: ` +
      `${M.totalBytes} bytes (crowd form ${M.crowd}: shared ${M.sharedBytes} incl. knot table ${M.knotBytes}, ` +
      `time rows ${M.rowBytes} each in an atlas of ${M.atlasBytes}; ${M.textures} data texture, ${M.geometries} ` +
      `geometry, ${M.programs} program key for all) vs ${N * M.firstBytes} unshared`,
  );
  console.log(
    `    each extra player adds ${extra.toFixed(0)} bytes = ${pct(extra, M.firstBytes)}% of the first's ` +
      `(goal <= ${GOAL_BYTES}%: ${verdict((100 * extra) / M.firstBytes <= GOAL_BYTES)}); the 100th alone adds ` +
      `its row, ${M.rowBytes} bytes (${pct(M.rowBytes, M.firstBytes)}%)`,
  );
  console.log(`    per frame: ${m(`${v}.setTimeMs`)} / ${m(`${v}.renderMs`)} / ${m(`${v}.frameMs`)} ms; ${mainThread(v)}`);
}
const one = first.meshes.firstBytes;
for (const k of [N, 10]) {
  const I = first[`instanced${k}`];
  const perExtra = (I.gpuBytes - one) / (N - 1);
  console.log(
    `  InstancedMesh, ${k} distinct offsets: ${I.gpuBytes} GPU bytes (shared ${I.sharedBytes}, time rows ` +
      `${I.frameBytes} in an atlas of ${I.atlasBytes}, attributes ${I.attributeBytes} incl. pdeSlot ${I.slotBytes}); ` +
      `each extra instance adds ${perExtra.toFixed(0)} bytes = ${pct(perExtra, one)}% of one player alone ` +
      `(goal <= ${GOAL_BYTES}%: ${verdict((100 * perExtra) / one <= GOAL_BYTES)})`,
  );
  console.log(
    `    per frame: ${m(`instanced${k}.setTimeMs`)} / ${m(`instanced${k}.renderMs`)} / ${m(`instanced${k}.frameMs`)} ms; ` +
      mainThread(`instanced${k}`),
  );
}
console.log(
  `  ${N} meshes at one time sharing one FrameTables (crowd form ${first.meshesOneTable.crowd}: the per-frame ` +
    `table): ${m('meshesOneTable.setTimeMs')} / ${m('meshesOneTable.renderMs')} / ${m('meshesOneTable.frameMs')} ms`,
);
console.log(
  `  peers, ${N} meshes of three.js alone (no clip): one shared material ${m('plainShared.renderMs')} ms, ` +
    `a material each (as ${N} players have) ${m('plainOwn.renderMs')} ms per render call`,
);
console.log(`after: ${uptime()}`);
