// three.js conventions: PDEClipLoader over real HTTP (load, loadAsync, progress, setRequestHeader, errors,
// the LoadingManager), and AnimationMixer driving a player (action time -> t, weights -> influence,
// crossFadeTo, timeScale, loop modes and events), also mixed with a skinned animation on the same model.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { createServer } from 'node:http';
import { join } from 'node:path';
import * as THREE from 'three';
import { createEvaluator, splitClipFile } from '../src/index.js';
import { PDEClipLoader, attachClip, clipAnimation, clipDuration } from '../src/three.js';
import { FIXTURES, manifest, readBytes } from './helpers.mjs';

// node has no ProgressEvent, which three's FileLoader makes for its progress callbacks (browsers have it)
globalThis.ProgressEvent ??= class ProgressEvent extends Event {
  constructor(type, init = {}) {
    super(type);
    Object.assign(this, { lengthComputable: false, loaded: 0, total: 0, ...init });
  }
};

const man = manifest();
const c = man.cases.find((x) => x.motion === 'rigid' && x.looping);
const open = man.cases.find((x) => x.kind === 'dynamic-pde' && !x.looping);
const file = readBytes(join(FIXTURES, c.clip));
const parts = splitClipFile(file);

function serve() {
  const seen = [];
  const server = createServer((req, res) => {
    seen.push({ url: req.url, auth: req.headers.authorization });
    const body = {
      '/v1/clips/abc/topology': parts.topology,
      '/v1/clips/abc/coefficients': parts.coefficients,
      '/files/x.clip': file,
    }[req.url.split('?')[0]];
    if (req.headers.authorization !== 'Bearer k1') {
      res.writeHead(401, { 'Content-Type': 'application/json' });
      res.end(JSON.stringify({ error: { code: 'unauthorized', message: 'unknown API key' } }));
    } else if (!body) {
      res.writeHead(404).end();
    } else {
      res.writeHead(200, { 'Content-Type': 'application/octet-stream', 'Content-Length': body.length });
      res.end(Buffer.from(body));
    }
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve({ server, seen })));
}

test('PDEClipLoader loads CLIP files and service clips with the request headers, reporting progress', async () => {
  const { server, seen } = await serve();
  try {
    const base = `http://127.0.0.1:${server.address().port}/`;
    const manager = new THREE.LoadingManager();
    const events = [];
    manager.onStart = () => events.push('start');
    manager.onLoad = () => events.push('load');
    const loader = new PDEClipLoader(manager).setPath(base).setRequestHeader({ Authorization: 'Bearer k1' });
    const progress = [];
    const clip = await loader.loadAsync('files/x.clip', (e) => progress.push([e.loaded, e.total]));
    assert.equal(clip.nVertices, c.n_vertices);
    assert.ok(clip.gpuTables, 'the GPU tables come with the clip');
    assert.deepEqual(progress.at(-1), [file.length, file.length]);
    const service = await loader.loadAsync('v1/clips/abc', (e) => progress.push([e.loaded, e.total]));
    const total = parts.topology.length + parts.coefficients.length;
    assert.deepEqual(progress.at(-1), [total, total]);
    assert.deepEqual(createEvaluator(service).evaluate(0.3), createEvaluator(clip).evaluate(0.3));
    assert.ok(seen.every((s) => s.auth === 'Bearer k1'));
    assert.deepEqual(events, ['start', 'load', 'start', 'load']);
    // callbacks: onLoad, and onError with the HTTP status
    const loaded = await new Promise((resolve, reject) => loader.load('files/x.clip', resolve, undefined, reject));
    assert.equal(loaded.nVertices, c.n_vertices);
    const bad = new PDEClipLoader().setPath(base).setRequestHeader({ Authorization: 'Bearer nope' });
    await assert.rejects(bad.loadAsync('files/x.clip'), /401/);
    await assert.rejects(loader.loadAsync('files/none.clip'), /404/);
    assert.throws(() => loader.parse(new Uint8Array(40).buffer), /pdeanim container|too short/);
  } finally {
    server.close();
  }
});

function meshOf(clip) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(Float32Array.from(clip.rest), 3));
  g.setIndex(new THREE.BufferAttribute(Uint32Array.from(clip.faces), 1));
  return new THREE.Mesh(g, new THREE.MeshStandardMaterial());
}

