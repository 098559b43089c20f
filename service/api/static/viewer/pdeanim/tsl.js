// The clip evaluation of glsl.js in TSL (three.js's node shading language), for WebGPURenderer on either of
// its backends (WebGPU, and its WebGL 2 fallback): the same data textures (gpu.js), the same math, one clip
// vertex evaluated from the vertex texture and the per-frame table, the mesh vertex placed and its normal
// turned (area-weighted ring normals, or the frame of a triangle). Each function mirrors its GLSL namesake.

import * as TSL from 'three/tsl';

/** The TSL functions this module uses (three.js r187's three/tsl; checkTSL names any that is missing). */
const NEEDED = [
  'Fn', 'If', 'Loop', 'attribute', 'cross', 'dot', 'float', 'int', 'ivec2', 'mix', 'normalGeometry',
  'normalLocal', 'normalize', 'positionLocal', 'reference', 'referenceAttribute', 'select', 'sqrt', 'texture',
  'transformNormal', 'uniform', 'vec2', 'vec3', 'vec4',
];

/** Throw naming what three/tsl lacks when the installed three.js is older than the node materials need. */
export function checkTSL() {
  const missing = NEEDED.filter((k) => typeof TSL[k] !== 'function' && typeof TSL[k] !== 'object');
  if (missing.length) {
    throw new Error(`pdeanim/webgpu needs three.js's node materials as in r187: three/tsl has no ${missing.join(', ')}`);
  }
}

const {
  Fn,
  If,
  Loop,
  attribute,
  cross,
  dot,
  float,
  int,
  ivec2,
  mix,
  normalGeometry,
  normalLocal,
  normalize,
  positionLocal,
  reference,
  referenceAttribute,
  select,
  sqrt,
  texture,
  transformNormal,
  uniform,
  vec2,
  vec3,
  vec4,
} = TSL;

const XYZW = ['x', 'y', 'z', 'w'];

/**
 * The evaluation functions of a layout (GPU numbering and texel layout of gpu.js): {evaluate(v), fetch},
 * building TSL nodes inside a Fn (evaluate calls one shader function). nodes: {vertex, frame, ring} TextureNodes (frame null for cyclic
 * clips without slots), sinWt / cosWt float nodes (cyclic), frameBase an int node (a crowd instance's slot's
 * first texel; 0 otherwise). The clip's constants (numbering, texel counts, axis, bend) are baked in.
 */
function evaluation(layout, nodes) {
  const shift = Math.log2(layout.width);
  const mask = layout.width - 1;
  // texel i of a data texture (rows of layout.width texels)
  const fetch = (tex, i) => tex.load(ivec2(i.bitAnd(mask), i.shiftRight(shift))).setUpdateMatrix(false);
  let base = null; // the function's frame-base parameter while its body is built
  const frame = (i) => fetch(nodes.frame, i.add(base));
  const make = layout.kind === 'cyclic-spine' ? cyclicEvaluate : dynamicEvaluate;
  const body = make(layout, nodes, fetch, frame);
  // one shader function (called for the vertex and each ring neighbour), not the body inlined at every call
  const fn = Fn(
    ([v, b]) => {
      base = b;
      return body(v);
    },
    // a fixed name: players of one clip generate the same shader code (three.js shares its pipelines)
    {
      name: 'pdeanimEval',
      type: 'vec3',
      inputs: [
        { name: 'v', type: 'int' },
        { name: 'frameBase', type: 'int' },
      ],
    },
  );
  return { evaluate: (v) => fn(v, nodes.frameBase), fetch };
}

/** glsl.js's CYCLIC_EVAL: the swim of a cyclic-spine clip's vertex v at the phase (sin, cos) of its time. */
function cyclicEvaluate(layout, nodes, fetch, frame) {
  return (v) => {
    const a = fetch(nodes.vertex, v.mul(3)).toVar();
    const w = fetch(nodes.vertex, v.mul(3).add(1)).toVar();
    const rl = fetch(nodes.vertex, v.mul(3).add(2)).x;
    const phase = nodes.slots ? frame(int(0)).xy.toVar() : vec2(nodes.sinWt, nodes.cosWt).toVar();
    const ca = float(0).toVar();
    const cl = w.x.mul(phase.x).add(w.y.mul(phase.y)).toVar();
    if (layout.rotate) {
      const g = w.z.mul(phase.x).add(w.w.mul(phase.y)).toVar();
      const c = float(1).div(sqrt(g.mul(g).add(1))).toVar();
      const sn = g.mul(c).toVar();
      ca.assign(c.sub(1).mul(a.w).sub(sn.mul(rl)));
      cl.addAssign(sn.mul(a.w).add(c.sub(1).mul(rl)));
    }
    return a.xyz.add(ca.mul(vec3(...layout.axis))).add(cl.mul(vec3(...layout.bend)));
  };
}

