// Run a test page of clients/js in headless Chromium (software WebGL 2) and hand back what it POSTs to
// /result: shared by the browser tests (the GPU path, bone clips, crowds).

import { spawn, spawnSync } from 'node:child_process';
import { createServer } from 'node:http';
import { mkdtempSync, readFileSync, rmSync, statSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, extname, join, normalize } from 'node:path';
import { fileURLToPath } from 'node:url';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..');
const TYPES = { '.js': 'text/javascript', '.mjs': 'text/javascript', '.html': 'text/html' };

/** Chromium flags that expose WebGPU (SwiftShader's adapter where there is no GPU) to an http://127.0.0.1 page. */
export const WEBGPU_FLAGS = ['--enable-unsafe-webgpu'];

/** The Chromium to run ($PDEANIM_CHROMIUM or one on the PATH), or null. */
export function findChromium() {
  const names = [process.env.PDEANIM_CHROMIUM, 'chromium', 'chromium-browser', 'google-chrome'].filter(Boolean);
  for (const name of names) {
    const r = spawnSync(name, ['--version'], { encoding: 'utf8', timeout: 60_000 });
    if (r.status === 0) return name;
  }
  return null;
}

/**
 * Serve clients/js read-only on 127.0.0.1, and files (path -> bytes) from memory: {server, result}, result
 * resolving with the page's POSTed result.
 */
function serve(files) {
  let deliver;
  const result = new Promise((resolve) => {
    deliver = resolve;
  });
  const server = createServer((req, res) => {
    if (req.method === 'POST' && req.url === '/result') {
      let body = '';
      req.on('data', (c) => {
        body += c;
      });
      req.on('end', () => {
        res.end('ok');
        const r = JSON.parse(body);
        if (r.done || r.errors.length) deliver(r);
      });
      return;
    }
    const pathname = decodeURIComponent(new URL(req.url, 'http://x').pathname);
    if (files[pathname]) {
      res.writeHead(200, { 'Content-Type': 'application/octet-stream' });
      res.end(Buffer.from(files[pathname]));
      return;
    }
    const path = normalize(join(ROOT, pathname));
    try {
      if (!path.startsWith(ROOT) || !statSync(path).isFile()) throw new Error('not found');
      res.writeHead(200, { 'Content-Type': TYPES[extname(path)] ?? 'application/octet-stream' });
      res.end(readFileSync(path));
    } catch {
      res.writeHead(404).end();
    }
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve({ server, result })));
}

/**
 * Open page (a path under clients/js with its query, e.g. '/test/browser/gpu.html?cases=a,b') in headless
 * chromium and resolve with its result (rejects after timeoutMs); files: paths served from memory (path ->
 * bytes); flags: more Chromium flags (e.g. WEBGPU_FLAGS). The browser's whole process group, the server and the profile are gone when it settles.
 */
export async function pageResult(chromium, page, { files = {}, timeoutMs = 240_000, flags: extra = [] } = {}) {
  const { server, result } = await serve(files);
  const profile = mkdtempSync(join(tmpdir(), 'pdeanim-chromium-'));
  const url = `http://127.0.0.1:${server.address().port}${page}`;
  const flags = ['--headless=new', '--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
    '--disable-gpu-sandbox', '--no-first-run', `--user-data-dir=${profile}`, ...extra];
  // its own process group: renderer and GPU processes go with it
  const browser = spawn(chromium, [...flags, url], { stdio: 'ignore', detached: true });
  let timer;
  try {
    return await Promise.race([
      result,
      new Promise((_, reject) => {
        timer = setTimeout(() => reject(new Error(`no result from the page within ${timeoutMs / 1000} s`)), timeoutMs);
      }),
    ]);
  } finally {
    clearTimeout(timer);
    const exited = new Promise((resolve) => browser.once('exit', resolve));
    if (browser.exitCode === null) {
      try {
        process.kill(-browser.pid, 'SIGKILL'); // the whole group, so none still writes to the profile
      } catch {
        browser.kill('SIGKILL');
      }
    }
    await exited;
    server.close();
    rmSync(profile, { recursive: true, force: true, maxRetries: 5, retryDelay: 200 });
  }
}
