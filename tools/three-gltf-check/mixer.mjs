#!/usr/bin/env node
// Play a GLB's first animation with three.js's AnimationMixer in node and print one JSON line: for each
// mesh (depth-first), its _PDEANIM_VERTEX map (null without one) and, at each time, every vertex's world
// position as three.js computes it on the CPU (Mesh.getVertexPosition: morph targets with the mixer's
// influences, then the world matrix), so a test can compare what a player shows with the clip.
// Usage: node mixer.mjs FILE.glb T1,T2,...  (times in seconds); exit status 1 when it does not load.
import fs from 'node:fs';
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { MeshoptDecoder } from 'three/examples/jsm/libs/meshopt_decoder.module.js';

async function main() {
  const [file, timeList] = process.argv.slice(2);
  const times = timeList.split(',').map(Number);
  const data = fs.readFileSync(file);
  const loader = new GLTFLoader();
  loader.setMeshoptDecoder(MeshoptDecoder);
  // node has no image decoder: textures resolve to empty ones (positions do not depend on them)
  loader.register(() => ({ name: 'node_texture_stub', loadTexture: () => Promise.resolve(new THREE.Texture()) }));
  const gltf = await loader.parseAsync(data.buffer.slice(data.byteOffset, data.byteOffset + data.byteLength), '');
  const mixer = new THREE.AnimationMixer(gltf.scene);
  mixer.clipAction(gltf.animations[0]).play();
  const meshes = [];
  gltf.scene.traverse((o) => {
    if (o.isMesh) meshes.push(o);
  });
  const out = meshes.map((m) => {
    const map = m.geometry.getAttribute('_pdeanim_vertex');
    const ids = map ? Array.from({ length: map.count }, (_, i) => map.getX(i)) : null;
    return { name: m.name, map: ids, frames: [] };
  });
  const v = new THREE.Vector3();
  for (const t of times) {
    mixer.setTime(t);
    gltf.scene.updateMatrixWorld(true);
    meshes.forEach((m, j) => {
      const n = m.geometry.getAttribute('position').count;
      const frame = new Array(3 * n);
      for (let i = 0; i < n; i++) {
        m.getVertexPosition(i, v).applyMatrix4(m.matrixWorld);
        frame[3 * i] = v.x;
        frame[3 * i + 1] = v.y;
        frame[3 * i + 2] = v.z;
      }
      out[j].frames.push(frame);
    });
  }
  process.stdout.write(JSON.stringify({ file, duration: gltf.animations[0].duration, meshes: out }) + '\n');
}

main().catch((err) => {
  process.stderr.write(String(err && err.stack ? err.stack : err) + '\n');
  process.exit(1);
});
