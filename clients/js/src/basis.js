// The balanced space basis and time pairs of the dynamic-PDE families (docs/format.md §3.3-3.4).

export const D_SWITCH = 4.0;
export const MU_TRIG_MAX = 0.95 * Math.PI;
const SMALL_SCALE = [1, 2, 4, 24];
const SQRT2 = Math.SQRT2;

function factorial(n) {
  let f = 1;
  for (let i = 2; i <= n; i++) f *= i;
  return f;
}

/** Taylor coefficients (degree 0..n) of cosh, sinh, cos or sin. */
function taylor(kind, n = 24) {
  const out = new Float64Array(n + 1);
  for (let k = 0; k <= n; k++) {
    const even = k % 2 === 0;
    const sign = Math.floor(k / 2) % 2 === 0 ? 1 : -1;
    const f = factorial(k);
    if (kind === 'cosh') out[k] = even ? 1 / f : 0;
    else if (kind === 'sinh') out[k] = even ? 0 : 1 / f;
    else if (kind === 'cos') out[k] = even ? sign / f : 0;
    else out[k] = even ? 0 : sign / f;
  }
  return out;
}

function polymulTrunc(a, b) {
  const out = new Float64Array(a.length);
  for (let i = 0; i < a.length; i++) for (let j = 0; i + j < a.length; j++) out[i + j] += a[i] * b[j];
  return out;
}

const SMS = (() => {
  // series of (sinh x - sin x) / x^3
  const a = taylor('sinh');
  const b = taylor('sin');
  return a.map((v, i) => v - b[i]).slice(3);
})();
const CSC = (() => {
  // series of (cosh x sin x - sinh x cos x) / x^3
  const a = polymulTrunc(taylor('cosh'), taylor('sin'));
  const b = polymulTrunc(taylor('sinh'), taylor('cos'));
  return a.map((v, i) => v - b[i]).slice(3);
})();

function polyval(c, x) {
  let r = 0;
  for (let i = c.length - 1; i >= 0; i--) r = r * x + c[i];
  return r;
}

/** sinh(y) / y, 1 at 0 (series below |y| < 1e-4). */
function shc(y) {
  return Math.abs(y) < 1e-4 ? 1 + (y * y) / 6 : Math.sinh(y) / y;
}

/** sin(y) / y, 1 at 0 (series below |y| < 1e-4). */
function sc(y) {
  return Math.abs(y) < 1e-4 ? 1 - (y * y) / 6 : Math.sin(y) / y;
}

function ratio3(x, coeffs, fx) {
  return Math.abs(x) < 0.5 ? polyval(coeffs, x) : fx / (x * x * x);
}

/**
 * The four balanced space functions at curve parameter u for constant D and space kind (0 = D0, 1 = D1),
 * written into out[o..o+3] (float64 math).
 */
export function spaceBasis(u, Din, kind, out, o = 0) {
  const D = Math.abs(Din);
  const s = u - 0.5;
  if (D < D_SWITCH) {
    if (kind === 0) {
      const x = D * s;
      const sh = Math.sinh(x);
      const sn = Math.sin(x);
      out[o] = 0.5 * (Math.cosh(x) + Math.cos(x)) * SMALL_SCALE[0];
      out[o + 1] = 0.5 * s * (shc(x) + sc(x)) * SMALL_SCALE[1];
      const h = shc(0.5 * x);
      const hs = sc(0.5 * x);
      out[o + 2] = 0.5 * s * s * (h * h + hs * hs) * SMALL_SCALE[2];
      out[o + 3] = s * s * s * ratio3(x, SMS, sh - sn) * SMALL_SCALE[3];
    } else {
      const x = (D / SQRT2) * s;
      const ch = Math.cosh(x);
      const c = Math.cos(x);
      const sh = Math.sinh(x);
      const sn = Math.sin(x);
      const shcx = shc(x);
      const scx = sc(x);
      out[o] = ch * c * SMALL_SCALE[0];
      out[o + 1] = 0.5 * s * (ch * scx + shcx * c) * SMALL_SCALE[1];
      out[o + 2] = s * s * shcx * scx * SMALL_SCALE[2];
      out[o + 3] = 0.5 * (s * s * s) * ratio3(x, CSC, ch * sn - sh * c) * SMALL_SCALE[3];
    }
    return out;
  }
  if (kind === 0) {
    out[o] = Math.exp(-D * u);
    out[o + 1] = Math.exp(D * (u - 1));
    out[o + 2] = Math.cos(D * s);
    out[o + 3] = Math.sin(D * s);
  } else {
    const a = D / SQRT2;
    const lo = Math.exp(-a * u);
    const hi = Math.exp(a * (u - 1));
    const c = Math.cos(a * s);
    const sn = Math.sin(a * s);
    out[o] = lo * c;
    out[o + 1] = lo * sn;
    out[o + 2] = hi * c;
    out[o + 3] = hi * sn;
  }
  return out;
}

