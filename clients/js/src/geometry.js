// Small geometry helpers: area-weighted vertex normals, the bounding-box diagonal, and the orthonormal frame
// of a triangle (the GPU path turns each vertex normal with the frame of one of its triangles).

/** Area-weighted vertex normals (V, 3) of positions (V * 3) and faces (T * 3) into out; returns out. */
export function computeNormals(positions, faces, out = new Float32Array(positions.length)) {
  out.fill(0);
  for (let f = 0; f < faces.length; f += 3) {
    const a = faces[f] * 3;
    const b = faces[f + 1] * 3;
    const c = faces[f + 2] * 3;
    const ux = positions[b] - positions[a];
    const uy = positions[b + 1] - positions[a + 1];
    const uz = positions[b + 2] - positions[a + 2];
    const vx = positions[c] - positions[a];
    const vy = positions[c + 1] - positions[a + 1];
    const vz = positions[c + 2] - positions[a + 2];
    const nx = uy * vz - uz * vy;
    const ny = uz * vx - ux * vz;
    const nz = ux * vy - uy * vx;
    for (const i of [a, b, c]) {
      out[i] += nx;
      out[i + 1] += ny;
      out[i + 2] += nz;
    }
  }
  for (let i = 0; i < out.length; i += 3) {
    const l = Math.hypot(out[i], out[i + 1], out[i + 2]);
    if (l > 0) {
      out[i] /= l;
      out[i + 1] /= l;
      out[i + 2] /= l;
    }
  }
  return out;
}

/** Length of the bounding-box diagonal of positions (V * 3). */
export function boundingBoxDiagonal(positions) {
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < positions.length; i += 3) {
    for (let w = 0; w < 3; w++) {
      lo[w] = Math.min(lo[w], positions[i + w]);
      hi[w] = Math.max(hi[w], positions[i + w]);
    }
  }
  return positions.length ? Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) : 0;
}

/**
 * Orthonormal frame of triangle (p, a, b) of positions (vertex i at pos[3i..3i+2]) into out[o..o+8], rows
 * t1, t2, n: t1 along p->a, n the triangle normal, t2 = n x t1 (the shaders build the same frame from
 * evaluated positions). Degenerate edges give zero rows instead of NaN. Allocation-free; returns out.
 */
export function triangleFrame(pos, p, a, b, out, o = 0) {
  const p3 = p * 3;
  const e1x = pos[a * 3] - pos[p3];
  const e1y = pos[a * 3 + 1] - pos[p3 + 1];
  const e1z = pos[a * 3 + 2] - pos[p3 + 2];
  const e2x = pos[b * 3] - pos[p3];
  const e2y = pos[b * 3 + 1] - pos[p3 + 1];
  const e2z = pos[b * 3 + 2] - pos[p3 + 2];
  const l1 = Math.hypot(e1x, e1y, e1z) || 1;
  const t1x = e1x / l1;
  const t1y = e1y / l1;
  const t1z = e1z / l1;
  let nx = e1y * e2z - e1z * e2y;
  let ny = e1z * e2x - e1x * e2z;
  let nz = e1x * e2y - e1y * e2x;
  const ln = Math.hypot(nx, ny, nz) || 1;
  nx /= ln;
  ny /= ln;
  nz /= ln;
  out[o] = t1x;
  out[o + 1] = t1y;
  out[o + 2] = t1z;
  out[o + 3] = ny * t1z - nz * t1y;
  out[o + 4] = nz * t1x - nx * t1z;
  out[o + 5] = nx * t1y - ny * t1x;
  out[o + 6] = nx;
  out[o + 7] = ny;
  out[o + 8] = nz;
  return out;
}

/** Shape quality of triangle (p, a, b): |e1 x e2| / (|e1|^2 + |e2|^2), 0 when degenerate. */
export function triangleQuality(pos, p, a, b) {
  const p3 = p * 3;
  const e1x = pos[a * 3] - pos[p3];
  const e1y = pos[a * 3 + 1] - pos[p3 + 1];
  const e1z = pos[a * 3 + 2] - pos[p3 + 2];
  const e2x = pos[b * 3] - pos[p3];
  const e2y = pos[b * 3 + 1] - pos[p3 + 1];
  const e2z = pos[b * 3 + 2] - pos[p3 + 2];
  const cx = e1y * e2z - e1z * e2y;
  const cy = e1z * e2x - e1x * e2z;
  const cz = e1x * e2y - e1y * e2x;
  const den = e1x * e1x + e1y * e1y + e1z * e1z + e2x * e2x + e2y * e2y + e2z * e2z;
  return den > 0 ? Math.hypot(cx, cy, cz) / den : 0;
}