test('AnimationMixer: action time maps to t, weights to the influence; timeScale, loop and events work', () => {
  const clip = new PDEClipLoader().parse(readBytes(join(FIXTURES, open.clip)));
  const mesh = meshOf(clip);
  const scene = new THREE.Scene().add(mesh);
  const player = attachClip(mesh, clip);
  const animation = clipAnimation(player, { name: 'run' });
  assert.equal(animation.duration, clipDuration(clip));
  assert.equal(player.influence, 0, 'the mixer owns the influence from here on');
  const mixer = new THREE.AnimationMixer(scene); // rooted above the mesh
  const action = mixer.clipAction(animation);
  action.setLoop(THREE.LoopOnce, 1);
  action.clampWhenFinished = true;
  const finished = [];
  mixer.addEventListener('finished', (e) => finished.push(e.action));
  action.play();
  const d = animation.duration;
  mixer.update(0.25 * d);
  assert.ok(Math.abs(player.time - 0.25) < 1e-9, `${player.time}`);
  assert.equal(player.influence, 1);
  action.timeScale = 2;
  mixer.update(0.25 * d); // twice as fast: 0.25 + 0.5
  assert.ok(Math.abs(player.time - 0.75) < 1e-9);
  mixer.update(d); // past the end of a LoopOnce action: clamped at t = 1, 'finished' fired
  assert.equal(player.time, 1);
  assert.deepEqual(finished, [action]);
  // the player's shared state follows: the GPU uniforms are the ones of t = 1
  assert.equal(player.uniforms.pdeSeg.value, clip.nSegments - 1);
});

test('AnimationMixer: a looping clip wraps with LoopRepeat and fires loop events', () => {
  const clip = new PDEClipLoader().parse(file);
  const mesh = meshOf(clip);
  const player = attachClip(mesh, clip);
  const action = new THREE.AnimationMixer(mesh).clipAction(clipAnimation(player, { duration: 2 }));
  const loops = [];
  action.getMixer().addEventListener('loop', () => loops.push(player.time));
  action.play();
  action.getMixer().update(0.5);
  assert.ok(Math.abs(player.time - 0.25) < 1e-9);
  action.getMixer().update(2); // 2.5 s: one loop, t = 0.25
  assert.equal(loops.length, 1);
  assert.ok(Math.abs(player.time - 0.25) < 1e-9, `${player.time}`);
});

/** A mesh over the clip's vertices with a two-bone skeleton and a clip that turns the second bone. */
function skinnedOf(clip) {
  const g = meshOf(clip).geometry;
  const n = clip.nVertices;
  g.setAttribute('skinIndex', new THREE.Uint16BufferAttribute(new Uint16Array(n * 4).map((_, i) => (i % 4 === 0 ? (i / 4) % 2 : 0)), 4));
  g.setAttribute('skinWeight', new THREE.Float32BufferAttribute(new Float32Array(n * 4).map((_, i) => (i % 4 === 0 ? 1 : 0)), 4));
  const bones = [new THREE.Bone(), new THREE.Bone()];
  bones[0].name = 'hip';
  bones[1].name = 'leg';
  bones[0].add(bones[1]);
  const mesh = new THREE.SkinnedMesh(g, new THREE.MeshStandardMaterial());
  mesh.add(bones[0]);
  mesh.bind(new THREE.Skeleton(bones));
  const turn = new THREE.QuaternionKeyframeTrack('leg.quaternion', [0, 1], [0, 0, 0, 1, 0, 0, Math.SQRT1_2, Math.SQRT1_2]);
  return { mesh, walk: new THREE.AnimationClip('walk', 1, [turn]) };
}