/**
 * The end-interpolating time pair at local time tau for a signed constant mu (> 0 exp, < 0 trig, else
 * linear), as stored by the dynamic-PDE coefficients: writes phi0 to out[o], phi1 to out[o + 1].
 */
export function timePair(tau, mu, out, o = 0) {
  if (mu > 1e-12) {
    const inv = 1 / Math.expm1(-2 * mu);
    out[o] = Math.exp(-mu * tau) * Math.expm1(-2 * mu * (1 - tau)) * inv;
    out[o + 1] = Math.exp(mu * (tau - 1)) * Math.expm1(-2 * mu * tau) * inv;
  } else if (mu < -1e-12) {
    const m = Math.min(-mu, MU_TRIG_MAX);
    const inv = 1 / Math.sin(m);
    out[o] = Math.sin(m * (1 - tau)) * inv;
    out[o + 1] = Math.sin(m * tau) * inv;
  } else {
    out[o] = 1 - tau;
    out[o + 1] = tau;
  }
  return out;
}

/** Time pair of the rigid tracks (docs/format.md §3.6): like timePair, any mu < 0 is trig. */
export function rigidTimePair(tau, mu, out, o = 0) {
  if (mu < 0) {
    const m = Math.min(Math.max(-mu, 1e-150), MU_TRIG_MAX);
    const inv = 1 / Math.sin(m);
    out[o] = Math.sin(m * (1 - tau)) * inv;
    out[o + 1] = Math.sin(m * tau) * inv;
  } else if (mu < 1e-12) {
    out[o] = 1 - tau;
    out[o + 1] = tau;
  } else {
    const inv = 1 / Math.expm1(-2 * mu);
    out[o] = Math.exp(-mu * tau) * Math.expm1(-2 * mu * (1 - tau)) * inv;
    out[o + 1] = Math.exp(mu * (tau - 1)) * Math.expm1(-2 * mu * tau) * inv;
  }
  return out;
}

/**
 * Segment index and local time of t on boundaries bounds (S+1,): looping clips wrap t into [0, 1),
 * others clamp it; returns [segment, tau, wrapped t] (written into out when given: no allocation).
 */
export function locate(bounds, t, looping, out = [0, 0, 0]) {
  const tw = looping ? t - Math.floor(t) : Math.min(Math.max(t, 0), 1);
  const S = bounds.length - 1;
  let lo = 0;
  let hi = bounds.length; // bisect right: first index with bounds[i] > tw
  while (lo < hi) {
    const mid = (lo + hi) >> 1;
    if (tw < bounds[mid]) hi = mid;
    else lo = mid + 1;
  }
  const seg = Math.min(Math.max(lo - 1, 0), S - 1);
  const t0 = bounds[seg];
  const t1 = bounds[seg + 1];
  const tau = Math.min(Math.max((tw - t0) / (t1 > t0 ? t1 - t0 : 1), 0), 1);
  out[0] = seg;
  out[1] = tau;
  out[2] = tw;
  return out;
}
