// The vertex-shader path in a real browser: headless Chromium (software WebGL 2) renders fixture clips with
// the GPU path and with the CPU fallback; the images must agree and move between two t. Skipped (with the
// reason) when no Chromium is installed outside CI (script/setup installs it with the viewer's dependencies).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { findChromium, pageResult } from './pagerun.mjs';

// the paper's time pairs (rigid), spline items in the vertex shader, the paper's time pairs and spline items
// (rigid) in the evaluation pass, a cyclic clip
const CASES = [
  'fit-rigid-paper-loop',
  'fit-displacement-chord',
  'synthetic-rigid-paper',
  'synthetic-rigid-paper-spline',
  'cyclic-trout-travelling-rotate-vertical',
];



const chromium = findChromium();

// as the viewer's test: a missing browser is a failure in CI (CI=true), a skip elsewhere
test('Chromium is available in CI', { skip: process.env.CI === 'true' ? false : 'not in CI' }, () => {
  assert.ok(chromium, 'no Chromium found (script/setup installs it; or set PDEANIM_CHROMIUM)');
});

test(
  'the vertex shader renders what the CPU path renders, in headless Chromium',
  {
    skip: chromium ? false : 'no Chromium found (set PDEANIM_CHROMIUM or install chromium)',
    timeout: 300_000,
  },
  async () => {
    const r = await pageResult(chromium, `/test/browser/gpu.html?cases=${CASES.join(',')}`);
    assert.deepEqual(r.errors, []);
    assert.deepEqual(r.passes, [false, false, true, true, true]); // both GPU variants ran
    assert.equal(r.cases.length, CASES.length + 1); // + one transformed multi-mesh scene
    // the spline shader ran: in the vertex shader (the second case) and in the evaluation pass (the fourth)
    assert.deepEqual(
      r.cases.slice(0, CASES.length).map((c) => c.spline),
      [false, true, false, true, false],
    );
    // the points check of each clip ran alone, then beside the mesh's player (dynamic clips: the crowd form)
    for (const c of r.cases.slice(0, CASES.length)) {
      assert.deepEqual(c.forms, [false, !c.name.startsWith('cyclic')], `${c.name}: ${c.forms}`);
    }
    for (const c of r.cases) {
      // same mesh, same lighting: only rasterisation at silhouettes may differ (positions agree to ~1e-7
      // of the diagonal); the runs show 0 to 0.05 % of the pixels, 0.5 % leaves room for other drivers
      for (const k of ['gpuVsCpu02', 'gpuVsCpu07']) {
        assert.ok(c[k].covered > 0.05, `${c.name}: the mesh covers ${c[k].covered} of the image`);
        assert.ok(c[k].differ < 0.005, `${c.name} ${k}: ${c[k].differ} of the pixels differ`);
      }
      // float32 sums of values up to ~0.3 of the diagonal on the GPU (time pairs and rotations come from
      // the CPU in float64): worst seen 5.9e-8 of the diagonal
      assert.ok(c.gpuError < 3e-7, `${c.name}: GPU positions deviate by ${c.gpuError} of the diagonal`);
      assert.ok(c.gpu02vs07.differ > 0.01, `${c.name}: the image does not change between t = 0.2 and 0.7`);
      // frame normals: three.js's own drawing of the same positions (computeVertexNormals), lit alike
      if (c.normals === 'frame') {
        for (const k of ['gpuVsThree02', 'gpuVsThree07']) {
          console.log(`${c.name} ${k}: ${c[k].differ} of the pixels differ from three.js's own`);
          assert.ok(c[k].differ < 0.005, `${c.name} ${k}: ${c[k].differ} of the pixels differ from three.js's`);
        }
      }
    }
  },
);
