// The bone layer's shader in a real browser: headless Chromium (software WebGL 2) renders clips with bones
// (with a residual, without one, and with it on some curves only) through test/browser/gpu.html, in the vertex shader and in the evaluation
// pass, against the CPU fallback; the GLSL must compile and the positions read back from the shader must be
// the CPU evaluator's. Skipped (with the reason) when no Chromium is installed outside CI.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { spawn, spawnSync } from 'node:child_process';
import { createServer } from 'node:http';
import { mkdtempSync, readFileSync, rmSync, statSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, extname, join, normalize } from 'node:path';
import { fileURLToPath } from 'node:url';
import { manifest } from './helpers.mjs';
import { boneClipParts } from './bonehelpers.mjs';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..');
const TYPES = { '.js': 'text/javascript', '.mjs': 'text/javascript', '.html': 'text/html' };
const man = manifest();
const byName = (name) => man.cases.find((c) => c.name === name);
// served from memory as /test/fixtures/NAME.clip: the first plays with rest normals, the second in the
// vertex shader, the others in the evaluation pass (gpu.html's order)
const CLIPS = {
  'bones-chord-res': boneClipParts(byName('fit-displacement-chord'), { K: 3, B: 4 }).file,
  'bones-chord-nores': boneClipParts(byName('fit-displacement-chord'), { K: 3, B: 4, residual: false }).file,
  'bones-loop-res': boneClipParts(byName('fit-displacement-chord-loop'), { K: 4, B: 5 }).file,
  'bones-spline-half': boneClipParts(byName('synthetic-displacement-chord-spline'), { K: 2, Sb: 6, zeroCurve: (c) => c % 2 === 0 }).file,
};

function findChromium() {
  for (const name of [process.env.PDEANIM_CHROMIUM, 'chromium', 'chromium-browser', 'google-chrome'].filter(Boolean)) {
    const r = spawnSync(name, ['--version'], { encoding: 'utf8', timeout: 60_000 });
    if (r.status === 0) return name;
  }
  return null;
}

/** Serve clients/js read-only (and the bone clips from memory) on 127.0.0.1; resolve with the page's result. */
function serve() {
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
    const clip = CLIPS[pathname.replace(/^\/test\/fixtures\/(.*)\.clip$/, '$1')];
    if (clip) {
      res.writeHead(200, { 'Content-Type': 'application/octet-stream' });
      res.end(Buffer.from(clip));
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

const chromium = findChromium();

test(
  'bone clips: the skinning shader renders what the CPU path renders, in headless Chromium',
  { skip: chromium ? false : 'no Chromium found (set PDEANIM_CHROMIUM or install chromium)', timeout: 300_000 },
  async () => {
    const { server, result } = await serve();
    const profile = mkdtempSync(join(tmpdir(), 'pdeanim-chromium-'));
    const names = [...Object.keys(CLIPS), 'bones-fit-k4-residual']; // + a fixture written by the Python library
    const url = `http://127.0.0.1:${server.address().port}/test/browser/gpu.html?cases=${names.join(',')}`;
    const flags = ['--headless=new', '--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'];
    const browser = spawn(chromium, [...flags, '--disable-gpu-sandbox', '--no-first-run', `--user-data-dir=${profile}`, url], {
      stdio: 'ignore',
      detached: true,
    });
    let timer;
    try {
      const r = await Promise.race([
        result,
        new Promise((_, reject) => {
          timer = setTimeout(() => reject(new Error('no result from the page within 240 s')), 240_000);
        }),
      ]);
      assert.deepEqual(r.errors, []);
      assert.deepEqual(r.passes, [false, false, true, true, true]); // the vertex shader and the evaluation pass ran
      assert.equal(r.cases.length, names.length + 1); // + one transformed multi-mesh scene
      for (const c of r.cases) {
        for (const k of ['gpuVsCpu02', 'gpuVsCpu07']) {
          assert.ok(c[k].covered > 0.05, `${c.name}: the mesh covers ${c[k].covered} of the image`);
          assert.ok(c[k].differ < 0.005, `${c.name} ${k}: ${c[k].differ} of the pixels differ`);
        }
        // float32 skinning of positions up to ~the diagonal, plus the residual
        assert.ok(c.gpuError < 1e-6, `${c.name}: GPU positions deviate by ${c.gpuError} of the diagonal`);
        assert.ok(c.gpu02vs07.differ > 0.01, `${c.name}: the image does not change between t = 0.2 and 0.7`);
      }
    } finally {
      clearTimeout(timer);
      const exited = new Promise((resolve) => browser.once('exit', resolve));
      if (browser.exitCode === null) {
        try {
          process.kill(-browser.pid, 'SIGKILL'); // the whole group
        } catch {
          browser.kill('SIGKILL');
        }
      }
      await exited;
      server.close();
      rmSync(profile, { recursive: true, force: true, maxRetries: 5, retryDelay: 200 });
    }
  },
);
