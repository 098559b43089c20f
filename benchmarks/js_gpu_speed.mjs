// GPU playback speed of the JavaScript client in headless Chromium (SwiftShader, software WebGL 2): median
// frame time (render + 1-pixel read-back) of a 50k-vertex clip as a plain mesh, on the GPU (in the vertex
// shader, in an evaluation pass, with rest normals) and on the CPU, with the JavaScript per frame. Clips
// come from benchmarks/js_eval_clips.py --50k (made when missing).
// Run: node benchmarks/js_gpu_speed.mjs [DIR]

import { execFileSync, spawn } from 'node:child_process';
import { createServer } from 'node:http';
import { existsSync, mkdtempSync, readFileSync, rmSync, statSync } from 'node:fs';
import { cpus, loadavg, tmpdir } from 'node:os';
import { dirname, extname, join, normalize } from 'node:path';
import { fileURLToPath } from 'node:url';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..');
const dir = process.argv[2] ?? join(tmpdir(), 'pdeanim-js-bench');
const NAMES = ['torus50k-displacement.clip', 'torus50k-rigid.clip'];
const chromium = process.env.PDEANIM_CHROMIUM ?? 'chromium';

if (!NAMES.every((n) => existsSync(join(dir, n)))) {
  console.log(`making the clips in ${dir} ...`);
  const script = join(ROOT, 'benchmarks', 'js_eval_clips.py');
  execFileSync(join(ROOT, '.venv', 'bin', 'python'), [script, dir, '--50k'], { stdio: 'inherit' });
}

function file(urlPath) {
  if (urlPath === '/page.html') return join(ROOT, 'benchmarks', 'js_gpu_speed.html');
  if (urlPath.startsWith('/js/')) return normalize(join(ROOT, 'clients', 'js', urlPath.slice(4)));
  if (urlPath.startsWith('/clips/')) return normalize(join(dir, urlPath.slice(7)));
  return null;
}

async function measure(name) {
  let deliver;
  const result = new Promise((resolve) => {
    deliver = resolve;
  });
  const server = createServer((req, res) => {
    if (req.method === 'POST') {
      let body = '';
      req.on('data', (c) => (body += c));
      req.on('end', () => {
        res.end();
        deliver(JSON.parse(body));
      });
      return;
    }
    const path = file(new URL(req.url, 'http://x').pathname);
    try {
      if (!path || !statSync(path).isFile()) throw new Error();
      const types = { '.html': 'text/html', '.js': 'text/javascript' };
      const type = types[extname(path)] ?? 'application/octet-stream';
      res.writeHead(200, { 'Content-Type': type });
      res.end(readFileSync(path));
    } catch {
      res.writeHead(404).end();
    }
  });
  await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));
  const profile = mkdtempSync(join(tmpdir(), 'pdeanim-bench-chromium-'));
  const url = `http://127.0.0.1:${server.address().port}/page.html?clip=${name}&frames=60`;
  const browser = spawn(
    chromium,
    [
      '--headless=new',
      '--no-sandbox',
      '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader',
      '--disable-gpu-sandbox',
      '--no-first-run',
      `--user-data-dir=${profile}`,
      url,
    ],
    { stdio: 'ignore' },
  );
  try {
    return await result;
  } finally {
    const exited = new Promise((resolve) => browser.once('exit', resolve));
    browser.kill('SIGKILL');
    await exited;
    server.close();
    rmSync(profile, { recursive: true, force: true, maxRetries: 5, retryDelay: 200 });
  }
}

const load = () =>
  loadavg()
    .map((x) => x.toFixed(2))
    .join(' ');
console.log(`${cpus().length} CPUs, load average ${load()} (shared machine)`);
for (const name of NAMES) {
  const r = await measure(name);
  if (r.error) throw new Error(r.error);
  const f = (x) => `${x.frameMs.toFixed(1)} ms/frame (JS ${x.jsMs.toFixed(2)} ms)`;
  console.log(`${name}: ${r.vertices} vertices, ${r.renderer}`);
  console.log(`  plain mesh ${f(r.plain)}; CPU path ${f(r.cpu)}`);
  console.log(
    `  GPU in the vertex shader ${f(r.gpu_vertex)}; GPU evaluation pass ${f(r.gpu_pass)}; ` +
      `GPU with rest normals ${f(r.gpu_rest)}`,
  );
}
console.log(`load average after: ${load()}`);
