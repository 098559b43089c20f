// First frame of a large clip in headless Chromium (software WebGL, SwiftShader): milliseconds from the end of
// the download to the first frame drawn (decode in a Web Worker, or on the main thread), the longest main-
// thread task in that time, and the clip's GPU memory (data textures, per-vertex attributes, evaluation
// pass) against the download. Medians of --runs fresh pages per mode.
//
//   node benchmarks/js_first_frame.mjs [CLIP] [--runs 5]
//
// CLIP defaults to the 33.7k-vertex clip of benchmarks/js_large_clip.py (run that first).
import { createServer } from 'node:http';
import { readFileSync, statSync } from 'node:fs';
import { loadavg } from 'node:os';
import { dirname, extname, join, normalize, relative } from 'node:path';
import { fileURLToPath } from 'node:url';
import { launchChromium } from '../tests/browser/chromium.mjs';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..');
const args = process.argv.slice(2);
const runs = Number(args[args.indexOf('--runs') + 1] || 5) || 5;
const clipPath = args.find((a) => !a.startsWith('--') && !/^\d+$/.test(a))
  ?? join(ROOT, 'benchmarks/.cache/js-large/clip33700-36.clip');
const TYPES = { '.js': 'text/javascript', '.mjs': 'text/javascript', '.html': 'text/html' };
const server = createServer((req, res) => {
  const path = normalize(join(ROOT, decodeURIComponent(new URL(req.url, 'http://x').pathname)));
  try {
    if (!path.startsWith(ROOT) || !statSync(path).isFile()) throw new Error('no');
    res.writeHead(200, { 'Content-Type': TYPES[extname(path)] ?? 'application/octet-stream' });
    res.end(readFileSync(path));
  } catch {
    res.writeHead(404).end();
  }
});
await new Promise((r) => server.listen(0, '127.0.0.1', r));
const load = () => loadavg().map((x) => x.toFixed(2)).join(' ');
console.log(`load average before: ${load()}; clip ${clipPath} (${statSync(clipPath).size} bytes)`);
const median = (xs) => [...xs].sort((a, b) => a - b)[Math.floor(xs.length / 2)];
const browser = await launchChromium();
try {
  for (const worker of [true, false]) {
    const results = [];
    for (let r = 0; r < runs; r++) {
      const page = await browser.newPage();
      const url = `http://127.0.0.1:${server.address().port}/benchmarks/js_first_frame.html?worker=${worker ? 1 : 0}` +
        `&clip=/${relative(ROOT, clipPath)}`;
      await page.goto(url);
      await page.waitForFunction('window.result !== undefined', { timeout: 300_000 });
      const res = await page.evaluate('window.result');
      await page.close();
      if (res.error) throw new Error(res.error);
      results.push(res);
    }
    const m = (k) => median(results.map((x) => x[k]));
    const first = results[0];
    const gpu = first.texture_bytes + first.attribute_bytes + first.pass_bytes;
    console.log(`${worker ? 'worker' : 'main thread'}: first frame ${m('first_frame_ms').toFixed(0)} ms after the download ` +
      `(decode ${m('decode_ms').toFixed(0)} ms, attach + draw ${m('attach_and_draw_ms').toFixed(0)} ms = ` +
      `${m('attach_ms').toFixed(0)} + ${m('draw_ms').toFixed(0)}; longest main-thread ` +
      `task ${m('longest_main_task_ms').toFixed(0)} ms), runs: ${results.map((x) => x.first_frame_ms.toFixed(0)).join(', ')}`);
    if (worker) {
      console.log(`clip: ${first.vertices} vertices, ${first.curves} curves, ${first.segments} segments; ` +
        `CLIP file ${first.download_bytes} bytes, its two parts (the service's download) ${first.parts_bytes} bytes; GPU ${first.gpu_mode}: textures ${first.texture_bytes}, ` +
        `attributes ${first.attribute_bytes}, pass ${first.pass_bytes} = ${gpu} bytes (${(gpu / first.parts_bytes).toFixed(1)}x the parts)`);
    }
  }
} finally {
  await browser.close();
  server.close();
}
console.log(`load average after: ${load()}`);