/**
 * glsl.js's DYNAMIC_EVAL: a direct vertex's position from the per-frame table, else base (bones: the rest
 * position skinned) + the curve's frame coefficients . the vertex's basis rows, then the curve's rigid
 * motion; with bones, the vertices from skinOnly on are their skinned rest position alone.
 */
function dynamicEvaluate(layout, nodes, fetch, frame) {
  const VT = layout.vertexTexels ?? 4;
  const CT = layout.curveTexels;
  const nDirect = layout.nDirect;
  // the rest position skinned by the bone rows at the end of the per-frame table (vertex texels r, r + 1:
  // bone indices, normalised weights)
  const skin = (r, rest) => {
    const index = fetch(nodes.vertex, r).toVar();
    const weight = fetch(nodes.vertex, r.add(1)).toVar();
    const x = vec4(rest, 1).toVar();
    const acc = vec3(0).toVar();
    for (const k of XYZW) {
      If(weight[k].notEqual(0), () => {
        const b = int(layout.boneTexel).add(int(index[k].add(0.5)).mul(3)).toVar();
        acc.addAssign(vec3(dot(frame(b), x), dot(frame(b.add(1)), x), dot(frame(b.add(2)), x)).mul(weight[k]));
      });
    }
    return acc;
  };
  const residual = (v, p) => {
    const r = v.sub(nDirect).mul(VT).toVar();
    const head = fetch(nodes.vertex, r).toVar();
    const q = head.yzw.toVar();
    if (layout.bones) q.assign(skin(r.add(VT - 2), q));
    const c = int(nDirect).add(int(head.x.add(0.5)).mul(CT)).toVar();
    q.addAssign(
      vec3(
        dot(frame(c), fetch(nodes.vertex, r.add(1))),
        dot(frame(c.add(1)), fetch(nodes.vertex, r.add(2))),
        dot(frame(c.add(2)), fetch(nodes.vertex, r.add(3))),
      ),
    );
    if (layout.rigid) {
      const ct = layout.coefficientTexels;
      const r0 = frame(c.add(ct)).toVar();
      const r1 = frame(c.add(ct + 1)).toVar();
      const r2 = frame(c.add(ct + 2)).toVar();
      q.assign(vec3(dot(r0.xyz, q).add(r0.w), dot(r1.xyz, q).add(r1.w), dot(r2.xyz, q).add(r2.w)));
    }
    p.assign(q);
  };
  return (v) => {
    const p = vec3(0).toVar();
    If(v.lessThan(nDirect), () => {
      p.assign(frame(v).xyz);
    }).Else(() => {
      if (layout.bones && layout.skinOnly < layout.nVertices) {
        If(v.greaterThanEqual(layout.skinOnly), () => {
          const s = int(layout.skinTexel).add(v.sub(layout.skinOnly).mul(3)).toVar();
          p.assign(skin(s.add(1), fetch(nodes.vertex, s).yzw));
        }).Else(() => residual(v, p));
      } else {
        residual(v, p);
      }
    });
    return p;
  };
}

/** Value i of the ring table (four a texel). */
function ringValue(fetch, ring, i) {
  const t = fetch(ring, i.shiftRight(2)).toVar();
  const c = i.bitAnd(3);
  return select(c.equal(0), t.x, select(c.equal(1), t.y, select(c.equal(2), t.z, t.w)));
}

/** The area-weighted normal (unnormalised) of GPU vertex v at p from its ring (gpu.js ringTable). */
function ringNormal(at, fetch, ring, v, p) {
  const value = (i) => ringValue(fetch, ring, i);
  const ringAt = (i) => at(int(value(i).add(0.5))).sub(p);
  const first = int(value(v.mul(2)).add(0.5)).toVar();
  const count = int(value(v.mul(2).add(1))).toVar();
  const n = vec3(0).toVar();
  If(count.greaterThan(0), () => {
    // a closed fan: triangles (v, n_k, n_k+1)
    const e0 = ringAt(first).toVar();
    const ea = vec3(e0).toVar();
    Loop({ start: int(1), end: count, type: 'int', condition: '<' }, ({ i }) => {
      const eb = ringAt(first.add(i)).toVar();
      n.addAssign(cross(ea, eb));
      ea.assign(eb);
    });
    n.addAssign(cross(ea, e0));
  }).Else(() => {
    // -count triangles' (a, b) pairs
    Loop({ start: int(0), end: count.negate(), type: 'int', condition: '<' }, ({ i }) => {
      const k = first.add(i.mul(2)).toVar();
      n.addAssign(cross(ringAt(k), ringAt(k.add(1))));
    });
  });
  return n;
}

/**
 * The uniform-like inputs of a player's node material: TSL nodes reading the player's {value} uniforms each
 * frame (so that influence, the mixer's weight and the per-frame tables stay the player's), the data texture
 * nodes and the matrices.
 */
