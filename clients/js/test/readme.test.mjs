// The README's browser example as written: its import map and its three.js example, pasted into a page served
// from a project folder laid out as npm installs it (node_modules/three, fzstd, pdeanim), run in headless
// Chromium against a service-like server (the clip's two parts, a skinned glTF with two animations). Skipped
// (with the reason) when no Chromium is installed outside CI.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { spawn, spawnSync } from 'node:child_process';
import { createServer } from 'node:http';
import { mkdtempSync, readFileSync, rmSync, statSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, extname, join, normalize } from 'node:path';
import { fileURLToPath } from 'node:url';
import { decodeClipFile, splitClipFile } from '../src/index.js';
import { FIXTURES, manifest, readBytes } from './helpers.mjs';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..');
const TYPES = { '.js': 'text/javascript', '.mjs': 'text/javascript', '.html': 'text/html' };
const README = readFileSync(join(ROOT, 'README.md'), 'utf8');

function findChromium() {
  for (const name of [process.env.PDEANIM_CHROMIUM, 'chromium', 'chromium-browser', 'google-chrome'].filter(Boolean)) {
    if (spawnSync(name, ['--version'], { encoding: 'utf8', timeout: 60_000 }).status === 0) return name;
  }
  return null;
}

/** The README's fenced blocks of a language, in order. */
function blocks(lang) {
  return [...README.matchAll(new RegExp('```' + lang + '\\n([\\s\\S]*?)```', 'g'))].map((m) => m[1]);
}

/** A GLB (bytes) over the clip's rest vertices: one joint skinning them all, animations walk and run. */
function skinnedGlb(clip) {
  const n = clip.nVertices;
  const views = [];
  const accessors = [];
  let offset = 0;
  const add = (array, type, componentType, extra = {}) => {
    const bytes = new Uint8Array(array.buffer, array.byteOffset, array.byteLength);
    views.push({ buffer: 0, byteOffset: offset, byteLength: bytes.length, bytes });
    offset += Math.ceil(bytes.length / 4) * 4;
    const per = { SCALAR: 1, VEC4: 4, VEC3: 3 }[type];
    accessors.push({ bufferView: views.length - 1, componentType, count: array.length / per, type, ...extra });
    return accessors.length - 1;
  };
  const rest = Float32Array.from(clip.rest);
  const min = [0, 1, 2].map((k) => Math.min(...rest.filter((_, i) => i % 3 === k)));
  const max = [0, 1, 2].map((k) => Math.max(...rest.filter((_, i) => i % 3 === k)));
  const position = add(rest, 'VEC3', 5126, { min, max });
  const joints = add(new Uint8Array(n * 4), 'VEC4', 5121);
  const weights = add(Float32Array.from({ length: n * 4 }, (_, i) => (i % 4 === 0 ? 1 : 0)), 'VEC4', 5126);
  const indices = add(Uint32Array.from(clip.faces), 'SCALAR', 5125);
  const times = add(new Float32Array([0, 1]), 'SCALAR', 5126, { min: [0], max: [1] });
  const turn = (a, b) => new Float32Array([0, Math.sin(a / 2), 0, Math.cos(a / 2), 0, Math.sin(b / 2), 0, Math.cos(b / 2)]);
  const walk = add(turn(0, 0.4), 'VEC4', 5126);
  const run = add(turn(0, -0.6), 'VEC4', 5126);
  const animation = (name, output) => ({
    name,
    samplers: [{ input: times, output, interpolation: 'LINEAR' }],
    channels: [{ sampler: 0, target: { node: 0, path: 'rotation' } }],
  });
  const doc = {
    asset: { version: '2.0', generator: 'pdeanim readme test' },
    scene: 0,
    scenes: [{ nodes: [0, 1] }],
    nodes: [{ name: 'joint' }, { name: 'model', mesh: 0, skin: 0 }],
    meshes: [{ primitives: [{ attributes: { POSITION: position, JOINTS_0: joints, WEIGHTS_0: weights }, indices }] }],
    skins: [{ joints: [0] }],
    animations: [animation('walk', walk), animation('run', run)],
    buffers: [{ byteLength: offset }],
    bufferViews: views.map((v) => ({ buffer: 0, byteOffset: v.byteOffset, byteLength: v.byteLength })),
    accessors,
  };
  const bin = new Uint8Array(offset);
  for (const v of views) bin.set(v.bytes, v.byteOffset);
  let json = new TextEncoder().encode(JSON.stringify(doc));
  const pad = (4 - (json.length % 4)) % 4;
  json = Uint8Array.from([...json, ...new Array(pad).fill(0x20)]);
  const out = new Uint8Array(12 + 8 + json.length + 8 + bin.length);
  const dv = new DataView(out.buffer);
  dv.setUint32(0, 0x46546c67, true);
  dv.setUint32(4, 2, true);
  dv.setUint32(8, out.length, true);
  dv.setUint32(12, json.length, true);
  dv.setUint32(16, 0x4e4f534a, true);
  out.set(json, 20);
  dv.setUint32(20 + json.length, bin.length, true);
  dv.setUint32(24 + json.length, 0x004e4942, true);
  out.set(bin, 28 + json.length);
  return out;
}

