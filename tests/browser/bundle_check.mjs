// Build a small page that loads a CLIP file with the package's PDEClipLoader, the way an application does
// (`import { PDEClipLoader } from 'pdeanim/three'`, the package installed in node_modules), with esbuild or
// Vite, serve the build on 127.0.0.1 and load it in headless Chromium (one browser for every build). Prints
// one JSON object mapping each build to what its page saw: the workers that ran (the package's is named
// pdeanim-decoder), the console warnings, the decoded vertex count.
// Usage: node bundle_check.mjs CLIP_FILE BUILD... (BUILD: esbuild, esbuild-without-worker, vite)
import { createServer } from 'node:http';
import { mkdirSync, mkdtempSync, readFileSync, rmSync, statSync, symlinkSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, extname, join, normalize } from 'node:path';
import { fileURLToPath } from 'node:url';
import { launchChromium } from './chromium.mjs';

const HERE = dirname(fileURLToPath(import.meta.url));
const PACKAGE = join(HERE, '..', '..', 'clients', 'js');
const TYPES = { '.js': 'text/javascript', '.html': 'text/html', '.clip': 'application/octet-stream' };

const MAIN = `
import { PDEClipLoader } from 'pdeanim/three';
const warnings = [];
const warn = console.warn.bind(console);
console.warn = (...args) => { warnings.push(args.map(String).join(' ')); warn(...args); };
try {
  const clip = await new PDEClipLoader().loadAsync('./input.clip');
  window.result = { nVertices: clip.nVertices, warnings };
} catch (err) {
  window.result = { error: String(err?.stack ?? err), warnings };
}
`;

/** A project folder with the package installed as node_modules/pdeanim (a link, as npm link makes). */
function project(clipFile) {
  const dir = mkdtempSync(join(tmpdir(), 'pdeanim-bundle-'));
  mkdirSync(join(dir, 'node_modules'));
  symlinkSync(PACKAGE, join(dir, 'node_modules', 'pdeanim'), 'dir');
  writeFileSync(join(dir, 'main.js'), MAIN);
  writeFileSync(join(dir, 'index.html'),
    '<!doctype html><meta charset="utf-8"><script type="module" src="./main.js"></script>\n');
  mkdirSync(join(dir, 'public'));
  writeFileSync(join(dir, 'public', 'input.clip'), readFileSync(clipFile));
  return dir;
}

/**
 * esbuild: the page and the package's worker as two entry points side by side (the package README's recipe);
 * withWorker false leaves the worker out, as a build that forgot it.
 */
async function buildEsbuild(dir, withWorker = true) {
  const esbuild = await import('esbuild');
  const out = join(dir, 'dist');
  const entryPoints = { main: join(dir, 'main.js') };
  if (withWorker) entryPoints.worker = join(dir, 'node_modules', 'pdeanim', 'src', 'worker.js');
  await esbuild.build({
    entryPoints,
    bundle: true, format: 'esm', outdir: out, logLevel: 'error', absWorkingDir: dir,
  });
  writeFileSync(join(out, 'index.html'), readFileSync(join(dir, 'index.html')));
  writeFileSync(join(out, 'input.clip'), readFileSync(join(dir, 'public', 'input.clip')));
  return out;
}

/** Vite: a plain production build (it bundles new Worker(new URL(...)) workers by itself). */
async function buildVite(dir) {
  const { build } = await import('vite');
  await build({ root: dir, logLevel: 'error', configFile: false, build: { outDir: join(dir, 'dist') } });
  return join(dir, 'dist');
}

function serve(root) {
  const server = createServer((req, res) => {
    const path = normalize(join(root, decodeURIComponent(new URL(req.url, 'http://x').pathname)));
    const file = path.endsWith('/') ? join(path, 'index.html') : path;
    try {
      if (!file.startsWith(root) || !statSync(file).isFile()) throw new Error('not found');
      res.writeHead(200, { 'Content-Type': TYPES[extname(file)] ?? 'application/octet-stream' });
      res.end(readFileSync(file));
    } catch {
      res.writeHead(404);
      res.end();
    }
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve(server)));
}

/** Build the page with ``build``, load it in a new tab of browser, return what the page saw. */
async function check(browser, build, clipFile) {
  const dir = project(clipFile);
  let server;
  try {
    const out = build === 'vite' ? await buildVite(dir) : await buildEsbuild(dir, build === 'esbuild');
    server = await serve(out);
    const page = await browser.newPage();
    await page.goto(`http://127.0.0.1:${server.address().port}/`);
    await page.waitForFunction(() => window.result !== undefined, { timeout: 240_000 });
    const result = await page.evaluate(() => window.result);
    const workerNames = [];
    for (const w of page.workers()) workerNames.push(await w.evaluate(() => self.name));
    await page.close();
    return { ...result, workerNames };
  } finally {
    server?.close();
    rmSync(dir, { recursive: true, force: true });
  }
}

async function main() {
  const [clipFile, ...builds] = process.argv.slice(2);
  const browser = await launchChromium();
  try {
    const seen = {};
    for (const build of builds) seen[build] = await check(browser, build, clipFile);
    console.log(JSON.stringify(seen));
  } finally {
    await browser.close();
  }
}

main().catch((err) => {
  console.error(err);
  process.exit(1);
});