function playerNodes(player) {
  const u = player.uniforms;
  const L = player.layout;
  const slots = Boolean(player.slots);
  // the clip's weight in the mix: 0 when disabled (detached, influence 0)
  const weight = {
    get value() {
      return u.pdeEnabled.value ? u.pdeInfluence.value : 0;
    },
  };
  const frameTex = player.frames.texture;
  return {
    weight: reference('value', 'float', weight),
    vertex: texture(u.pdeVertexTex.value),
    ring: u.pdeRingTex.value ? texture(u.pdeRingTex.value) : null,
    frame: frameTex ? texture(frameTex) : null,
    sinWt: reference('value', 'float', u.pdeSinWt),
    cosWt: reference('value', 'float', u.pdeCosWt),
    slots,
    frameBase: slots ? int(attribute('pdeSlot', 'float').add(0.5)).mul(player.frames.stride) : int(0),
    clipToLocal: uniform(player.clipToLocal),
    normalToLocal: uniform(player.normalToLocal),
    layout: L,
  };
}

/**
 * The clip's vertex (evaluated here, or the CPU's attributes) in the mesh's frame into position and, with
 * normals, its normal into normal (left as is where the vertex keeps its own): glsl.js's pdeCompute.
 */
function clipVertex(player, nodes, position, normal) {
  const L = nodes.layout;
  if (!player.gpu) {
    // the CPU evaluated this vertex (positions and normals in the mesh's frame)
    position.assign(attribute('pdeCpuPosition', 'vec3'));
    if (normal) normal.assign(attribute('pdeCpuNormal', 'vec3'));
    return;
  }
  const ev = evaluation(L, nodes);
  const pdeVertex = attribute('pdeVertex', 'vec3').toVar();
  const v = int(pdeVertex.x.add(0.5)).toVar();
  const p = ev.evaluate(v).toVar();
  position.assign(nodes.clipToLocal.mul(vec4(p, 1)).xyz);
  if (!normal || player.normals !== 'frame') return;
  const va = int(pdeVertex.y.add(0.5)).toVar();
  const vb = int(pdeVertex.z.add(0.5)).toVar();
  If(pdeVertex.y.lessThan(-0.5), () => {
    const n = ringNormal(ev.evaluate, ev.fetch, nodes.ring, v, p).toVar();
    If(dot(n, n).greaterThan(0), () => {
      normal.assign(normalize(nodes.normalToLocal.mul(n)));
    });
  }).ElseIf(va.notEqual(v), () => {
    const f = attribute('pdeNormalFrame', 'vec3').toVar();
    const e1 = ev.evaluate(va).sub(p).toVar();
    const e2 = ev.evaluate(vb).sub(p).toVar();
    const t1 = normalize(e1).toVar();
    const n = normalize(cross(e1, e2)).toVar();
    const turned = t1.mul(f.x).add(cross(n, t1).mul(f.y)).add(n.mul(f.z));
    normal.assign(normalize(nodes.normalToLocal.mul(turned)));
  });
}

/**
 * Play the clip in the vertex stage being built (called from a node material's setupPosition, after three.js
 * morphed, skinned and instanced positionLocal and normalLocal and applied the material's own positionNode,
 * as skinning() does): positionLocal and normalLocal mixed with the clip's vertex and normal by the player's
 * weight (glsl.js's patchVertexShader). An InstancedMesh's instance matrix is applied to the clip's vertex and
 * normal too.
 */
export function playClip(player, { instanced = false } = {}) {
  const nodes = playerNodes(player);
  // the mesh's side (initialises positionLocal and normalLocal in this scope, not in the branch below)
  const meshPosition = vec3(positionLocal).toVar();
  const meshNormal = vec3(normalLocal).toVar();
  If(nodes.weight.greaterThan(0), () => {
    const position = vec3(0).toVar();
    const normal = vec3(normalGeometry).toVar();
    clipVertex(player, nodes, position, normal);
    if (instanced) placeInstance(position, normal);
    positionLocal.assign(mix(meshPosition, position, nodes.weight));
    normalLocal.assign(normalize(mix(meshNormal, normal, nodes.weight)));
  });
}

/** The instance's matrix (three.js's instancedMesh() applied it to the mesh's side) on position and normal. */
function placeInstance(position, normal) {
  const m = referenceAttribute('instanceMatrix', 'mat4');
  position.assign(m.mul(vec4(position, 1)).xyz);
  if (normal) normal.assign(transformNormal(normal, m));
}

/**
 * The positions alone as a positionNode (what WebGPURenderer's shadow pass draws with: castShadowPositionNode):
 * the clip's vertex mixed with positionLocal by the player's weight.
 */
export function shadowPositionNode(player, { instanced = false } = {}) {
  const nodes = playerNodes(player);
  return Fn(() => {
    const out = vec3(positionLocal).toVar();
    If(nodes.weight.greaterThan(0), () => {
      const position = vec3(0).toVar();
      clipVertex(player, nodes, position, null);
      if (instanced) placeInstance(position, null);
      out.assign(mix(out, position, nodes.weight));
    });
    return out;
  })();
}