/** The page: the README's import map, then its three.js example between the variables it leaves to you. */
function page() {
  const [importMap] = blocks('html');
  const example = blocks('js').find((b) => b.includes('attachClipToScene'));
  assert.ok(importMap && example, 'the README shows an import map and a three.js example');
  // the example's imports first, then the variables it leaves to you, then the rest of it
  const lines = example.split('\n');
  const imports = lines.filter((l) => l.startsWith('import ')).join('\n');
  const body = lines.filter((l) => !l.startsWith('import ')).join('\n');
  const prelude = `
const out = { errors: [] };
const key = 'k1', service = location.origin, clipId = 'abc', t = 0.25;
const renderer = new THREE.WebGLRenderer({ canvas: document.querySelector('canvas') });
const scene = new THREE.Scene();
`;
  const postlude = `
mixer.update(0.25);   // halfway through the crossfade
renderer.render(scene, new THREE.PerspectiveCamera());
Object.assign(out, { done: true, nVertices: clip.nVertices, influence: player.influence, time: player.time,
  gpu: player.gpu, animations: gltf.animations.map((a) => a.name), runTracks: run.getClip().tracks.length });
fetch('/result', { method: 'POST', body: JSON.stringify(out) });
`;
  return `<!doctype html><html><head><meta charset="utf-8">
${importMap}
<script>
const fail = (m) => fetch('/result', { method: 'POST', body: JSON.stringify({ errors: [String(m)] }) });
window.addEventListener('error', (e) => fail(e.message ?? e), true);
window.addEventListener('unhandledrejection', (e) => fail(e.reason?.stack ?? e.reason));
</script>
</head><body><canvas width="64" height="64"></canvas>
<script type="module" onerror="fail('a module failed to load')">
${imports}
${prelude}
${body}
${postlude}
</script></body></html>`;
}

function serve(files) {
  const missing = [];
  let deliver;
  const result = new Promise((resolve) => {
    deliver = resolve;
  });
  const mounts = {
    '/node_modules/pdeanim/': ROOT,
    '/node_modules/three/': join(ROOT, 'node_modules', 'three'),
    '/node_modules/fzstd/': join(ROOT, 'node_modules', 'fzstd'),
  };
  const server = createServer((req, res) => {
    const url = new URL(req.url, 'http://x').pathname;
    if (req.method === 'POST' && url === '/result') {
      let body = '';
      req.on('data', (c) => {
        body += c;
      });
      req.on('end', () => {
        res.end('ok');
        deliver(JSON.parse(body));
      });
      return;
    }
    if (files[url]) {
      if (url.startsWith('/v1/') && req.headers.authorization !== 'Bearer k1') return res.writeHead(401).end();
      res.writeHead(200, { 'Content-Type': files[url].type, 'Content-Length': files[url].body.length });
      return res.end(files[url].body);
    }
    const mount = Object.keys(mounts).find((m) => url.startsWith(m));
    const path = mount && normalize(join(mounts[mount], decodeURIComponent(url.slice(mount.length))));
    try {
      if (!path || !path.startsWith(mounts[mount]) || !statSync(path).isFile()) throw new Error('not found');
      res.writeHead(200, { 'Content-Type': TYPES[extname(path)] ?? 'application/octet-stream' });
      res.end(readFileSync(path));
    } catch {
      if (url !== '/favicon.ico') missing.push(url);
      res.writeHead(404).end();
    }
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve({ server, result, missing })));
}

const chromium = findChromium();

test(
  "the README's import map and three.js example run as written in headless Chromium",
  { skip: chromium ? false : 'no Chromium found (set PDEANIM_CHROMIUM or install chromium)', timeout: 300_000 },
  async () => {
    const c = manifest().cases.find((x) => x.motion === 'rigid' && x.looping);
    const file = readBytes(join(FIXTURES, c.clip));
    const parts = splitClipFile(file);
    const bin = 'application/octet-stream';
    const { server, result, missing } = await serve({
      '/': { type: 'text/html', body: Buffer.from(page()) },
      '/fox.glb': { type: 'model/gltf-binary', body: Buffer.from(skinnedGlb(decodeClipFile(file))) },
      '/v1/clips/abc/topology': { type: bin, body: Buffer.from(parts.topology) },
      '/v1/clips/abc/coefficients': { type: bin, body: Buffer.from(parts.coefficients) },
    });
    const profile = mkdtempSync(join(tmpdir(), 'pdeanim-chromium-'));
    const browser = spawn(
      chromium,
      ['--headless=new', '--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
        '--disable-gpu-sandbox', '--no-first-run', `--user-data-dir=${profile}`,
        `http://127.0.0.1:${server.address().port}/`],
      { stdio: 'ignore', detached: true },
    );
    let timer;
    try {
      const r = await Promise.race([
        result,
        new Promise((_, reject) => {
          timer = setTimeout(() => reject(new Error(`no result within 240 s; 404s: ${missing.join(', ')}`)), 240_000);
        }),
      ]);
      assert.deepEqual({ errors: r.errors, missing }, { errors: [], missing: [] });
      assert.equal(r.done, true);
      assert.equal(r.nVertices, c.n_vertices);
      assert.deepEqual(r.animations, ['walk', 'run']);
      assert.equal(r.runTracks, 2, "the clip's action carries its pose's bone track");
      // halfway through a 0.5 s crossfade
      assert.ok(Math.abs(r.influence - 0.5) < 1e-6, `${r.influence}`);
      assert.ok(r.gpu, 'played on the GPU');
    } finally {
      clearTimeout(timer);
      const exited = new Promise((resolve) => browser.once('exit', resolve));
      if (browser.exitCode === null) {
        try {
          process.kill(-browser.pid, 'SIGKILL');
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
