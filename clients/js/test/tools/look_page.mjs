// The look page (test/browser/look.html) for a glTF and the clip fitted on it: node look_page.mjs MODEL.glb
// MODEL.clip prints the page's result as JSON (one line). Run by tests/browser/test_webgpu_look.py.
import { readFileSync } from 'node:fs';
import { WEBGPU_FLAGS, findChromium, pageResult } from '../pagerun.mjs';

const [glb, clip] = process.argv.slice(2);
const chromium = findChromium();
if (!chromium) {
  console.log(JSON.stringify({ skip: 'no Chromium found (set PDEANIM_CHROMIUM or install chromium)' }));
  process.exit(0);
}
const files = { '/look/model.glb': readFileSync(glb), '/look/model.clip': readFileSync(clip) };
const r = await pageResult(chromium, '/test/browser/look.html', { files, flags: WEBGPU_FLAGS });
console.log(JSON.stringify(r));
