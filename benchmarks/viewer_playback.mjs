// Playback in the viewer in headless Chromium (software WebGL: SwiftShader): frames per second and the
// JavaScript milliseconds of each frame (time uniforms or CPU evaluation + three.js render call), per mode.
// Driven by benchmarks/viewer_playback.py; argument: a JSON job
// {url, modes, runs, seconds, width, height, out}.
import { writeFileSync } from 'node:fs';
import { launchChromium } from '../tests/browser/chromium.mjs';

const job = JSON.parse(process.argv[2]);
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
const browser = await launchChromium();
try {
  const page = await browser.newPage();
  await page.setViewport({ width: job.width, height: job.height });
  await page.goto(job.url, { waitUntil: 'load', timeout: 300_000 });
  await page.waitForFunction('window.pdeanimViewer !== undefined', { timeout: 300_000 });
  await page.evaluate('window.pdeanimViewer.ready');
  const out = await page.evaluate(() => {
    const gl = document.getElementById('canvas').getContext('webgl2');
    const ext = gl.getExtension('WEBGL_debug_renderer_info');
    const c = document.getElementById('canvas');
    return { renderer: ext ? gl.getParameter(ext.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER),
      canvas: [c.width, c.height], vertices: window.pdeanimViewer.clip.nVertices, runs: {} };
  });
  for (const mode of job.modes) {
    out.runs[mode] = [];
    // "static": the CPU path paused on one frame and drawn every frame: the cost of drawing the mesh alone
    const got = await page.evaluate((m) => {
      const v = window.pdeanimViewer;
      v.setMode(m === 'static' ? 'cpu' : m);
      if (m === 'static') { v.pause(); v.renderAlways = true; return 'static'; }
      v.renderAlways = false;
      v.play();
      return v.mode;
    }, mode);
    if (got !== mode) {
      const why = await page.evaluate('window.pdeanimViewer.gpuUnavailableReason');
      throw new Error(`could not switch to ${mode}: ${why}`);
    }
    await sleep(1500); // warm-up: shader compilation, first uploads
    for (let r = 0; r < job.runs; r++) {
      await page.evaluate(() => window.pdeanimViewer.resetFrameStats());
      await sleep(job.seconds * 1000);
      out.runs[mode].push(await page.evaluate(() => window.pdeanimViewer.frameStats()));
    }
  }
  writeFileSync(job.out, JSON.stringify(out));
} finally {
  await browser.close();
}
