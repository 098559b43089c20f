// The bone layer's shader in a real browser: headless Chromium (software WebGL 2) renders clips with bones
// (with a residual, without one, and with it on some curves only) through test/browser/gpu.html, in the vertex shader and in the evaluation
// pass, against the CPU fallback; the GLSL must compile and the positions read back from the shader must be
// the CPU evaluator's. Skipped (with the reason) when no Chromium is installed outside CI.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { findChromium, pageResult } from './pagerun.mjs';
import { manifest } from './helpers.mjs';
import { boneClipParts } from './bonehelpers.mjs';

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

const chromium = findChromium();

test(
  'bone clips: the skinning shader renders what the CPU path renders, in headless Chromium',
  { skip: chromium ? false : 'no Chromium found (set PDEANIM_CHROMIUM or install chromium)', timeout: 300_000 },
  async () => {
    const names = [...Object.keys(CLIPS), 'bones-fit-k4-residual']; // + a fixture written by the Python library
    const files = Object.fromEntries(Object.entries(CLIPS).map(([k, v]) => [`/test/fixtures/${k}.clip`, v]));
    const r = await pageResult(chromium, `/test/browser/gpu.html?cases=${names.join(',')}`, { files });
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
  },
);
