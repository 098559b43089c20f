// Frame normals against three.js's own (computeVertexNormals on the exact positions) on real meshes fed exact
// positions: Keenan Crane's Bob (tests/data/bob.obj, split at its UV seams as a glTF loader splits it, authored
// smooth normals) under a smooth bend and twist, unwelded (seam duplicates are clip vertices) and welded
// (mesh vertices mapped to clip vertices, as _pdeanim_vertex does); the CPU path and a float32 emulation of the
// shader's ring loop (glsl.js pdeRingNormal) over the ring texture; and a box's hard edges (split normals).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';
import * as THREE from 'three';
import { mergeVertices } from 'three/examples/jsm/utils/BufferGeometryUtils.js';
import { ringNormals, vertexRings } from '../src/geometry.js';
import { frameNormals, meshAttributes, ringTable } from '../src/gpu.js';

const DATA = join(dirname(fileURLToPath(import.meta.url)), '..', '..', '..', 'tests', 'data');
const f = Math.fround;

/** An OBJ with v/vt/vn corners as a loader makes it: a vertex per distinct corner; {positions, normals, faces, weld}. */
function loadObj(path) {
  const v = [];
  const vn = [];
  const corners = new Map();
  const positions = [];
  const normals = [];
  const weld = []; // the OBJ position of each vertex (the welded mesh's vertex)
  const faces = [];
  for (const line of readFileSync(path, 'utf8').split('\n')) {
    const [tag, ...rest] = line.trim().split(/\s+/);
    if (tag === 'v') v.push(rest.map(Number));
    else if (tag === 'vn') vn.push(rest.map(Number));
    else if (tag === 'f') {
      for (const c of rest) {
        if (!corners.has(c)) {
          const [pi, , ni] = c.split('/').map((x) => Number(x) - 1);
          corners.set(c, weld.length);
          weld.push(pi);
          positions.push(...v[pi]);
          normals.push(...vn[ni]);
        }
        faces.push(corners.get(c));
      }
    }
  }
  return {
    positions: Float32Array.from(positions),
    normals: Float32Array.from(normals),
    faces: Int32Array.from(faces),
    weld: Int32Array.from(weld),
  };
}

/** A smooth non-rigid deformation (bend about z along y, twist about y, a bulge) of positions, in float32. */
function deform(positions, diag) {
  const out = new Float32Array(positions.length);
  for (let i = 0; i < positions.length; i += 3) {
    const [x, y, z] = [positions[i], positions[i + 1], positions[i + 2]];
    const tw = (2.5 * y) / diag;
    const [cx, sx] = [Math.cos(tw), Math.sin(tw)];
    const xt = cx * x + sx * z;
    const zt = -sx * x + cx * z;
    const bend = (2 * y) / diag;
    const s = 1 + 0.3 * Math.sin((12 * x) / diag);
    out[i] = s * (Math.cos(bend) * xt - Math.sin(bend) * y);
    out[i + 1] = Math.sin(bend) * xt + Math.cos(bend) * y;
    out[i + 2] = s * zt;
  }
  return out;
}

/** three.js's computeVertexNormals of the geometry merged by position (a smooth source's normals). */
function threeNormals(positions, faces, merge = true) {
  let g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(positions, 3));
  g.setIndex(new THREE.BufferAttribute(Uint32Array.from(faces), 1));
  const key = (i) => `${positions[i * 3]},${positions[i * 3 + 1]},${positions[i * 3 + 2]}`;
  if (merge) g = mergeVertices(g);
  g.computeVertexNormals();
  const merged = g.getAttribute('position');
  const n = g.getAttribute('normal');
  const at = new Map();
  for (let i = 0; i < merged.count; i++) at.set(`${merged.getX(i)},${merged.getY(i)},${merged.getZ(i)}`, i);
  const out = new Float32Array(positions.length);
  for (let i = 0; i < positions.length / 3; i++) {
    const j = merge ? at.get(key(i)) : i;
    out.set([n.getX(j), n.getY(j), n.getZ(j)], i * 3);
  }
  return out;
}

