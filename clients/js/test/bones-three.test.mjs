// Clips with bones (format 1.1) in three.js: PDEClipLoader loads a bone CLIP file over real HTTP (main thread:
// node has no module workers), and three's AnimationMixer plays it through clipAnimation on the GPU path and
// the CPU fallback, mixed with the model's own skinned animation; a clip requiring an unknown feature fails
// the load with the reader's message.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { createServer } from 'node:http';
import * as THREE from 'three';
import { createEvaluator, decodeClip } from '../src/index.js';
import { PDEClipLoader, attachClip, clipAnimation, clipDuration } from '../src/three.js';
import { edited, manifest } from './helpers.mjs';
import { boneClipParts } from './bonehelpers.mjs';

globalThis.ProgressEvent ??= class ProgressEvent extends Event {
  constructor(type, init = {}) {
    super(type);
    Object.assign(this, { lengthComputable: false, loaded: 0, total: 0, ...init });
  }
};

const man = manifest();
const c = man.cases.find((x) => x.name === 'fit-displacement-chord');
const bones = boneClipParts(c, { K: 3, B: 4 });
const zero = boneClipParts(c, { K: 3, B: 4, residual: false });
const future = edited(bones.file, ({ header }) => Object.assign(header, { required: ['bones', 'hair'] }));

function serve() {
  const server = createServer((req, res) => {
    const body = {
      '/bones.clip': bones.file,
      '/zero.clip': zero.file,
      '/future.clip': future,
      '/v1/clips/b/topology': bones.topology,
      '/v1/clips/b/coefficients': bones.coefficients,
    }[req.url.split('?')[0]];
    if (!body) return res.writeHead(404).end();
    res.writeHead(200, { 'Content-Type': 'application/octet-stream', 'Content-Length': body.length });
    return res.end(Buffer.from(body));
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve(server)));
}

function meshOf(clip) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(Float32Array.from(clip.rest), 3));
  g.setIndex(Array.from(clip.faces));
  g.computeVertexNormals();
  return new THREE.Mesh(g, new THREE.MeshStandardMaterial());
}

test('PDEClipLoader loads bone clips (CLIP file and service parts) and refuses a clip needing an unknown feature', async () => {
  const server = await serve();
  try {
    const loader = new PDEClipLoader().setPath(`http://127.0.0.1:${server.address().port}/`);
    for (const url of ['bones.clip', 'v1/clips/b', 'zero.clip']) {
      const clip = await loader.loadAsync(url);
      assert.ok(clip.bones, url);
      assert.equal(clip.bones.nBones, 4);
      assert.ok(clip.gpuTables.bones, 'the GPU tables are made with the clip');
      assert.equal(clip.gpuTables.residual, url !== 'zero.clip');
    }
    await assert.rejects(loader.loadAsync('future.clip'), /requires format feature\(s\) "hair" that this reader lacks \(it supports: bones, stream\)/);
  } finally {
    server.close();
  }
});

test('AnimationMixer plays a bone clip: action time -> t, GPU bone rows and CPU positions at that t', () => {
  for (const parts of [bones, zero]) {
    const clip = new PDEClipLoader().parse(parts.file);
    const mesh = meshOf(clip);
    const scene = new THREE.Scene().add(mesh);
    const player = attachClip(mesh, clip);
    const animation = clipAnimation(player, { name: 'walk' });
    assert.equal(animation.duration, clipDuration(clip));
    const mixer = new THREE.AnimationMixer(scene);
    mixer.clipAction(animation).play();
    mixer.update(0.4 * animation.duration);
    assert.ok(Math.abs(player.time - 0.4) < 1e-9);
    assert.equal(player.influence, 1);
    const L = player.layout;
    const rows = createEvaluator(clip).bones.at(player.time).affine();
    const frame = L.textures.frame.data.subarray(L.boneTexel * 4, (L.boneTexel + L.nBones * 3) * 4);
    assert.deepEqual(Array.from(frame), Array.from(rows, Math.fround));
    // the CPU fallback at the mixer's time: the mesh's clip attribute is the evaluator's frame
    player.useGPU(false);
    mixer.update(0.1 * animation.duration);
    const want = createEvaluator(decodeClip(parts.topology, parts.coefficients)).evaluate(player.time);
    const got = mesh.geometry.getAttribute('pdeCpuPosition').array;
    for (let i = 0; i < want.length; i++) assert.ok(Math.abs(got[i] - want[i]) <= 1e-6 * c.diagonal);
    player.detach();
  }
});

test('crossFadeTo from a skinned animation to a bone clip on one SkinnedMesh: the weight becomes the influence', () => {
  const clip = new PDEClipLoader().parse(bones.file);
  const mesh = meshOf(clip);
  const skinned = new THREE.SkinnedMesh(mesh.geometry, mesh.material);
  const bone = new THREE.Bone();
  skinned.add(bone);
  const n = clip.nVertices;
  skinned.geometry.setAttribute('skinIndex', new THREE.BufferAttribute(new Uint16Array(n * 4), 4));
  skinned.geometry.setAttribute('skinWeight', new THREE.BufferAttribute(new Float32Array(n * 4).fill(0).map((_, i) => (i % 4 ? 0 : 1)), 4));
  skinned.bind(new THREE.Skeleton([bone]));
  const scene = new THREE.Scene().add(skinned);
  const player = attachClip(skinned, clip);
  const idle = new THREE.AnimationClip('idle', 1, [new THREE.NumberKeyframeTrack(`${bone.uuid}.position[y]`, [0, 1], [0, 1])]);
  const mixer = new THREE.AnimationMixer(scene);
  const from = mixer.clipAction(idle).play();
  const to = mixer.clipAction(clipAnimation(player));
  mixer.update(0.1);
  assert.equal(player.influence, 0);
  to.play();
  from.crossFadeTo(to, 1, false);
  mixer.update(0.5);
  assert.ok(player.influence > 0.3 && player.influence < 0.7, `${player.influence}`);
  mixer.update(0.6);
  assert.equal(player.influence, 1);
  player.detach();
});
