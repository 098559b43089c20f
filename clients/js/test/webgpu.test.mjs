// pdeanim/webgpu without a browser: the entry point resolves by its package name (it was
// ERR_PACKAGE_PATH_NOT_EXPORTED), pdeanim/three's refusal points to it, and the player gives the mesh node
// materials (a built-in material's node counterpart with its settings, or a clone of a NodeMaterial with its
// own positionNode kept) whose vertex stage plays the clip, restores them on detach, and refuses what it
// cannot draw. test/webgpu-browser.test.mjs renders with WebGPURenderer.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import * as THREE from 'three';
import { MeshStandardNodeMaterial, NodeMaterial } from 'three/webgpu';
import { positionLocal } from 'three/tsl';
import { decodeClipFile } from '../src/index.js';
import { WEBGPU_REFUSAL } from '../src/three.js';
import { AnimationMixer } from 'three';
import { FIXTURES, manifest, readBytes } from './helpers.mjs';

const man = manifest();
const WG = await import('pdeanim/webgpu'); // by its package name, as a user imports it
const webgpu = { isWebGPURenderer: true }; // what the player checks (a WebGPURenderer needs a browser)

function loadCase(c) {
  return decodeClipFile(readBytes(join(FIXTURES, c.clip)));
}

function meshOf(clip, material) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(Float32Array.from(clip.rest), 3));
  g.setIndex(new THREE.BufferAttribute(Uint32Array.from(clip.faces), 1));
  g.computeVertexNormals();
  return new THREE.Mesh(g, material);
}

const rigid = () => loadCase(man.cases.find((x) => x.motion === 'rigid'));

test('pdeanim/webgpu is exported, and pdeanim/three refuses WebGPURenderer pointing to it', async () => {
  for (const k of ['ClipPlayer', 'ScenePlayer', 'attachClip', 'attachClipToScene', 'PDEClipLoader', 'clipAnimation']) {
    assert.equal(typeof WG[k], 'function', k);
  }
  assert.match(WEBGPU_REFUSAL, /pdeanim\/webgpu/);
  assert.doesNotMatch(WEBGPU_REFUSAL, /no WebGPU|not yet/);
});

test('a built-in material becomes its node material, with its settings; detach gives it back', () => {
  const clip = rigid();
  const material = new THREE.MeshStandardMaterial({ color: 0x336699, roughness: 0.25, side: THREE.DoubleSide });
  const mesh = meshOf(clip, material);
  const player = WG.attachClip(mesh, clip, { renderer: webgpu });
  const m = mesh.material;
  assert.ok(m instanceof MeshStandardNodeMaterial);
  assert.notEqual(m.uuid, material.uuid);
  assert.equal(m.color.getHex(), 0x336699);
  assert.equal(m.roughness, 0.25);
  assert.equal(m.side, THREE.DoubleSide);
  // the clip is played in the vertex stage after three.js's own steps; shadows follow it
  assert.ok(Object.hasOwn(m, 'setupPosition'));
  assert.ok(m.castShadowPositionNode?.isNode);
  assert.equal(player.pass, false);
  player.setTime(0.3);
  assert.equal(player.gpu, true);
  // a switch to the CPU path rebuilds the node graph (another vertex stage)
  const version = m.version;
  player.useGPU(false);
  assert.ok(m.version > version);
  assert.ok(mesh.geometry.getAttribute('pdeCpuPosition'));
  player.detach();
  assert.equal(mesh.material, material);
  assert.equal(mesh.geometry.getAttribute('pdeVertex'), undefined);
});

test('a NodeMaterial is cloned with its own positionNode kept (the clip is mixed after it)', () => {
  const clip = rigid();
  const own = positionLocal.mul(1.5);
  const material = new MeshStandardNodeMaterial();
  material.positionNode = own;
  const mesh = meshOf(clip, material);
  const player = WG.attachClip(mesh, clip, { shadows: false });
  assert.notEqual(mesh.material, material);
  assert.equal(mesh.material.positionNode, own);
  assert.equal(mesh.material.castShadowPositionNode, null); // shadows: the mesh's own (shadows: false)
  const clone = player.clone(); // an independent player with its own node material
  assert.notEqual(clone.mesh.material, mesh.material);
  assert.equal(clone.mesh.material.positionNode, own);
  clone.detach();
  player.detach();
  assert.equal(mesh.material, material);
});

test('refused: a WebGLRenderer (at attach and at the first frame), the pass, a ShaderMaterial', () => {
  const clip = rigid();
  const gl = { isWebGLRenderer: true };
  const mesh = () => meshOf(clip, new THREE.MeshLambertMaterial());
  assert.throws(() => WG.attachClip(mesh(), clip, { renderer: gl }), { message: WG.WEBGL_REFUSAL });
  const m = mesh();
  WG.attachClip(m, clip);
  assert.throws(() => m.onBeforeRender(gl, null, null, m.geometry, m.material, null), { message: WG.WEBGL_REFUSAL });
  assert.doesNotThrow(() => m.onBeforeRender(webgpu, null, null, m.geometry, m.material, null));
  assert.throws(() => WG.attachClip(mesh(), clip, { pass: true }), /vertex stage/);
  assert.throws(() => WG.attachClip(meshOf(clip, new THREE.ShaderMaterial()), clip), /ShaderMaterial has no node material/);
  assert.ok(NodeMaterial.prototype.setupPosition);
});

test('scenes, multi-material meshes and the AnimationMixer link work as in pdeanim/three', () => {
  const clip = rigid();
  const root = new THREE.Group();
  const mesh = meshOf(clip, [new THREE.MeshPhongMaterial(), new THREE.MeshToonMaterial()]);
  mesh.geometry.addGroup(0, clip.faces.length, 0);
  root.add(mesh);
  const player = WG.attachClipToScene(root, clip, { renderer: webgpu });
  assert.deepEqual(mesh.material.map((m) => m.isNodeMaterial), [true, true]);
  const mixer = new AnimationMixer(root);
  const action = mixer.clipAction(WG.clipAnimation(player, { duration: 2 }));
  action.play();
  mixer.update(0.5);
  assert.ok(Math.abs(player.time - 0.25) < 1e-9);
  assert.equal(player.influence, 1);
  player.detach();
  assert.equal(mesh.material[0].type, 'MeshPhongMaterial');
  assert.ok(!mesh.material[0].isNodeMaterial);
});
