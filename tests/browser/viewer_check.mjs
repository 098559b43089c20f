// Drive the viewer in headless Chromium for tests/browser/test_viewer.py: open /viewer#clip=…&key=…, wait for
// window.pdeanimViewer.ready, evaluate positions at the given times, screenshot GPU and CPU frames.
// Usage: node viewer_check.mjs JOB, JOB = JSON {"url", "times": [t...], "shots": [{"t", "mode", "path"}],
// "measureGlb", "out"}
import { writeFileSync } from 'node:fs';
import { openBrowser, releaseBrowser } from './chromium.mjs';

const job = JSON.parse(process.argv[2]);
const browser = await openBrowser();
const logs = [];
let page;
try {
  page = await browser.newPage();
  page.on('console', (m) => logs.push(`${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => logs.push(`pageerror: ${e.message}`));
  page.on('requestfailed', (r) => logs.push(`requestfailed: ${r.url()} ${r.failure()?.errorText}`));
  await page.setViewport({ width: job.width ?? 800, height: job.height ?? 600 });
  await page.goto(job.url, { waitUntil: 'load', timeout: 120_000 });
  await page.waitForFunction('window.pdeanimViewer !== undefined', { timeout: 120_000 });
  await page.evaluate('window.pdeanimViewer.ready');
  const result = { logs };
  result.info = await page.evaluate(() => {
    const v = window.pdeanimViewer;
    return { mode: v.mode, gpuUnavailableReason: v.gpuUnavailableReason, nVertices: v.clip.nVertices,
      kind: v.clip.kind, sizes: v.sizes(), stats: document.querySelector('#stats').innerText, model: v.model,
      timings: v.timings, gpuBytes: v.gpuBytes };
  });
  result.positions = [];
  for (const t of job.times ?? []) {
    result.positions.push(await page.evaluate((tt) => Array.from(window.pdeanimViewer.positions(tt)), t));
  }
  if (job.measureGlb) result.glb = await page.evaluate(() => window.pdeanimViewer.measureGlb());
  result.shots = [];
  for (const shot of job.shots ?? []) {
    const mode = await page.evaluate((m) => window.pdeanimViewer.setMode(m), shot.mode);
    await page.evaluate((t) => window.pdeanimViewer.show(t), shot.t);
    await page.screenshot({ path: shot.path });
    result.shots.push({ ...shot, mode });
  }
  if (job.reference) {
    // the source glTF drawn by three.js alone (GLTFLoader, its own animation at time t * duration) with the
    // viewer's camera and lights, next to the clip's frame at t on it
    const r = job.reference;
    await page.evaluate((t) => window.pdeanimViewer.show(t), r.t);
    await page.screenshot({ path: r.clipPath });
    result.reference = await page.evaluate(async ({ url, key, t }) => {
      const { GLTFLoader } = await import('three/addons/loaders/GLTFLoader.js');
      const THREE = await import('three');
      const res = await fetch(url, { headers: { Authorization: `Bearer ${key}` } });
      const gltf = await new GLTFLoader().parseAsync(await res.arrayBuffer(), '');
      const mixer = new THREE.AnimationMixer(gltf.scene);
      const anim = gltf.animations[0];
      mixer.clipAction(anim).play();
      mixer.setTime(t * anim.duration);
      await window.pdeanimViewer.swapModel(gltf.scene);
      let flat = false;
      gltf.scene.traverse((o) => { if (o.isMesh) flat = flat || Boolean(o.material.flatShading); });
      return { flat, model: window.pdeanimViewer.model };
    }, { url: r.fileUrl, key: r.key, t: r.t });
    await page.screenshot({ path: r.referencePath });
    await page.evaluate(() => window.pdeanimViewer.swapModel(null));
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
