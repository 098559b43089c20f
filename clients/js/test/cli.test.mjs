// The node command: CLIP file or two parts in, little-endian float32 (K, V, 3) out; exit 2 on bad input.

import { after, test } from 'node:test';
import assert from 'node:assert/strict';
import { spawnSync } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';
import { createEvaluator, decodeClipFile } from '../src/index.js';
import {
  FIXTURES,
  edited,
  encodeContainer,
  expected,
  fixtureParts,
  manifest,
  readBytes,
  storedArrays,
} from './helpers.mjs';

const BIN = join(dirname(fileURLToPath(import.meta.url)), '..', 'bin', 'pdeanim-eval.mjs');
const tmp = mkdtempSync(join(tmpdir(), 'pdeanim-eval-'));
after(() => rmSync(tmp, { recursive: true, force: true }));
const man = manifest();

function run(args) {
  return spawnSync(process.execPath, [BIN, ...args], { encoding: 'utf8', timeout: 120_000 });
}

function readF32LE(path) {
  const b = readFileSync(path);
  const view = new DataView(b.buffer, b.byteOffset, b.byteLength);
  return Float32Array.from({ length: b.byteLength / 4 }, (_, i) => view.getFloat32(i * 4, true));
}

// a rigid looping clip on the paper's time pairs, a clip with spline items on a knot basis, a rigid clip with
// spline items, a cyclic clip
for (const c of [
  man.cases.find((x) => x.motion === 'rigid' && x.looping && x.spline_items === 0),
  man.cases.find((x) => x.knot_rank > 0 && x.spline_items > 0),
  man.cases.find((x) => x.motion === 'rigid' && x.spline_items > 0),
  man.cases.find((x) => x.kind === 'cyclic-spine'),
]) {
  test(`pdeanim-eval writes the expected frames of ${c.name}`, () => {
    // the manifest's times the clip takes (those in [0, 1] unless it loops) and their rows of expected
    const rows = c.t.map((t, k) => k).filter((k) => c.looping || (c.t[k] >= 0 && c.t[k] <= 1));
    assert.ok(rows.length >= 3);
    const out = join(tmp, `${c.name}.bin`);
    const r = run([join(FIXTURES, c.clip), '--t', rows.map((k) => c.t[k]).join(','), '--out', out]);
    assert.equal(r.status, 0, r.stderr);
    const got = readF32LE(out);
    const want = expected(c);
    const N = c.n_vertices * 3;
    assert.equal(got.length, rows.length * N);
    const worst = got.reduce((m, v, i) => Math.max(m, Math.abs(v - want[rows[Math.floor(i / N)] * N + (i % N)])), 0);
    assert.ok(worst <= 1e-6 * c.diagonal, `max deviation ${worst}`);
  });
}

test('pdeanim-eval reads the two parts from separate files', () => {
  const c = man.cases.find((x) => x.motion === 'absolute');
  const p = fixtureParts(c);
  writeFileSync(join(tmp, 'topo.bin'), p.topology);
  writeFileSync(join(tmp, 'coef.bin'), p.coefficients);
  const out = join(tmp, 'parts.bin');
  const r = run([
    '--coefficients',
    join(tmp, 'coef.bin'),
    '--topology',
    join(tmp, 'topo.bin'),
    '--t',
    '0.25,1',
    '--out',
    out,
  ]);
  assert.equal(r.status, 0, r.stderr);
  assert.equal(readFileSync(out).byteLength, 2 * c.n_vertices * 3 * 4);
});

test('pdeanim-eval --t all writes every source frame, as `pdeanim frame --t all`', () => {
  const c = man.cases.find((x) => x.kind === 'dynamic-pde' && !x.looping);
  const out = join(tmp, 'all.bin');
  const r = run([join(FIXTURES, c.clip), '--t', 'all', '--out', out]);
  assert.equal(r.status, 0, r.stderr);
  const clip = decodeClipFile(readBytes(join(FIXTURES, c.clip)));
  const K = clip.frameTimes.length;
  assert.equal(readFileSync(out).byteLength, K * c.n_vertices * 3 * 4);
  const got = new Float32Array(Uint8Array.from(readFileSync(out)).buffer);
  const ft = clip.frameTimes;
  const last = createEvaluator(clip).evaluate(1);
  assert.equal((ft[K - 1] - ft[0]) / (ft[K - 1] - ft[0]), 1);
  assert.deepEqual(got.subarray((K - 1) * c.n_vertices * 3), last);
});