test('crossFadeTo between a skinned animation and the clip on one model: weights become the influence', () => {
  const clip = new PDEClipLoader().parse(file);
  const { mesh, walk } = skinnedOf(clip);
  const player = attachClip(mesh, clip); // the clip replaces the skinned result, mixed by the influence
  const mixer = new THREE.AnimationMixer(mesh);
  const skinned = mixer.clipAction(walk).play();
  const pde = mixer.clipAction(clipAnimation(player, { duration: 1 }));
  mixer.update(0.5);
  assert.equal(player.influence, 0);
  assert.equal(player.uniforms.pdeEnabled.value, false, 'no clip evaluation while its weight is 0');
  const leg = mesh.skeleton.bones[1];
  assert.ok(leg.quaternion.z > 0.1, 'the skinned animation plays');
  pde.play();
  skinned.crossFadeTo(pde, 1, false);
  mixer.update(0.5); // halfway through the fade
  assert.ok(player.influence > 0.3 && player.influence < 0.7, `${player.influence}`);
  assert.ok(Math.abs(player.influence + skinned.getEffectiveWeight() - 1) < 1e-9);
  assert.ok(player.time > 0 && player.time <= 1);
  mixer.update(1); // fade done: the clip alone
  assert.equal(player.influence, 1);
  assert.equal(skinned.getEffectiveWeight(), 0);
  // and back: the clip fades out, the skinned animation takes over again
  pde.crossFadeTo(skinned.reset().play(), 0.5, false);
  mixer.update(1);
  assert.equal(player.influence, 0);
  const shader = { vertexShader: THREE.ShaderLib.standard.vertexShader, fragmentShader: '', uniforms: {} };
  mesh.material.onBeforeCompile(shader, null);
  // skinning runs first, then the clip is mixed in: at influence 0 the skinned mesh is drawn as it is
  const vs = shader.vertexShader;
  assert.ok(vs.indexOf('#include <skinning_vertex>') < vs.indexOf('mix(transformed, pdePosition, pdeInfluence)'));
});

// Blends of the clip action with skeletal actions, against a reference computed here: the bones are three.js's
// blend of the skeletal actions and the pose the clip was fitted on (weights normalised, the bind pose filling
// a total weight under 1), the skinned side is linear blend skinning of those bones, and the drawn vertex is
// (1 - w) skinned + w clip at the clip action's effective weight w and time.

const WALK = [0, 0, 0, 1, 0, 0, Math.sin(0.5), Math.cos(0.5)]; // leg: 0 -> 1 rad about z over 1 s
const RUN = [0, 0, Math.sin(-0.3), Math.cos(-0.3), 0, 0, Math.sin(-0.9), Math.cos(-0.9)]; // -0.6 -> -1.8 rad

function legTrack(values, duration = 1) {
  return new THREE.QuaternionKeyframeTrack('leg.quaternion', [0, duration], values);
}

function legAt(values, u) {
  const q = new THREE.Quaternion().fromArray(values, 0);
  return q.slerp(new THREE.Quaternion().fromArray(values, 4), u);
}

/** The leg's reference rotation: skeletal weights [[w, quaternion], ...] blended as three's mixer does. */
function referenceLeg(parts) {
  const total = parts.reduce((n, [w]) => n + w, 0);
  const q = new THREE.Quaternion();
  let acc = 0;
  for (const [w, p] of parts) {
    if (w <= 0) continue;
    acc += w;
    if (acc === w) q.copy(p);
    else q.slerp(p, w / acc);
  }
  if (total < 1) q.slerp(new THREE.Quaternion(), 1 - total); // the bind pose fills the rest
  return q;
}

/** The drawn vertices (V * 3): linear blend skinning with mesh's current bones, mixed with the clip. */
function drawn(mesh, player) {
  mesh.updateMatrixWorld(true);
  mesh.skeleton.update();
  const n = player.clip.nVertices;
  const clipPos = player.positions(player.time);
  const out = new Float64Array(n * 3);
  const v = new THREE.Vector3();
  const w = player.influence;
  for (let i = 0; i < n; i++) {
    mesh.getVertexPosition(i, v);
    out[i * 3] = (1 - w) * v.x + w * clipPos[i * 3];
    out[i * 3 + 1] = (1 - w) * v.y + w * clipPos[i * 3 + 1];
    out[i * 3 + 2] = (1 - w) * v.z + w * clipPos[i * 3 + 2];
  }
  return out;
}

/** The reference's vertices: the leg set to q, then as drawn() at weight w and clip time t. */
function reference(mesh, player, q, w, t) {
  const leg = mesh.skeleton.bones[1];
  const saved = leg.quaternion.clone();
  const state = { influence: player.influence, time: player.time };
  leg.quaternion.copy(q);
  const out = drawn(mesh, { clip: player.clip, influence: w, time: t, positions: (tt) => player.positions(tt) });
  leg.quaternion.copy(saved);
  assert.deepEqual({ influence: player.influence, time: player.time }, state);
  return out;
}

