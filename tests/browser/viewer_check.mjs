// Drive the viewer in headless Chromium for tests/browser/test_viewer.py: open /viewer#clip=…&key=…, wait for
// window.pdeanimViewer.ready, evaluate positions at the given times, screenshot GPU and CPU frames.
// Usage: node viewer_check.mjs JOB, JOB = JSON {"url", "times": [t...], "shots": [{"t", "mode", "path"}],
// "measureGlb", "playFrames", "out"}
import { writeFileSync } from 'node:fs';
import { openBrowser, releaseBrowser } from './chromium.mjs';
import { drawReference, writeDataUrl } from './look_reference.mjs';

const job = JSON.parse(process.argv[2]);
const browser = await openBrowser();
const logs = [];
let page;
try {
  page = await browser.newPage();
  page.on('console', (m) => logs.push(`${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => logs.push(`pageerror: ${e.message}`));
  page.on('requestfailed', (r) => logs.push(`requestfailed: ${r.url()} ${r.failure()?.errorText}`));
  const animationRequests = [];
  page.on('request', (r) => { if (r.url().includes('/animation')) animationRequests.push(r.method()); });
  await page.setViewport({ width: job.width ?? 800, height: job.height ?? 600 });
  await page.goto(job.url, { waitUntil: 'load', timeout: 120_000 });
  await page.waitForFunction('window.pdeanimViewer !== undefined', { timeout: 120_000 });
  await page.evaluate('window.pdeanimViewer.ready');
  const result = { logs };
  result.info = await page.evaluate(() => {
    const v = window.pdeanimViewer;
    return { mode: v.mode, gpuUnavailableReason: v.gpuUnavailableReason, nVertices: v.clip.nVertices,
      kind: v.clip.kind, sizes: v.sizes(), stats: document.querySelector('#stats').innerText, model: v.model,
      timings: v.timings, gpuBytes: v.gpuBytes,
      bones: v.clip.bones ? { nBones: v.clip.bones.nBones, residual: Boolean(v.clip.bones.residual) } : null };
  });
  if (job.playFrames) {
    // let it play: the animation loop advances t and draws until playFrames frames were drawn
    const t0 = await page.evaluate(() => { const v = window.pdeanimViewer; v.resetFrameStats(); v.play(); return v.t; });
    await page.waitForFunction((n) => window.pdeanimViewer.frameStats().frames >= n, { timeout: 120_000 },
      job.playFrames);
    result.played = await page.evaluate((start) => ({ start, end: window.pdeanimViewer.t,
      ...window.pdeanimViewer.frameStats() }), t0);
  }
  result.positions = [];
  for (const t of job.times ?? []) {
    result.positions.push(await page.evaluate(async (tt) => Array.from(await window.pdeanimViewer.positions(tt)), t));
  }
  if (job.measureGlb) result.glb = await page.evaluate(() => window.pdeanimViewer.measureGlb());
  result.animationRequests = animationRequests;
  result.shots = [];
  for (const shot of job.shots ?? []) {
    const mode = await page.evaluate((m) => window.pdeanimViewer.setMode(m), shot.mode);
    await page.evaluate((t) => window.pdeanimViewer.show(t), shot.t);
    await page.screenshot({ path: shot.path });
    result.shots.push({ ...shot, mode });
  }
  if (job.reference) {
    // the clip's frames at the given times on the viewer's canvas, against the source glTF drawn by three.js
    // alone (its own skinning at the same times) in another page, without the viewer's CSP or code
    const r = job.reference;
    const stage = await page.evaluate(() => window.pdeanimViewer.stage());
    result.reference = { clipPaths: [], referencePaths: [] };
    for (const [i, t] of r.times.entries()) {
      await page.evaluate((tt) => window.pdeanimViewer.show(tt), t);
      const png = await page.evaluate(() => document.querySelector('#canvas').toDataURL('image/png'));
      const path = `${r.dir}/clip-${i}.png`;
      writeDataUrl(writeFileSync, path, png);
      result.reference.clipPaths.push(path);
    }
    const drawn = await drawReference(browser, new URL(job.url).origin,
      { fileUrl: r.fileUrl, key: r.key, times: r.times, stage }, logs);
    for (const [i, png] of drawn.images.entries()) {
      const path = `${r.dir}/reference-${i}.png`;
      writeDataUrl(writeFileSync, path, png);
      result.reference.referencePaths.push(path);
    }
    result.reference.textured = drawn.textured;
    result.reference.flat = drawn.flat;
    result.reference.viewerTextured = await page.evaluate(() => window.pdeanimViewer.textured);
  }
  result.info.statsAfter = await page.evaluate(() => document.querySelector('#stats').innerText);
  writeFileSync(job.out, JSON.stringify(result));
} catch (err) {
  writeFileSync(job.out, JSON.stringify({ error: String(err?.stack ?? err), logs }));
  process.exitCode = 1;
} finally {
  await page?.close();
  await releaseBrowser(browser);
}
