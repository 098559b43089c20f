// Progressive playback in headless Chromium for tests/browser/test_stream.py: on the service's viewer page
// (its import map), PDEClipLoader loads a long service clip in the streamable layout over a throttled network
// (CDP Network.emulateNetworkConditions), draws its first frame, then plays on into later windows. The network
// events (CDP Network.requestWillBeSent / dataReceived / loadingFinished) of the coefficients request are
// recorded with the page's times, so the test can say from them how many bytes had arrived at the first frame.
// Usage: node stream_check.mjs JOB, JOB = JSON {"origin", "clip", "key", "throughput" (bytes/s), "play" (the
// normalised time to play to), "maxWindows", "out"}
import { writeFileSync } from 'node:fs';
import { openBrowser, releaseBrowser } from './chromium.mjs';

const job = JSON.parse(process.argv[2]);
const browser = await openBrowser();
const logs = [];
const result = { logs, requests: {}, events: [] };
let page;
try {
  page = await browser.newPage();
  page.on('console', (m) => logs.push(`${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => logs.push(`pageerror: ${e.message}`));
  await page.goto(`${job.origin}/viewer`, { waitUntil: 'load', timeout: 120_000 });
  const cdp = await page.createCDPSession();
  await cdp.send('Network.enable');
  await cdp.send('Network.emulateNetworkConditions', {
    offline: false, latency: 0, downloadThroughput: job.throughput, uploadThroughput: -1,
  });
  cdp.on('Network.requestWillBeSent', (e) => {
    result.requests[e.requestId] = { url: e.request.url, range: e.request.headers.Range ?? null, wallTime: e.wallTime, timestamp: e.timestamp };
  });
  cdp.on('Network.responseReceived', (e) => {
    const r = result.requests[e.requestId];
    if (r) Object.assign(r, { status: e.response.status, headers: e.response.headers });
  });
  cdp.on('Network.dataReceived', (e) => result.events.push({ type: 'data', id: e.requestId, timestamp: e.timestamp, bytes: e.dataLength }));
  cdp.on('Network.loadingFinished', (e) => result.events.push({ type: 'finished', id: e.requestId, timestamp: e.timestamp }));
  result.page = await page.evaluate(async (j) => {
    const THREE = await import('three');
    const { PDEClipLoader, attachClip } = await import('pdeanim/three.js');
    let longest = 0;
    new PerformanceObserver((list) => {
      for (const e of list.getEntries()) longest = Math.max(longest, e.duration);
    }).observe({ type: 'longtask', buffered: true });
    const canvas = document.createElement('canvas');
    canvas.width = 320;
    canvas.height = 240;
    document.body.append(canvas);
    const renderer = new THREE.WebGLRenderer({ canvas });
    const started = performance.timeOrigin + performance.now();
    const loader = new PDEClipLoader().setRequestHeader({ Authorization: `Bearer ${j.key}` }).setMaxWindows(j.maxWindows);
    const clip = await loader.loadAsync(`/v1/clips/${j.clip}`);
    const windowsDecoded = [];
    clip.addEventListener('window', (e) => windowsDecoded.push(e.detail.index));
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(Float32Array.from(clip.rest), 3));
    geometry.setIndex(new THREE.BufferAttribute(Uint32Array.from(clip.faces), 1));
    geometry.computeVertexNormals();
    const mesh = new THREE.Mesh(geometry, new THREE.MeshStandardMaterial());
    const scene = new THREE.Scene().add(mesh, new THREE.HemisphereLight(0xffffff, 0x333333, 2));
    const camera = new THREE.PerspectiveCamera(40, 4 / 3, 0.01, 100);
    camera.position.set(0, 0, 6);
    const player = attachClip(mesh, clip, { renderer });
    player.setTime(0);
    renderer.render(scene, camera);
    renderer.getContext().finish();
    const firstFrame = performance.timeOrigin + performance.now();
    const first = {
      streaming: Boolean(clip.streaming), nWindows: clip.nWindows, decodedAtFirstFrame: clip.decoded.size,
      gpu: player.gpu, windowT1: clip.windows[0].t1,
    };
    // play on (frame by frame) into later windows: each waits for its window as a player would buffer
    let most = clip.decoded.size;
    let frames = 1;
    const shown = [];
    let t = 0;
    for (; t <= j.play; t += 0.004) {
      if (!clip.ready(t)) await clip.whenReady(t);
      player.setTime(t);
      renderer.render(scene, camera);
      await new Promise((r) => requestAnimationFrame(r));
      most = Math.max(most, clip.decoded.size);
      frames++;
      if (shown.at(-1) !== clip.windowAt(t)) shown.push(clip.windowAt(t));
    }
    const pos = player.positions(t - 0.004); // the last time shown (its window decoded)
    clip.close();
    return { ...first, started, firstFrame, frames, mostDecoded: most, windowsDecoded, windowsShown: shown,
      longestTask: longest, finite: pos.every(Number.isFinite) };
  }, job);
} catch (err) {
  result.error = `${err.name}: ${err.message}`;
} finally {
  if (page) await page.close().catch(() => {});
  await releaseBrowser(browser);
}
writeFileSync(job.out, JSON.stringify(result));