function maxDiff(a, b) {
  let m = 0;
  for (let i = 0; i < a.length; i++) m = Math.max(m, Math.abs(a[i] - b[i]));
  return m;
}

function blendSetup(withPose = true) {
  const clip = new PDEClipLoader().parse(file);
  const { mesh } = skinnedOf(clip);
  const player = attachClip(mesh, clip);
  const mixer = new THREE.AnimationMixer(mesh);
  const walk = mixer.clipAction(new THREE.AnimationClip('walk', 1, [legTrack(WALK)]));
  // the clip was fitted on 'run' (2 s): its pose at the clip's t is run's at 2 t
  const pose = new THREE.AnimationClip('run', 2, [legTrack(RUN, 2)]);
  const pde = mixer.clipAction(clipAnimation(player, { duration: 1, ...(withPose ? { pose } : {}) }));
  const diag = Math.hypot(...[0, 1, 2].map((k) => {
    const xs = clip.rest.filter((_, i) => i % 3 === k);
    return Math.max(...xs) - Math.min(...xs);
  }));
  return { clip, mesh, player, mixer, walk, pde, diag };
}

test('blends: crossFadeTo, crossFadeFrom, fadeIn/fadeOut and weights match the reference blend', () => {
  const scenarios = {
    crossFadeTo: ({ walk, pde }) => { walk.play(); pde.play(); walk.crossFadeTo(pde, 1, false); },
    crossFadeFrom: ({ walk, pde }) => { walk.play(); pde.play(); pde.crossFadeFrom(walk, 1, false); },
    fades: ({ walk, pde }) => { walk.play().fadeOut(1); pde.play().fadeIn(2); },
    weights: ({ walk, pde }) => { walk.play().setEffectiveWeight(0.3); pde.play().setEffectiveWeight(0.45); },
    warped: ({ walk, pde }) => { walk.play(); pde.play(); walk.crossFadeTo(pde, 1, true); },
  };
  for (const [name, start] of Object.entries(scenarios)) {
    const s = blendSetup();
    start(s);
    for (const dt of [0.1, 0.25, 0.3]) {
      s.mixer.update(dt);
      const w = s.pde.getEffectiveWeight();
      const ws = s.walk.getEffectiveWeight();
      assert.ok(Math.abs(s.player.influence - Math.min(w, 1)) < 1e-12, name);
      const tWalk = s.walk.time;
      const tClip = s.pde.time / 1;
      assert.ok(Math.abs(s.player.time - tClip) < 1e-9, `${name}: ${s.player.time} ${tClip}`);
      const q = referenceLeg([[ws, legAt(WALK, tWalk)], [w, legAt(RUN, tClip)]]);
      const err = maxDiff(drawn(s.mesh, s.player), reference(s.mesh, s.player, q, Math.min(w, 1), tClip));
      assert.ok(err < 1e-7 * s.diag, `${name} at weights ${ws.toFixed(3)}/${w.toFixed(3)}: ${err / s.diag}`);
    }
  }
});

test('blends: without the pose the skinned side passes through the bind pose (why pose exists)', () => {
  const s = blendSetup(false);
  s.walk.play();
  s.pde.play();
  s.walk.crossFadeTo(s.pde, 1, false);
  s.mixer.update(0.5);
  const w = s.pde.getEffectiveWeight();
  const leg = s.mesh.skeleton.bones[1].quaternion;
  // the mixer filled the clip's half of the leg's weight with the bind pose (the identity rotation)
  const bindBlend = referenceLeg([[1 - w, legAt(WALK, s.walk.time)]]);
  assert.ok(maxDiff(leg.toArray(), bindBlend.toArray()) < 1e-8, `${leg.toArray()} ${bindBlend.toArray()}`);
  const withPose = referenceLeg([[1 - w, legAt(WALK, s.walk.time)], [w, legAt(RUN, s.pde.time)]]);
  assert.ok(leg.angleTo(withPose) > 0.3, 'the fixture would catch a bind-pose blend');
  assert.throws(() => clipAnimation(s.player, { pose: {} }), /AnimationClip/);
});
