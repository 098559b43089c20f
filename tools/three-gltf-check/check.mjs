#!/usr/bin/env node
// Load GLB files with three.js's GLTFLoader (+ MeshoptDecoder) in node and print, per file, one JSON line
// with what a three.js app gets: meshes (vertex count, position array type, morph targets, UVs, material,
// texture image name, the positions of morph target 1) and animations (duration, tracks).
// Usage: node check.mjs A.glb [B.glb ...]; exit status 1 when a file does not load.
import fs from 'node:fs';
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { MeshoptDecoder } from 'three/examples/jsm/libs/meshopt_decoder.module.js';

function loader() {
  const l = new GLTFLoader();
  l.setMeshoptDecoder(MeshoptDecoder);
  // node has no image decoder: textures resolve to empty ones named after their glTF image
  l.register((parser) => ({
    name: 'node_texture_stub',
    loadTexture: (i) => {
      const t = new THREE.Texture();
      t.name = parser.json.images[parser.json.textures[i].source].name || '';
      return Promise.resolve(t);
    },
  }));
  return l;
}

function describe(gltf) {
  const meshes = [];
  gltf.scene.updateMatrixWorld(true);
  gltf.scene.traverse((o) => {
    if (!o.isMesh) return;
    const g = o.geometry;
    const targets = g.morphAttributes.position || [];
    meshes.push({
      name: o.name, parent: o.parent ? o.parent.name : null, vertices: g.attributes.position.count,
      positionType: g.attributes.position.array.constructor.name, targets: targets.length,
      normalTargets: (g.morphAttributes.normal || []).length, relative: g.morphTargetsRelative,
      uv: Boolean(g.attributes.uv), normal: Boolean(g.attributes.normal), material: o.material.name,
      flatShading: Boolean(o.material.flatShading),
      map: o.material.map ? o.material.map.name : null, influences: (o.morphTargetInfluences || []).length,
      worldScale: o.matrixWorld.getMaxScaleOnAxis(),
    });
  });
  const animations = gltf.animations.map((a) => ({ name: a.name, duration: a.duration, tracks: a.tracks.length }));
  return { meshes, animations };
}

async function main() {
  let failed = false;
  for (const file of process.argv.slice(2)) {
    const data = fs.readFileSync(file);
    const buffer = data.buffer.slice(data.byteOffset, data.byteOffset + data.byteLength);
    try {
      const gltf = await loader().parseAsync(buffer, '');
      process.stdout.write(JSON.stringify({ file, ...describe(gltf) }) + '\n');
    } catch (err) {
      failed = true;
      process.stdout.write(JSON.stringify({ file, error: String(err && err.stack ? err.stack : err) }) + '\n');
    }
  }
  process.exit(failed ? 1 : 0);
}

main();