test('pdeanim-eval: t outside [0, 1] exits 2 for clips that do not loop, wraps for looping ones', () => {
  const open = man.cases.find((x) => x.kind === 'dynamic-pde' && !x.looping);
  const r = run([join(FIXTURES, open.clip), '--t', '0.5,-0.5', '--out', join(tmp, 'x.bin')]);
  assert.equal(r.status, 2);
  assert.match(r.stderr, /--t must lie in \[0, 1\] for this clip \(it does not loop\), got -0.5/);
  const loop = man.cases.find((x) => x.kind === 'dynamic-pde' && x.looping);
  const out = join(tmp, 'wrap.bin');
  assert.equal(run([join(FIXTURES, loop.clip), '--t', '0.25,1.25', '--out', out]).status, 0);
  const got = new Float32Array(Uint8Array.from(readFileSync(out)).buffer);
  const N = loop.n_vertices * 3;
  const worst = got.subarray(0, N).reduce((m, v, i) => Math.max(m, Math.abs(v - got[N + i])), 0);
  assert.ok(worst <= 1e-6 * loop.diagonal);
});

test('pdeanim-eval exits 2 with a reason on bad input', () => {
  const clip = join(FIXTURES, man.cases[0].clip);
  const out = join(tmp, 'bad.bin');
  // a coefficients part whose knots' zstd frame is cut short
  const p = fixtureParts(man.cases.find((x) => x.kind === 'dynamic-pde'));
  const arrays = storedArrays(p.coefficients);
  assert.ok(arrays.knots.encoding);
  arrays.knots = { ...arrays.knots, stored: arrays.knots.stored.subarray(0, arrays.knots.nbytes - 4) };
  writeFileSync(join(tmp, 'topo2.bin'), p.topology);
  writeFileSync(join(tmp, 'cut.bin'), encodeContainer({ part: 'coefficients' }, arrays));
  // a CLIP file of another major format version, and a coefficients part of one
  const future = edited(readBytes(clip), ({ header }) => {
    header.format_version = '2.0';
  });
  const futureCoef = edited(p.coefficients, ({ header }) => {
    header.format_version = '2.0';
  });
  writeFileSync(join(tmp, 'future.clip'), future);
  writeFileSync(join(tmp, 'future-coef.bin'), futureCoef);
  const topology = join(tmp, 'topo2.bin');
  const withTopology = (coef) => ['--topology', topology, '--coefficients', coef, '--t', '0', '--out', out];
  const cases = [
    [[join(tmp, 'missing.clip'), '--t', '0', '--out', out], /cannot read clip file/],
    [[join(FIXTURES, 'manifest.json'), '--t', '0', '--out', out], /bad magic/],
    [[clip, '--t', '0,abc', '--out', out], /finite numbers/],
    [[clip, '--t', 'nan', '--out', out], /finite numbers/],
    [[clip, '--out', out], /--t is required/],
    [[clip, '--t', '0'], /--out is required/],
    [['--t', '0', '--out', out], /give a CLIP file/],
    [[clip, '--topology', clip, '--t', '0', '--out', out], /not both/],
    [['--topology', clip, '--coefficients', clip, '--t', '0', '--out', out], /expected a topology part/],
    [[clip, '--bogus'], /bogus/],
    [withTopology(join(tmp, 'cut.bin')), /array "knots": bad zstd data/],
    [[join(tmp, 'future.clip'), '--t', '0', '--out', out],
      /unsupported clip format version "2\.0" in the clip-file part \(this build reads 1\.x\)/],
    [withTopology(join(tmp, 'future-coef.bin')),
      /unsupported clip format version "2\.0" in the coefficients part \(this build reads 1\.x\)/],
    [[clip, '--t', '0', '--out', join(tmp, 'no', 'such', 'dir', 'x.bin')], /cannot write/],
  ];
  for (const [args, reason] of cases) {
    const r = run(args);
    assert.equal(r.status, 2, `${args.join(' ')}: ${r.stderr}`);
    assert.match(r.stderr, reason);
    assert.doesNotMatch(r.stderr, /at .*\.js:\d+/); // a reason, not a stack trace
  }
});
