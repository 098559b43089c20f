// The package itself: browser-safe sources (no node-only imports outside bin/), exports that resolve,
// declarations for every entry point, an MIT licence and one runtime dependency (fzstd, the zstd decoder of
// the containers' encoded arrays).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { existsSync, readdirSync, readFileSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..');
const pkg = JSON.parse(readFileSync(join(ROOT, 'package.json'), 'utf8'));

test('sources import only each other, three and fzstd (they run in browsers)', () => {
  for (const name of readdirSync(join(ROOT, 'src'))) {
    const text = readFileSync(join(ROOT, 'src', name), 'utf8');
    for (const [, spec] of text.matchAll(/^\s*(?:import|export)\s[^'"]*?from\s+'([^']+)'/gms)) {
      assert.ok(spec.startsWith('./') || spec === 'three' || spec === 'fzstd', `${name} imports ${spec}`);
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