/**
 * The one-ring of every vertex for area-weighted normals: for vertex v, the pairs (a, b) of its incident
 * triangles (p, a, b), in winding order, so that the sum of cross(a - p, b - p) is three.js's
 * computeVertexNormals. Vertices at the same rest position (seam duplicates, rest V * 3) share one ring: each
 * lists the triangles of all of them, so that they get one normal as a smooth-shaded source gives them.
 * Returns {offset (Int32Array V + 1), pairs (Int32Array, 2 per triangle corner), group (Int32Array V: the
 * first vertex at each vertex's rest position)}: v's pairs are pairs[2 * offset[v] .. 2 * offset[v + 1]).
 */
export function vertexRings(faces, rest) {
  const V = rest.length / 3;
  const group = new Int32Array(V); // the first vertex at the same rest position
  const seen = new Map();
  for (let v = 0; v < V; v++) {
    const key = `${rest[v * 3]},${rest[v * 3 + 1]},${rest[v * 3 + 2]}`;
    const g = seen.get(key);
    if (g === undefined) seen.set(key, v);
    group[v] = g ?? v;
  }
  const per = new Int32Array(V); // corners per group
  for (let k = 0; k < faces.length; k++) per[group[faces[k]]]++;
  const start = new Int32Array(V + 1);
  for (let v = 0; v < V; v++) start[v + 1] = start[v] + per[v];
  const fill = start.slice(0, V);
  const groupPairs = new Int32Array(start[V] * 2);
  for (let f = 0; f < faces.length; f += 3) {
    for (let r = 0; r < 3; r++) {
      const o = fill[group[faces[f + r]]]++ * 2;
      groupPairs[o] = faces[f + ((r + 1) % 3)];
      groupPairs[o + 1] = faces[f + ((r + 2) % 3)];
    }
  }
  // every vertex gets its group's pairs (a copy per duplicate: the GPU reads one contiguous list)
  const offset = new Int32Array(V + 1);
  for (let v = 0; v < V; v++) offset[v + 1] = offset[v] + per[group[v]];
  const pairs = new Int32Array(offset[V] * 2);
  for (let v = 0; v < V; v++) {
    const g = group[v];
    pairs.set(groupPairs.subarray(start[g] * 2, start[g + 1] * 2), offset[v] * 2);
  }
  return { offset, pairs, group };
}

/**
 * Unit area-weighted normals (V * 3) of positions (V * 3) over vertexRings(): per vertex the sum of
 * cross(a - p, b - p) over its ring, normalised (zero when the sum is); only those of vertices (a list of
 * vertex numbers; null: all). Allocation-free; returns out.
 */
export function ringNormals(positions, { offset, pairs }, out = new Float32Array(positions.length), vertices = null) {
  const n = vertices ? vertices.length : offset.length - 1;
  for (let i = 0; i < n; i++) {
    const v = vertices ? vertices[i] : i;
    const px = positions[v * 3];
    const py = positions[v * 3 + 1];
    const pz = positions[v * 3 + 2];
    let nx = 0;
    let ny = 0;
    let nz = 0;
    for (let j = offset[v] * 2; j < offset[v + 1] * 2; j += 2) {
      const a = pairs[j] * 3;
      const b = pairs[j + 1] * 3;
      const ux = positions[a] - px;
      const uy = positions[a + 1] - py;
      const uz = positions[a + 2] - pz;
      const wx = positions[b] - px;
      const wy = positions[b + 1] - py;
      const wz = positions[b + 2] - pz;
      nx += uy * wz - uz * wy;
      ny += uz * wx - ux * wz;
      nz += ux * wy - uy * wx;
    }
    const l = Math.hypot(nx, ny, nz);
    out[v * 3] = l > 0 ? nx / l : 0;
    out[v * 3 + 1] = l > 0 ? ny / l : 0;
    out[v * 3 + 2] = l > 0 ? nz / l : 0;
  }
  return out;
}
