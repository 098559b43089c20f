// An instanced crowd in a real browser: headless Chromium (software WebGL 2) renders an InstancedMesh played
// with a time offset per instance, and separate players (clone()s) at the same times; the images must agree,
// and differ from the crowd without offsets. Skipped (with the reason) when no Chromium is installed.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { spawn, spawnSync } from 'node:child_process';
import { createServer } from 'node:http';
import { mkdtempSync, readFileSync, rmSync, statSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, extname, join, normalize } from 'node:path';
import { fileURLToPath } from 'node:url';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..');
// the paper's time pairs (rigid, looping), spline items, a cyclic clip
const CASES = ['fit-rigid-paper-loop', 'fit-displacement-chord-smooth-spline', 'cyclic-trout-travelling-rotate-vertical'];
const TYPES = { '.js': 'text/javascript', '.mjs': 'text/javascript', '.html': 'text/html' };

function findChromium() {
  const names = [process.env.PDEANIM_CHROMIUM, 'chromium', 'chromium-browser', 'google-chrome'].filter(
    Boolean,
  );
  for (const name of names) {
    const r = spawnSync(name, ['--version'], { encoding: 'utf8', timeout: 60_000 });
    if (r.status === 0) return name;
  }
  return null;
}

/** Serve clients/js read-only on 127.0.0.1 and resolve with the page's POSTed result. */
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
    const path = normalize(join(ROOT, decodeURIComponent(new URL(req.url, 'http://x').pathname)));
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
  'an InstancedMesh with time offsets renders what separate players at those times render, in headless Chromium',
  { skip: chromium ? false : 'no Chromium found (set PDEANIM_CHROMIUM or install chromium)', timeout: 300_000 },
  async () => {
    const { server, result } = await serve();
    const profile = mkdtempSync(join(tmpdir(), 'pdeanim-chromium-'));
    const url = `http://127.0.0.1:${server.address().port}/test/browser/crowd.html?cases=${CASES.join(',')}`;
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
      { stdio: 'ignore', detached: true }, // its own process group: renderer and GPU processes go with it
    );
    let timer;
    try {
      const r = await Promise.race([
        result,
        new Promise((_, reject) => {
          timer = setTimeout(() => reject(new Error('no result from the page within 240 s')), 240_000);
        }),
      ]);
      assert.deepEqual(r.errors, []);
      assert.equal(r.cases.length, CASES.length);
      for (const c of r.cases) {
        assert.ok(c.shared, `${c.name}: the clones share the clip's data texture`);
        assert.ok(c.crowdVsSeparate.covered > 0.01, `${c.name}: the crowd covers ${c.crowdVsSeparate.covered}`);
        // same meshes, same times: only rasterisation may differ (0 seen); 0.5 % leaves room for drivers
        assert.ok(c.crowdVsSeparate.differ < 0.005, `${c.name}: ${c.crowdVsSeparate.differ} of the pixels differ`);
        assert.ok(c.crowdVsInSync.differ > 0.002, `${c.name}: the offsets change nothing (${c.crowdVsInSync.differ})`);
      }
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
  },
);
