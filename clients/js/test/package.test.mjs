// The package itself: browser-safe sources (no node-only imports outside bin/), exports that resolve,
// declarations for every entry point, an MIT licence and one runtime dependency (fzstd, the zstd decoder of
// the containers' encoded arrays).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { spawnSync } from 'node:child_process';
import { existsSync, readdirSync, readFileSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..');
const pkg = JSON.parse(readFileSync(join(ROOT, 'package.json'), 'utf8'));

test('sources import only each other, three (three/webgpu, three/tsl) and fzstd (they run in browsers)', () => {
  for (const name of readdirSync(join(ROOT, 'src'))) {
    const text = readFileSync(join(ROOT, 'src', name), 'utf8');
    for (const [, spec] of text.matchAll(/^\s*(?:import|export)\s[^'"]*?from\s+'([^']+)'/gms)) {
      const three = spec === 'three' || spec === 'three/webgpu' || spec === 'three/tsl';
      assert.ok(spec.startsWith('./') || three || spec === 'fzstd', `${name} imports ${spec}`);
    }
    assert.doesNotMatch(text, /\brequire\(|\bprocess\.|\bBuffer\./, name);
  }
});

test('every export resolves, has declarations, and loads', async () => {
  for (const [entry, target] of Object.entries(pkg.exports)) {
    if (entry === './package.json') continue;
    assert.ok(existsSync(join(ROOT, target.default)), entry);
    assert.ok(existsSync(join(ROOT, target.types)), entry);
    const mod = await import(join(ROOT, target.default));
    assert.ok(Object.keys(mod).length > 0, entry);
  }
  assert.ok(existsSync(join(ROOT, pkg.bin['pdeanim-eval'])));
});

test('MIT licence, ES modules, fzstd the one runtime dependency, three only as an optional peer', () => {
  assert.equal(pkg.license, 'MIT');
  assert.match(readFileSync(join(ROOT, 'LICENSE'), 'utf8'), /MIT License/);
  assert.equal(pkg.type, 'module');
  assert.deepEqual(Object.keys(pkg.dependencies), ['fzstd']);
  const lock = JSON.parse(readFileSync(join(ROOT, 'package-lock.json'), 'utf8'));
  assert.equal(lock.packages['node_modules/fzstd'].license, 'MIT');
  assert.equal(lock.packages['node_modules/fzstd'].dependencies, undefined); // nothing pulled in with it
  assert.ok(pkg.peerDependencies.three);
  assert.equal(pkg.peerDependenciesMeta.three.optional, true);
});

test('npm pack ships the sources, declarations, command, README and licence, and nothing else', () => {
  const r = spawnSync('npm', ['pack', '--dry-run', '--json', '--ignore-scripts'], { cwd: ROOT, encoding: 'utf8' });
  assert.equal(r.status, 0, r.stderr);
  const files = JSON.parse(r.stdout)[0].files.map((f) => f.path).sort();
  const src = readdirSync(join(ROOT, 'src')).map((f) => `src/${f}`);
  const types = readdirSync(join(ROOT, 'types')).map((f) => `types/${f}`);
  const want = ['LICENSE', 'README.md', 'bin/pdeanim-eval.mjs', 'package.json', ...src, ...types].sort();
  assert.deepEqual(files, want);
  // every file the exports and sideEffects name is in the tarball
  for (const target of Object.values(pkg.exports)) {
    for (const path of typeof target === 'string' ? [target] : Object.values(target)) {
      assert.ok(files.includes(path.replace(/^\.\//, '')), path);
    }
  }
  for (const path of pkg.sideEffects) assert.ok(files.includes(path.replace(/^\.\//, '')), path);
});

test('metadata: repository (with its folder), keywords, sideEffects naming the modules with side effects', () => {
  assert.equal(pkg.repository.type, 'git');
  assert.match(pkg.repository.url, /^git\+https:\/\//);
  assert.equal(pkg.repository.directory, 'clients/js');
  assert.ok(pkg.keywords.includes('three.js') && pkg.keywords.length >= 5);
  // the modules that install something when imported, and only those
  const effects = readdirSync(join(ROOT, 'src')).filter((f) =>
    /^(?:setZstdDecompress\(|self\.onmessage =)/m.test(readFileSync(join(ROOT, 'src', f), 'utf8')),
  );
  assert.deepEqual(pkg.sideEffects.map((p) => p.replace('./src/', '')).sort(), effects.sort());
});

test('the README stands alone: absolute links only, and the options it shows are ones the code takes', async () => {
  const readme = readFileSync(join(ROOT, 'README.md'), 'utf8');
  for (const [, href] of readme.matchAll(/\]\(([^)]+)\)/g)) assert.match(href, /^https:\/\//, href);
  const { PLAYER_OPTIONS } = await import('../src/three.js');
  // every option named in an attachClip / ClipPlayer call of the README's examples
  for (const [, opts] of readme.matchAll(/(?:attachClip|attachClipToScene|new ClipPlayer)\([^)]*\{([^}]*)\}/g)) {
    for (const [, name] of opts.matchAll(/(\w+)\s*(?::|,|$)/g)) {
      assert.ok([...PLAYER_OPTIONS, 'filter'].includes(name), `README option ${name}`);
    }
  }
});
