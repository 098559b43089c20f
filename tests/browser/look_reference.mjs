// The look test's reference: the source glTF drawn by three.js alone (GLTFLoader, its own skinning and
// animation) in a page of its own, served at the service's origin (so it loads the service's vendored three.js)
// but answered by the test, without the viewer's Content-Security-Policy or any of the viewer's code.
import { Buffer } from 'node:buffer';

const PAGE_PATH = '/__pdeanim_look_reference';

function pageHtml(origin) {
  return `<!doctype html><html><head><meta charset="utf-8">
<script type="importmap">{ "imports": { "three": "${origin}/static/vendor/three/three.module.js",
  "three/addons/": "${origin}/static/vendor/three/addons/" } }</script>
<script type="module">
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
window.drawReference = async ({ fileUrl, key, times, stage }) => {
  const res = await fetch(fileUrl, { headers: { Authorization: 'Bearer ' + key } });
  if (!res.ok) throw new Error('the source model: HTTP ' + res.status);
  const gltf = await new GLTFLoader().parseAsync(await res.arrayBuffer(), '');
  const canvas = document.querySelector('canvas');
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
  renderer.outputColorSpace = THREE.SRGBColorSpace;
  renderer.setPixelRatio(stage.pixelRatio);
  renderer.setSize(stage.width, stage.height);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(stage.background);
  for (const l of stage.lights) {
    const light = l.type === 'HemisphereLight' ? new THREE.HemisphereLight(l.color, l.groundColor, l.intensity)
      : new THREE.DirectionalLight(l.color, l.intensity);
    light.position.fromArray(l.position);
    if (l.target) { light.target.position.fromArray(l.target); scene.add(light.target); }
    scene.add(light);
  }
  const c = stage.camera;
  const camera = new THREE.PerspectiveCamera(c.fov, c.aspect, c.near, c.far);
  new THREE.Matrix4().fromArray(c.matrixWorld).decompose(camera.position, camera.quaternion, camera.scale);
  scene.add(gltf.scene);
  let textured = false;
  let flat = false;
  gltf.scene.traverse((o) => {
    if (o.isMesh && o.material.map?.image) textured = true;
    if (o.isMesh && o.material.flatShading) flat = true;
  });
  const mixer = new THREE.AnimationMixer(gltf.scene);
  const anim = gltf.animations[0];
  // t = 1 is the animation's last frame: played once and held there, not wrapped to its first
  const action = mixer.clipAction(anim).setLoop(THREE.LoopOnce, 1);
  action.clampWhenFinished = true;
  action.play();
  const images = [];
  for (const t of times) {
    mixer.setTime(t * anim.duration);
    renderer.render(scene, camera);
    images.push(canvas.toDataURL('image/png'));
  }
  return { textured, flat, images };
};
window.referenceReady = true;
</script></head><body style="margin:0"><canvas></canvas></body></html>`;
}

/** Write PNG data URLs to files. */
export function writeDataUrl(writeFileSync, path, dataUrl) {
  writeFileSync(path, Buffer.from(dataUrl.slice(dataUrl.indexOf(',') + 1), 'base64'));
}

/**
 * Draw the source model at each normalised time in a new page of browser (an own origin's page without the
 * viewer's CSP) with the viewer's stage (camera, lights, size); resolves to {textured, flat, images: [data URLs]}.
 */
export async function drawReference(browser, origin, { fileUrl, key, times, stage }, logs) {
  const page = await browser.newPage();
  page.on('console', (m) => logs.push(`reference ${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => logs.push(`reference pageerror: ${e.message}`));
  await page.setRequestInterception(true);
  page.on('request', (r) => {
    if (new URL(r.url()).pathname === PAGE_PATH) {
      r.respond({ status: 200, contentType: 'text/html', body: pageHtml(origin) });
    } else r.continue();
  });
  await page.setViewport({ width: stage.width, height: stage.height });
  await page.goto(origin + PAGE_PATH, { waitUntil: 'load', timeout: 120_000 });
  await page.waitForFunction('window.referenceReady === true', { timeout: 120_000 });
  try {
    return await page.evaluate((job) => window.drawReference(job), { fileUrl, key, times, stage });
  } finally {
    await page.close();
  }
}
