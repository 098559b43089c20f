// Decode and evaluate "cyclic-spine" clips (docs/format.md §4) on the CPU.

import { ClipFormatError, checkBounded, checkFormatVersion } from './container.js';

const WAVES = ['standing', 'travelling'];
const RADIAL = ['rotate', 'translate'];
const DIRECTIONS = ['lateral', 'vertical'];
const SWIM_NUMBERS = ['omega0', 'omega1', 'alpha', 'phi', 'frequency', 'amplitude'];

function vec3(x, what) {
  if (!Array.isArray(x) || x.length !== 3 || !x.every(Number.isFinite)) {
    throw new ClipFormatError(`bad cyclic-spine clip header: ${what} must be three finite numbers`);
  }
  return x.map(Number);
}

function swimParams(d) {
  if (!d || typeof d !== 'object')
    throw new ClipFormatError('bad cyclic-spine clip header: no swim parameters');
  const p = {
    mode: 'eel',
    omega0: 0,
    omega1: 0.3,
    alpha: 1.5,
    phi: Math.PI / 2,
    frequency: 1,
    amplitude: 0.08,
    wave: 'standing',
    radial: 'rotate',
    direction: 'lateral',
  };
  for (const [k, v] of Object.entries(d)) {
    if (!(k in p)) throw new ClipFormatError(`bad cyclic-spine clip header: unknown swim parameter ${k}`);
    p[k] = SWIM_NUMBERS.includes(k) ? Number(v) : String(v);
  }
  if (
    !SWIM_NUMBERS.every((k) => Number.isFinite(p[k])) ||
    !(p.frequency >= 1e-3 && p.frequency <= 1e3) ||
    !(p.amplitude >= 0 && p.amplitude <= 1) ||
    !WAVES.includes(p.wave) ||
    !RADIAL.includes(p.radial) ||
    !DIRECTIONS.includes(p.direction)
  ) {
    throw new ClipFormatError('bad cyclic-spine clip header: invalid swim parameters');
  }
  return p;
}

/** The body frame of a cyclic-spine topology header (origin, axis, lateral, up, x range). */
function bodyFrame(f) {
  if (!f || typeof f !== 'object') throw new ClipFormatError('bad cyclic-spine clip header: no body frame');
  const frame = {
    origin: vec3(f.origin, 'frame.origin'),
    axis: vec3(f.axis, 'frame.axis'),
    lateral: vec3(f.lateral, 'frame.lateral'),
    up: vec3(f.up, 'frame.up'),
    xMin: Number(f.x_min),
    xMax: Number(f.x_max),
  };
  if (!Number.isFinite(frame.xMin) || !Number.isFinite(frame.xMax)) {
    throw new ClipFormatError('bad cyclic-spine clip header: frame.x_min/x_max must be numbers');
  }
  return frame;
}

/** Validate and decode the topology and coefficients containers of a cyclic-spine clip. */
export function decodeCyclic(topo, coef) {
  checkFormatVersion(topo.header, 'topology');
  checkFormatVersion(coef.header, 'coefficients');
  if ((coef.header.required ?? []).includes('bones')) {
    throw new ClipFormatError('the bone layer (required "bones") is only defined for dynamic-pde clips');
  }
  const ta = topo.arrays;
  const ca = coef.arrays;
  const missing = ['faces', 'rest', 'vertex_patch', 'vertex_uv'].filter((n) => !ta[n]);
  if (missing.length)
    throw new ClipFormatError(`cyclic-spine topology part lacks arrays: ${missing.join(', ')}`);
  if (!ca.spine) throw new ClipFormatError('cyclic-spine coefficients part lacks arrays: spine');
  const frame = bodyFrame(topo.header.frame);
  const swim = swimParams(coef.header.swim);
  const frames = Number(coef.header.frames ?? 24);
  const spine = ca.spine;
  const rest = ta.rest;
  const patch = ta.vertex_patch;
  const uv = ta.vertex_uv;
  const V = rest.shape[0];
  const Bn = spine.shape[0];
  const bad =
    spine.shape.length !== 3 ||
    spine.shape[2] !== 3 ||
    rest.shape.length !== 2 ||
    rest.shape[1] !== 3 ||
    patch.data.length !== V ||
    uv.shape[0] !== V ||
    uv.shape[1] !== 2 ||
    !Number.isInteger(frames) ||
    frames < 1 ||
    patch.data.some((p) => p < 0 || p >= Bn);
  if (bad) throw new ClipFormatError('cyclic-spine clip arrays do not fit together');
  const faces = ta.faces;
  if (faces.shape.length !== 2 || faces.shape[1] !== 3 || faces.data.some((i) => i < 0 || i >= V)) {
    throw new ClipFormatError('cyclic-spine faces must be (T, 3) indices of the vertices');
  }
  checkBounded(rest.data, 'cyclic-spine rest');
  checkBounded(spine.data, 'cyclic-spine spine');
  const period = 1 / swim.frequency;
  const frameTimes = new Float64Array(frames + 1).map((_, i) => i * (period / frames));
  return {
    kind: 'cyclic-spine',
    nVertices: V,
    faces: faces.data,
    rest: rest.data,
    patch: patch.data,
    uv: uv.data,
    spine: spine.data,
    nPatches: Bn,
    order: spine.shape[1],
    frame,
    swim,
    period,
    frames,
    frameTimes,
    looping: true,
    header: coef.header,
    topologyHeader: topo.header,
  };
}

