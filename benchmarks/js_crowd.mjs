// A crowd of one clip in headless Chromium (SwiftShader, software WebGL 2): 100 players of one clip in one
// scene, as 100 meshes (one attached player and 99 clone()s) at distinct times (crowdForm 'auto', the
// default; 'bytes', the form of fewer GPU bytes; 'always', the crowd form whatever its bytes) and at one
// time, and as an InstancedMesh with a time offset per instance (100 and 10 distinct offsets). Prints the
// GPU bytes the first player takes alone and each extra one adds (all 100's bytes less the first's, over
// 99; goal: at most 1% of the first's), and per frame the main-thread milliseconds of the 100 players'
// setTime and of renderer.render (goal: their sum at most 2 ms for all 100), split into three.js's own
// render of 100 plain meshes with a material each (measured in the same page) and ours (setTime and the
// render call beyond three.js's own); medians of FRAMES frames, the median of RUNS runs; with the load
// (uptime, os.loadavg) before and after. Each goal is printed beside its figure.
// Clips: CLIPS (comma-separated, default torus15k-loop.clip,horse.clip). The torus clips come from
// benchmarks/js_eval_clips.py, horse.clip is `pdeanim fit` (defaults: bones auto) of
// $SEQUENCES/horse-collapse.npz (default ../shared/data/sequences; made when missing, skipped without it).
// Run: [RUNS=3] [FRAMES=10] [WARMUP=5] [CLIPS=torus15k-loop.clip,horse.clip] [VARIANTS=...] node benchmarks/js_crowd.mjs [DIR]

import { execFileSync } from 'node:child_process';
import { createServer } from 'node:http';
import { existsSync, readFileSync, statSync } from 'node:fs';
import { loadavg, tmpdir } from 'node:os';
import { dirname, extname, join, normalize } from 'node:path';
import { fileURLToPath } from 'node:url';
import { launchChromium } from '../tests/browser/chromium.mjs';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..');
const dir = process.argv[2] ?? join(tmpdir(), 'pdeanim-js-bench');
// CLIPS=torus15k-rigid.clip etc. (js_eval_clips.py); CLIP= (one clip) as before
const CLIPS = (process.env.CLIPS ?? process.env.CLIP ?? 'torus15k-loop.clip,horse.clip').split(',').filter(Boolean);
const SEQUENCES = process.env.SEQUENCES ?? join(ROOT, '..', 'shared', 'data', 'sequences');
const N = 100;
const FRAMES = Number(process.env.FRAMES ?? 10);
const RUNS = Number(process.env.RUNS ?? 3);
const WARMUP = Number(process.env.WARMUP ?? 5); // frames before those measured
// 'rest': one evaluation per vertex (SwiftShader draws 100 x 15k vertices per frame on the CPU)
const NORMALS = process.env.NORMALS ?? 'rest';
const VARIANTS = (process.env.VARIANTS ?? `single,meshes,meshesBytes,meshesSame,instanced${N},instanced10,plainShared,plainOwn`).split(',');
const GOAL_BYTES = 1; // % of the first player's bytes per extra player
const GOAL_MS = 2; // main-thread ms per frame for all N

const python = process.env.PDEANIM_PYTHON ?? join(ROOT, '.venv', 'bin', 'python');
if (CLIPS.some((c) => c.startsWith('torus') && !existsSync(join(dir, c)))) {
  console.log(`making the clips in ${dir} ...`);
  execFileSync(python, [join(ROOT, 'benchmarks', 'js_eval_clips.py'), dir], { stdio: 'inherit' });
}
const HORSE = join(SEQUENCES, 'horse-collapse.npz');
if (CLIPS.includes('horse.clip') && !existsSync(join(dir, 'horse.clip'))) {
  if (existsSync(HORSE)) {
    console.log(`fitting ${HORSE} (defaults) into ${dir}/horse.clip ...`);
    execFileSync(python, ['-m', 'pdeanim_service.cli', 'fit', HORSE, '--out', join(dir, 'horse.clip'), '--quiet'], { stdio: 'inherit' });
  } else {
    console.log(`horse.clip skipped: no ${HORSE} (set SEQUENCES)`);
    CLIPS.splice(CLIPS.indexOf('horse.clip'), 1);
  }
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
const results = {};
const browser = await launchChromium();
try {
  for (const CLIP of CLIPS) {
  const runs = (results[CLIP] = []);
  for (let r = 0; r < RUNS; r++) {
    const page = await browser.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(String(e)));
    await page.goto(`http://127.0.0.1:${server.address().port}/page.html`, { waitUntil: 'load' });
    await page.waitForFunction('window.ready === true', { timeout: 120_000 });
    const run = {};
    for (const variant of VARIANTS) {
      const job = { clipName: CLIP, frames: FRAMES, n: N, variant, normals: NORMALS, warmup: WARMUP };
      Object.assign(run, await page.evaluate((j) => window.crowd(j), job));
    }
    runs.push(run);
    if (errors.length) throw new Error(errors.join('\n'));
    await page.close();
  }
  }
} finally {
  await browser.close();
  server.close();
}

for (const CLIP of CLIPS) report(CLIP, results[CLIP]);