/** Angles in degrees between unit normals a and b (n * 3). */
function angles(a, b) {
  const out = new Float64Array(a.length / 3);
  for (let i = 0; i < out.length; i++) {
    const d = a[i * 3] * b[i * 3] + a[i * 3 + 1] * b[i * 3 + 1] + a[i * 3 + 2] * b[i * 3 + 2];
    const l = Math.hypot(a[i * 3], a[i * 3 + 1], a[i * 3 + 2]) * Math.hypot(b[i * 3], b[i * 3 + 1], b[i * 3 + 2]);
    out[i] = (Math.acos(Math.max(-1, Math.min(1, d / l))) * 180) / Math.PI;
  }
  return out;
}

const share = (a, deg) => a.filter((x) => x <= deg).length / a.length;

function diagonal(p) {
  const box = new THREE.Box3().setFromArray(p);
  return box.max.distanceTo(box.min);
}

/** cross(u, v) in float32. */
function cross32(u, v) {
  return [f(f(u[1] * v[2]) - f(u[2] * v[1])), f(f(u[2] * v[0]) - f(u[0] * v[2])), f(f(u[0] * v[1]) - f(u[1] * v[0]))];
}

/**
 * The shader's pdeRingNormal(g, p) in float32 from the ring table (the ring texture's values, row-major) and
 * the pass texture's positions (GPU order), normalised.
 */
function emulateRingNormal(values, pos, g) {
  const first = values[2 * g];
  const count = values[2 * g + 1];
  const p = [pos[g * 3], pos[g * 3 + 1], pos[g * 3 + 2]];
  const at = (i) => [0, 1, 2].map((w) => f(pos[values[i] * 3 + w] - p[w]));
  let n = [0, 0, 0];
  const add = (c) => (n = n.map((x, w) => f(x + c[w])));
  if (count > 0) {
    for (let k = 0; k < count; k++) add(cross32(at(first + k), at(first + ((k + 1) % count))));
  } else {
    for (let k = first; k < first - 2 * count; k += 2) add(cross32(at(k), at(k + 1)));
  }
  const l = f(Math.sqrt(f(f(f(n[0] * n[0]) + f(n[1] * n[1])) + f(n[2] * n[2]))));
  return n.map((x) => f(x / l));
}

const bob = loadObj(join(DATA, 'bob.obj'));
const diag = diagonal(bob.positions);
const exactPos = deform(bob.positions, diag);

/** The mesh's frame normals (CPU path) with the clip's vertices clipRest and faces clipFaces. */
function cpuFrameNormals({ clipRest, clipFaces, clipPos, vertexMap, meshFaces, ring = true }) {
  const rings = vertexRings(clipFaces, clipRest);
  const attrs = meshAttributes({
    vertexMap,
    positions: bob.positions,
    normals: bob.normals,
    index: meshFaces,
    clipNormals: ring ? ringNormals(clipRest, rings) : null,
  });
  const cn = ringNormals(clipPos, rings);
  return { attrs, rings, got: frameNormals(clipPos, attrs, bob.normals, new Float32Array(bob.normals.length), cn) };
}

test('Bob split at its UV seams, fed exact positions: frame normals within 5 degrees of three.js on 99% of vertices', (t) => {
  const want = threeNormals(exactPos, bob.faces);
  const identity = Int32Array.from({ length: bob.weld.length }, (_, i) => i);
  const args = { clipRest: bob.positions, clipFaces: bob.faces, clipPos: exactPos, vertexMap: identity, meshFaces: bob.faces };
  const { attrs, got } = cpuFrameNormals(args);
  const a = angles(got, want);
  const smooth = attrs.pdeVertex.filter((x, i) => i % 3 === 1 && x === -1).length;
  // the triangle-turned normals this replaces, for the record
  const old = angles(cpuFrameNormals({ ...args, ring: false }).got, want);
  t.diagnostic(
    `${bob.weld.length} vertices (${smooth} smooth): within 5 deg ${share(a, 5)}, max ${Math.max(...a).toFixed(2)} deg;` +
      ` one-triangle normals: within 5 deg ${share(old, 5)}, > 20 deg ${old.filter((x) => x > 20).length}`,
  );
  assert.ok(share(a, 5) >= 0.99, `${share(a, 5)} within 5 degrees`);
  // seam duplicates (the same position) get one normal
  const byPos = new Map();
  for (let i = 0; i < bob.weld.length; i++) {
    const k = bob.weld[i];
    if (byPos.has(k)) assert.ok(angles(got.subarray(i * 3, i * 3 + 3), got.subarray(byPos.get(k) * 3, byPos.get(k) * 3 + 3))[0] < 1e-3);
    else byPos.set(k, i);
  }
});

