// An instanced crowd in a real browser: headless Chromium (software WebGL 2) renders an InstancedMesh played
// with a time offset per instance, and separate players (clone()s) at the same times; the images must agree,
// and differ from the crowd without offsets; the separate players (the clip's crowd form: shared knot table,
// a time row each) must draw what the CPU path draws. Skipped (with the reason) when no Chromium is installed.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { findChromium, pageResult } from './pagerun.mjs';

// the paper's time pairs (rigid, looping; :curves: every curve's rigid motion on the GPU, none direct), spline
// items (some, all), a bone clip with a residual, a cyclic clip
const CASES = [
  'fit-rigid-paper-loop',
  'fit-rigid-paper-loop:curves',
  'fit-displacement-chord-smooth-spline',
  'fit-displacement-chord-windows-basis', // every item on the spline: no time-pair indices
  'bones-fit-k4-residual',
  'cyclic-trout-travelling-rotate-vertical',
];



const chromium = findChromium();

test(
  'an InstancedMesh with time offsets renders what separate players at those times render, in headless Chromium',
  { skip: chromium ? false : 'no Chromium found (set PDEANIM_CHROMIUM or install chromium)', timeout: 300_000 },
  async () => {
    const r = await pageResult(chromium, `/test/browser/crowd.html?cases=${CASES.join(',')}`);
    assert.deepEqual(r.errors, []);
    assert.equal(r.cases.length, CASES.length);
    for (const c of r.cases) {
      assert.ok(c.shared, `${c.name}: the clones share the clip's data texture`);
      const dynamic = !c.name.startsWith('cyclic');
      assert.equal(c.alone, false, `${c.name}: one player alone keeps its per-frame table`);
      assert.equal(c.crowdForm, dynamic, `${c.name}: players at distinct times take the crowd form (dynamic clips)`);
      // the crowd form (shared knots, a time row each) draws what the CPU evaluates: silhouettes only
      assert.ok(c.separateVsCpu.differ < 0.005, `${c.name}: ${c.separateVsCpu.differ} of the pixels differ from the CPU's`);
      assert.ok(c.crowdVsSeparate.covered > 0.01, `${c.name}: the crowd covers ${c.crowdVsSeparate.covered}`);
      // same meshes, same times: only rasterisation may differ (0 seen); 0.5 % leaves room for drivers
      assert.ok(c.crowdVsSeparate.differ < 0.005, `${c.name}: ${c.crowdVsSeparate.differ} of the pixels differ`);
      assert.ok(c.crowdVsInSync.differ > 0.002, `${c.name}: the offsets change nothing (${c.crowdVsInSync.differ})`);
    }
  },
);