/** Print one clip's figures with the goals beside them. */
function report(CLIP, runs) {
  const first = runs[0];
  const med = (path) => median(runs.map((x) => path.split('.').reduce((o, k) => o[k], x)));
  const m = (path) => med(path).toFixed(2);
  const pct = (a, b) => ((100 * a) / b).toFixed(2);
  const verdict = (ok) => (ok ? 'met' : 'NOT met');
  const has = (v) => first[v] !== undefined;
  const bones = first.bones ? `, ${first.bones} bones` : '';
  console.log(`${CLIP}: ${first.vertices} vertices, ${first.curves} curves, ${first.segments} segments${bones}; ${first.renderer}`);
  console.log(`${N} players (normals '${NORMALS}'), medians of ${FRAMES} frames, median of ${RUNS} runs (setTime / render call / frame with sync):`);
  if (has('single')) console.log(`  one player alone: ${m('single.setTimeMs')} / ${m('single.renderMs')} / ${m('single.frameMs')} ms`);
  // three.js's own: the render call of 100 plain meshes with a material each (as 100 players have), same page
  const own = has('plainOwn') ? (x) => x.plainOwn.renderMs : null;
  const mainThread = (v) => {
    const ms = median(runs.map((x) => x[v].setTimeMs + x[v].renderMs));
    let split = '';
    if (own) {
      const ours = median(runs.map((x) => x[v].setTimeMs + Math.max(0, x[v].renderMs - own(x))));
      split = ` = ours ${ours.toFixed(2)} (setTime + render call beyond three.js's own) + three.js's own ${median(runs.map(own)).toFixed(2)}`;
    }
    return `main thread (setTime + render call) ${ms.toFixed(2)} ms for all ${N}${split} (goal <= ${GOAL_MS} ms: ${verdict(ms <= GOAL_MS)})`;
  };
  const byteLine = (extra, base) =>
    `each extra player adds ${extra.toFixed(0)} bytes = ${pct(extra, base)}% of the first's ` +
    `(goal <= ${GOAL_BYTES}%: ${verdict((100 * extra) / base <= GOAL_BYTES)})`;
  const meshVariants = [
    ['meshes', "distinct times, crowdForm 'auto' (default)"],
    ['meshesBytes', "distinct times, crowdForm 'bytes'"],
    ['meshesAlways', "distinct times, crowdForm 'always'"],
    ['meshesSame', 'one time'],
  ];
  for (const [v, what] of meshVariants.filter(([x]) => has(x))) {
    const M = first[v];
    const extra = (M.totalBytes - M.firstBytes) / (N - 1);
    const form = M.crowd
      ? `crowd form: shared ${M.sharedBytes} incl. knot table ${M.knotBytes}, time rows ${M.rowBytes} each in an atlas of ${M.atlasBytes}`
      : `per-frame tables of ${M.rowBytes} bytes each; the crowd form would take ${M.formBytes?.crowd} against ${M.formBytes?.tables}`;
    console.log(
      `  ${N} meshes (1 player + ${N - 1} clone()s), ${what}: first player alone ${M.firstBytes} GPU bytes (data ` +
        `textures ${M.aloneShared}, per-frame table ${M.aloneFrame}, attributes ${M.attributeBytes}); all ${N}: ` +
        `${M.totalBytes} bytes (${form}; ${M.textures} data texture, ${M.geometries} geometry, ${M.programs} ` +
        `program key for all) vs ${N * M.firstBytes} unshared`,
    );
    console.log(`    ${byteLine(extra, M.firstBytes)}; the 100th alone adds ${M.rowBytes} bytes (${pct(M.rowBytes, M.firstBytes)}%)`);
    console.log(`    per frame: ${m(`${v}.setTimeMs`)} / ${m(`${v}.renderMs`)} / ${m(`${v}.frameMs`)} ms; ${mainThread(v)}`);
  }
  const one = (first.meshes ?? first.meshesBytes ?? first.meshesAlways ?? first.meshesSame)?.firstBytes;
  for (const k of [N, 10]) {
    const I = first[`instanced${k}`];
    if (!I || !one) continue;
    const perExtra = (I.gpuBytes - one) / (N - 1);
    const where = I.crowd ? `time rows ${I.frameBytes} in an atlas of ${I.atlasBytes}` : `per-frame tables ${I.frameBytes}`;
    console.log(
      `  InstancedMesh, ${k} distinct offsets (${I.crowd ? 'crowd form' : 'per-frame tables'}): ${I.gpuBytes} GPU bytes ` +
        `(shared ${I.sharedBytes}, ${where}, attributes ${I.attributeBytes} incl. pdeSlot ${I.slotBytes}); ` +
        `each extra instance adds ${perExtra.toFixed(0)} bytes = ${pct(perExtra, one)}% of one player alone ` +
        `(goal <= ${GOAL_BYTES}%: ${verdict((100 * perExtra) / one <= GOAL_BYTES)})`,
    );
    console.log(
      `    per frame: ${m(`instanced${k}.setTimeMs`)} / ${m(`instanced${k}.renderMs`)} / ${m(`instanced${k}.frameMs`)} ms; ` +
        mainThread(`instanced${k}`),
    );
  }
  if (has('meshesOneTable')) {
    console.log(
      `  ${N} meshes at one time sharing one FrameTables (crowd form ${first.meshesOneTable.crowd}: the per-frame ` +
        `table): ${m('meshesOneTable.setTimeMs')} / ${m('meshesOneTable.renderMs')} / ${m('meshesOneTable.frameMs')} ms`,
    );
  }
  if (has('plainShared') && has('plainOwn')) {
    console.log(
      `  peers, ${N} meshes of three.js alone (no clip): one shared material ${m('plainShared.renderMs')} ms, ` +
        `a material each (as ${N} players have) ${m('plainOwn.renderMs')} ms per render call`,
    );
  }
}
console.log(`after: ${uptime()}`);