/** Spine point (deriv 0) or its s-derivative (deriv 1) at chain parameter s into out[0..2]. */
function spineAt(clip, s, deriv, out) {
  const B = clip.nPatches;
  const N = clip.order;
  const x = Math.min(Math.max(s, 0), 1) * B;
  const b = Math.min(Math.floor(x), B - 1);
  const u = x - b;
  out[0] = 0;
  out[1] = 0;
  out[2] = 0;
  for (let k = deriv; k < N; k++) {
    const w = deriv ? k * u ** (k - 1) * B : u ** k;
    const o = (b * N + k) * 3;
    out[0] += w * clip.spine[o];
    out[1] += w * clip.spine[o + 1];
    out[2] += w * clip.spine[o + 2];
  }
  return out;
}

/** Peak of |Omega(U) cos(alpha U + phi)| on 2049 samples: the normaliser of the wave amplitude. */
function wavePeak(p) {
  let peak = 0;
  for (let i = 0; i <= 2048; i++) {
    const s = i / 2048;
    const shape =
      (p.omega0 + p.omega1 * s) * (p.wave === 'standing' ? Math.cos(2 * Math.PI * p.alpha * s + p.phi) : 1);
    peak = Math.max(peak, Math.abs(shape));
  }
  return peak;
}

/** CPU evaluator of a decoded cyclic-spine clip (t in cycles; one cycle per unit of t). */
export class CyclicEvaluator {
  constructor(clip) {
    this.clip = clip;
    const V = (this.nVertices = clip.nVertices);
    const { frame, swim: p } = clip;
    const bend = p.direction === 'vertical' ? frame.up : frame.lateral;
    const axis = frame.axis;
    const length = frame.xMax - frame.xMin;
    const peak = wavePeak(p);
    const gain = peak > 0 ? (p.amplitude * length) / peak : 0;
    const k = 2 * Math.PI * p.alpha;
    // per vertex: the coefficients of sin(wt) and cos(wt) in the wave (delta) and its slope,
    // and the spine-relative offset along the axis and the bend direction
    this.dS = new Float64Array(V);
    this.dC = new Float64Array(V);
    this.gS = new Float64Array(V);
    this.gC = new Float64Array(V);
    this.ra = new Float64Array(V);
    this.rl = new Float64Array(V);
    const pt = [0, 0, 0];
    const dp = [0, 0, 0];
    for (let v = 0; v < V; v++) {
      const s = (clip.patch[v] + clip.uv[v * 2]) / clip.nPatches;
      spineAt(clip, s, 0, pt);
      spineAt(clip, s, 1, dp);
      const rel = [0, 1, 2].map((w) => clip.rest[v * 3 + w] - pt[w]);
      this.ra[v] = rel[0] * axis[0] + rel[1] * axis[1] + rel[2] * axis[2];
      this.rl[v] = rel[0] * bend[0] + rel[1] * bend[1] + rel[2] * bend[2];
      const dxds = Math.max(dp[0] * axis[0] + dp[1] * axis[1] + dp[2] * axis[2], 0.1 * length);
      const amp = p.omega0 + p.omega1 * s;
      if (p.wave === 'standing') {
        const space = Math.cos(k * s + p.phi);
        const dspace = -k * Math.sin(k * s + p.phi);
        this.dS[v] = gain * amp * space;
        this.gS[v] = (gain * (p.omega1 * space + amp * dspace)) / dxds;
      } else {
        // sin(wt - a) = sin wt cos a - cos wt sin a, a = k s + phi
        const ca = Math.cos(k * s + p.phi);
        const sa = Math.sin(k * s + p.phi);
        this.dS[v] = gain * amp * ca;
        this.dC[v] = -gain * amp * sa;
        // slope = omega1 sin(wt - a) - amp k cos(wt - a)
        this.gS[v] = (gain * (p.omega1 * ca - amp * k * sa)) / dxds;
        this.gC[v] = (gain * (-p.omega1 * sa - amp * k * ca)) / dxds;
      }
    }
    this.axis = axis;
    this.bend = bend;
    this.rotate = p.radial === 'rotate';
  }

  /** Positions (V, 3) at t into out (Float32Array of V * 3, original vertex order); returns out. */
  evaluate(t, out = new Float32Array(this.nVertices * 3)) {
    if (!Number.isFinite(t)) throw new RangeError(`clip time must be a finite number, got ${t}`);
    if (out.length < this.nVertices * 3) throw new RangeError(`output needs ${this.nVertices * 3} floats`);
    const p = this.clip.swim;
    const wt = 2 * Math.PI * p.frequency * (t * this.clip.period);
    const sw = Math.sin(wt);
    const cw = Math.cos(wt);
    const { dS, dC, gS, gC, ra, rl, axis, bend, rotate } = this;
    const rest = this.clip.rest;
    for (let v = 0, i = 0; v < this.nVertices; v++, i += 3) {
      const delta = dS[v] * sw + dC[v] * cw;
      let ca = 0;
      let cl = delta;
      if (rotate) {
        const g = gS[v] * sw + gC[v] * cw;
        const c = 1 / Math.sqrt(1 + g * g);
        const sn = g * c;
        ca = (c - 1) * ra[v] - sn * rl[v];
        cl += sn * ra[v] + (c - 1) * rl[v];
      }
      out[i] = rest[i] + ca * axis[0] + cl * bend[0];
      out[i + 1] = rest[i + 1] + ca * axis[1] + cl * bend[1];
      out[i + 2] = rest[i + 2] + ca * axis[2] + cl * bend[2];
    }
    return out;
  }
}
