// pdeanim/webgpu in a real browser: headless Chromium with WebGPU enabled (SwiftShader's adapter) renders
// fixture clips with WebGPURenderer on its WebGPU backend and on its WebGL 2 fallback (forceWebGL), and with
// WebGLRenderer and pdeanim/three; the images must agree, agree with the CPU fallback and with three.js's own
// drawing of the CPU positions, and the positions read back from the node shader must be the CPU evaluator's.
// One browser for the module. Skipped (with the reason) when no Chromium is installed outside CI; the WebGPU
// backend's part is skipped only when the browser truly has no WebGPU adapter (PDEANIM_REQUIRE_WEBGPU=1 makes
// that a failure).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { WEBGPU_FLAGS, findChromium, pageResult } from './pagerun.mjs';
import { manifest } from './helpers.mjs';
import { boneClipParts } from './bonehelpers.mjs';

const man = manifest();
// a bone clip whose residual is zero on half of its curves (both branches of the skinning shader)
const HALF = boneClipParts(man.cases.find((c) => c.name === 'synthetic-displacement-chord-spline'), {
  K: 2,
  Sb: 6,
  zeroCurve: (c) => c % 2 === 0,
}).file;

// rest normals (first case: rigid, the paper's time pairs), frame normals: spline items, a cyclic clip, bones
// with a residual, bones with a residual on half the curves (both branches of the skinning shader)
const CASES = [
  'fit-rigid-paper-loop',
  'fit-displacement-chord-smooth-spline',
  'cyclic-trout-travelling-rotate-vertical',
  'bones-fit-k4-residual',
  'bones-spline-half',
];

const chromium = findChromium();
let result = null;
/** The page's result for both backends (one browser for every test of the module). */
async function run() {
  result ??= pageResult(chromium, `/test/browser/webgpu.html?cases=${CASES.join(',')}&backends=webgpu,webgl`, {
    files: { '/test/fixtures/bones-spline-half.clip': HALF },
    flags: WEBGPU_FLAGS,
  });
  return result;
}

// under CI a missing Chromium or WebGPU adapter fails (script/setup installs Chromium): a skip checks nothing
const IN_CI = /^(1|true|yes)$/i.test(process.env.CI ?? '');
const noChromium = chromium || IN_CI ? false : 'no Chromium found (set PDEANIM_CHROMIUM or install chromium)';

/** The checks of one backend's cases, scenes and crowds. */
function checkBackend(r, backend) {
  const cases = r.cases.filter((c) => c.backend === backend);
  assert.equal(cases.length, CASES.length, `${backend}: every case ran`);
  for (const c of cases) {
    const at = `${backend} ${c.name}`;
    for (const k of ['gpuVsWebgl02', 'gpuVsWebgl07', 'gpuVsCpu02', 'gpuVsCpu07']) {
      assert.ok(c[k].covered > 0.05, `${at}: the mesh covers ${c[k].covered} of the image`);
      // the same clip through WebGLRenderer's patched shader, or the CPU fallback: silhouette pixels at most
      // (0 to 0.04 % of the pixels seen); 0.1 % leaves room
      assert.ok(c[k].differ < 0.001, `${at} ${k}: ${c[k].differ} of the pixels differ`);
    }
    // float32 evaluation of positions up to ~the diagonal (bones: skinning too): 1e-7 of the diagonal seen
    assert.ok(c.gpuError < 3e-7, `${at}: node shader positions deviate by ${c.gpuError} of the diagonal`);
    assert.ok(c.gpu02vs07.differ > 0.01, `${at}: the image does not change between t = 0.2 and 0.7`);
    // the influence (the mixer's weight) reaches the node shader: 0 draws the mesh as without the clip
    assert.ok(c.influence0VsRest.differ < 0.001, `${at}: influence 0 differs from the rest pose`);
    const half = c.influenceHalf;
    assert.ok(half.rest.differ > 0.005 && half.clip.differ > 0.005, `${at}: influence 0.5 is not a mix`);
    if (c.normals === 'frame') {
      // the look: three.js's own drawing (computeVertexNormals) of the CPU positions on the same renderer
      for (const k of ['gpuVsThree02', 'gpuVsThree07']) {
        assert.ok(c[k].differ < 0.001, `${at} ${k}: ${c[k].differ} of the pixels differ from three.js's own`);
      }
    }
  }
  for (const s of r.scenes.filter((x) => x.backend === backend)) {
    assert.ok(s.gpuVsWebgl.covered > 0.02, `${backend} ${s.name}: covers ${s.gpuVsWebgl.covered}`);
    assert.ok(s.gpuVsWebgl.differ < 0.001, `${backend} ${s.name}: ${s.gpuVsWebgl.differ} of the pixels differ`);
    assert.ok(s.moved.differ > 0.01, `${backend} ${s.name}: the scene does not move`);
  }
  for (const s of r.crowds.filter((x) => x.backend === backend)) {
    assert.ok(s.gpuVsWebgl.covered > 0.02, `${backend} ${s.name}: covers ${s.gpuVsWebgl.covered}`);
    assert.ok(s.gpuVsWebgl.differ < 0.001, `${backend} ${s.name}: ${s.gpuVsWebgl.differ} of the pixels differ`);
    assert.ok(s.offsetsMatter.differ > 0.002, `${backend} ${s.name}: the offsets change nothing`);
  }
}

test('WebGPURenderer on WebGPU draws what WebGLRenderer draws, in headless Chromium', { skip: noChromium, timeout: 300_000 }, async (t) => {
  const r = await run();
  assert.deepEqual(r.errors, []);
  if (!r.adapter) {
    const reason = 'the browser has no WebGPU adapter (navigator.gpu.requestAdapter() gave null)';
    if (process.env.PDEANIM_REQUIRE_WEBGPU === '1' || IN_CI) assert.fail(reason);
    t.skip(reason);
    return;
  }
  assert.equal(r.backends[0], 'webgpu');
  checkBackend(r, 'webgpu');
});

test("WebGPURenderer's WebGL 2 fallback (forceWebGL) draws what WebGLRenderer draws", { skip: noChromium, timeout: 300_000 }, async () => {
  const r = await run();
  assert.deepEqual(r.errors, []);
  assert.equal(r.backends[1], 'webgl2');
  checkBackend(r, 'webgl2');
});
