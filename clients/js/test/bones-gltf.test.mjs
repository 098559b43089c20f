// The skinned animation GLB the Python library exports for a clip with bones (format 1.1), loaded with
// three.js's GLTFLoader and played by three.js's own AnimationMixer (no pdeanim code in the loop): at every
// key, three's skinned (and, with a residual, morphed) vertices are the JS evaluator's positions of the clip.
// The GLBs are made by test/tools/bone_glbs.py from the bone fixtures.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { createEvaluator, decodeClipFile } from '../src/index.js';
import { clipDuration } from '../src/three.js';
import { manifest, readBytes } from './helpers.mjs';

const GLTF = join(dirname(fileURLToPath(import.meta.url)), 'gltf');
const glbs = JSON.parse(readFileSync(join(GLTF, 'manifest.json'), 'utf8'));
const man = manifest();

async function loadGlb(file) {
  const bytes = readBytes(join(GLTF, file));
  return new GLTFLoader().parseAsync(bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength), '');
}

for (const [name, entry] of Object.entries(glbs)) {
  test(`three.js plays the skinned GLB of ${name} with its AnimationMixer: every key is the clip's frame`, async () => {
    const c = man.cases.find((x) => x.name === name);
    const clip = decodeClipFile(readBytes(join(GLTF, entry.clip)));
    const gltf = await loadGlb(entry.glb);
    const meshes = [];
    gltf.scene.traverse((o) => o.isMesh && meshes.push(o));
    assert.equal(meshes.length, 1);
    const mesh = meshes[0];
    assert.ok(mesh.isSkinnedMesh, 'a SkinnedMesh: three.js skins it natively');
    assert.ok(mesh.skeleton.bones.length >= clip.bones.nBones);
    const morphs = mesh.geometry.morphAttributes.position?.length ?? 0;
    if (c.bones.residual_zero) assert.equal(morphs, 0, 'a zero residual exports no morph targets');
    else assert.ok(morphs > 0, 'the residual rides on morph targets');
    assert.equal(mesh.geometry.getAttribute('position').count, clip.nVertices);
    const [animation] = gltf.animations;
    assert.ok(Math.abs(animation.duration - clipDuration(clip)) < 1e-5 * clipDuration(clip));
    const mixer = new THREE.AnimationMixer(gltf.scene);
    // played once and held: the last key is the clip's last frame (LoopRepeat would wrap it to the first)
    const action = mixer.clipAction(animation).setLoop(clip.looping ? THREE.LoopRepeat : THREE.LoopOnce, Infinity);
    action.clampWhenFinished = true;
    action.play();
    const keys = animation.tracks[0].times;
    assert.ok(keys.length >= 4);
    const ev = createEvaluator(clip);
    const v = new THREE.Vector3();
    let worst = 0;
    let moved = 0;
    for (const seconds of keys) {
      mixer.setTime(seconds);
      gltf.scene.updateMatrixWorld(true);
      const t = Math.min(seconds / clipDuration(clip), 1);
      const want = ev.evaluate(t);
      for (let i = 0; i < clip.nVertices; i++) {
        mesh.getVertexPosition(i, v).applyMatrix4(mesh.matrixWorld);
        worst = Math.max(worst, Math.abs(v.x - want[i * 3]), Math.abs(v.y - want[i * 3 + 1]), Math.abs(v.z - want[i * 3 + 2]));
        moved = Math.max(moved, Math.abs(want[i * 3] - clip.rest[i * 3]));
      }
    }
    assert.ok(moved > 0.01 * c.diagonal, 'the clip moves');
    // float32 keys (quaternions, translations) skinned in float32 by three.js: the exporter's test sees 4e-8
    assert.ok(worst <= 1e-6 * c.diagonal, `${name}: ${worst / c.diagonal} of the diagonal`);
  });
}
