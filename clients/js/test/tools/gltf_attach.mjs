// Load a GLB with three.js's GLTFLoader (+ MeshoptDecoder), play a CLIP file on it with attachClipToScene on
// the CPU path, and print JSON: per mesh (depth-first) its name, material names, attribute names, the clip
// vertex of each of its vertices, and the positions relative to the scene root at each t. Used by tests/conformance/test_gltf_attach.py.
// Usage: node gltf_attach.mjs FILE.glb FILE.clip T1,T2,...

import { readFileSync } from 'node:fs';
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { MeshoptDecoder } from 'three/examples/jsm/libs/meshopt_decoder.module.js';
import { decodeClipFile } from '../../src/index.js';
import { attachClipToScene } from '../../src/three.js';

// node has no DOM: GLTFLoader reads `self`, and its images cannot decode here (textures stay unloaded,
// which does not matter for geometry and material checks)
globalThis.self ??= globalThis;
const warn = console.warn;
console.warn = (...args) => (String(args[0]).includes("Couldn't load texture") ? undefined : warn(...args));

const [glbPath, clipPath, tList] = process.argv.slice(2);
const bytes = readFileSync(glbPath);
const clip = decodeClipFile(readFileSync(clipPath));
const loader = new GLTFLoader().setMeshoptDecoder(MeshoptDecoder);
await MeshoptDecoder.ready;
const gltf = await loader.parseAsync(
  bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength),
  '',
);
const root = gltf.scene;
const before = [];
root.traverse((o) => {
  if (o.isMesh) {
    const mats = Array.isArray(o.material) ? o.material : [o.material];
    before.push({
      name: o.name,
      materials: mats.map((m) => m.name),
      map: mats.map((m) => Boolean(m.map)),
      attributes: Object.keys(o.geometry.attributes).sort(),
      positionType: o.geometry.getAttribute('position').array.constructor.name,
    });
  }
});
const morphBefore = [];
root.traverse(
  (o) => o.isMesh && morphBefore.push(o.morphTargetInfluences ? [...o.morphTargetInfluences] : []),
);
const player = attachClipToScene(root, clip, { gpu: false });
const rootInverse = root.matrixWorld.clone().invert();
const frames = tList
  .split(',')
  .map(Number)
  .map((t) => {
    player.setTime(t);
    const out = [];
    for (const p of player.players) {
      const rel = rootInverse.clone().multiply(p.mesh.matrixWorld);
      const pos = p.mesh.geometry.getAttribute('pdeCpuPosition'); // the CPU path's own attribute
      for (let i = 0; i < pos.count; i++) {
        out.push(new THREE.Vector3(pos.getX(i), pos.getY(i), pos.getZ(i)).applyMatrix4(rel).toArray());
      }
    }
    return out;
  });
const after = player.players.map((p) =>
  (Array.isArray(p.mesh.material) ? p.mesh.material : [p.mesh.material]).map((m) => m.name),
);
const influences = (p) => (p.mesh.morphTargetInfluences ? [...p.mesh.morphTargetInfluences] : []);
const morphWhilePlaying = player.players.map(influences);
const influenceWhilePlaying = player.influence;
const vertexMaps = player.players.map((p) => Array.from(p.vertexMap)); // clip vertex of each mesh vertex
player.detach();
const morphAfter = player.players.map(influences);
process.stdout.write(
  JSON.stringify({
    meshes: before,
    materialsWhilePlaying: after,
    frames,
    morphWhilePlaying,
    influenceWhilePlaying,
    morphAfter,
    morphBefore,
    vertexMaps,
  }),
);