test('Bob welded (mesh vertices mapped to clip vertices): the same normals, seam duplicates sharing their clip vertex', () => {
  const V = Math.max(...bob.weld) + 1;
  const clipRest = new Float32Array(V * 3);
  const clipPos = new Float32Array(V * 3);
  for (let i = 0; i < bob.weld.length; i++) {
    clipRest.set(bob.positions.subarray(i * 3, i * 3 + 3), bob.weld[i] * 3);
    clipPos.set(exactPos.subarray(i * 3, i * 3 + 3), bob.weld[i] * 3);
  }
  const clipFaces = bob.faces.map((v) => bob.weld[v]);
  const { got } = cpuFrameNormals({ clipRest, clipFaces, clipPos, vertexMap: bob.weld, meshFaces: bob.faces });
  const a = angles(got, threeNormals(exactPos, bob.faces));
  assert.ok(share(a, 5) >= 0.99, `${share(a, 5)} within 5 degrees`);
});

test('the float32 shader emulation of the ring loop over the ring texture agrees with the CPU normals', () => {
  const rings = vertexRings(bob.faces, bob.positions);
  const V = bob.weld.length;
  // a GPU numbering that is not the clip's (gpuTables numbers direct vertices first)
  const gpuIndex = Int32Array.from({ length: V }, (_, v) => (v * 7919) % V);
  assert.equal(new Set(gpuIndex).size, V);
  const values = ringTable(rings, gpuIndex);
  // most vertices are closed fans (a neighbour per triangle; seam duplicates joined), the rest pairs
  const fans = Array.from({ length: V }, (_, g) => values[2 * g + 1] > 0).filter(Boolean).length;
  assert.ok(fans > 0.9 * V, `${fans} closed fans of ${V}`);
  assert.ok(values.length < 2 * V + 0.6 * rings.pairs.length);
  const pass = new Float32Array(V * 3); // the evaluation pass's texture: float32 positions in GPU order
  for (let v = 0; v < V; v++) pass.set(exactPos.subarray(v * 3, v * 3 + 3), gpuIndex[v] * 3);
  const cpu = ringNormals(exactPos, rings);
  const want = threeNormals(exactPos, bob.faces);
  const gpu = new Float32Array(V * 3);
  for (let v = 0; v < V; v++) gpu.set(emulateRingNormal(values, pass, gpuIndex[v]), v * 3);
  assert.ok(Math.max(...angles(gpu, cpu)) < 0.05);
  assert.ok(share(angles(gpu, want), 5) >= 0.99);
});

test("hard edges (a box's split normals) keep turning with their triangle; three.js's flat faces are kept", (t) => {
  const box = new THREE.BoxGeometry(1, 1, 1, 6, 6, 6);
  const positions = Float32Array.from(box.getAttribute('position').array);
  const normals = Float32Array.from(box.getAttribute('normal').array);
  const faces = Int32Array.from(box.index.array);
  const exact = deform(positions, diagonal(positions) * 3);
  const rings = vertexRings(faces, positions);
  const map = Int32Array.from({ length: positions.length / 3 }, (_, i) => i);
  const attrs = meshAttributes({ vertexMap: map, positions, normals, index: faces, clipNormals: ringNormals(positions, rings) });
  const got = frameNormals(exact, attrs, normals, new Float32Array(normals.length), ringNormals(exact, rings));
  // three's normals of the box as it is (no merge: each face its own vertices)
  const a = angles(got, threeNormals(exact, faces, false));
  const hard = attrs.pdeVertex.filter((x, i) => i % 3 === 1 && x !== -1).length;
  assert.equal(hard, 6 * (4 * 6)); // every face's border vertices (on the box's edges)
  const isHard = (i) => attrs.pdeVertex[i * 3 + 1] !== -1;
  const hardA = a.filter((_, i) => isHard(i));
  const smoothA = a.filter((_, i) => !isHard(i));
  t.diagnostic(`hard: within 5 deg ${share(hardA, 5)}, max ${Math.max(...hardA).toFixed(2)} deg`);
  // inside the faces: three's normals; on the edges one triangle's turn against three's few-triangle mean
  assert.ok(Math.max(...smoothA) < 0.01);
  assert.ok(Math.max(...hardA) < 20, `hard vertices: max ${Math.max(...hardA)} degrees`);
});
