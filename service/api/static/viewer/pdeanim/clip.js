// Clips: the two parts (topology + coefficients), the CLIP file, fetching, and the evaluator factory.

import { ClipFormatError, checkFormatVersion, decodeContainer } from './container.js';
import { CyclicEvaluator, decodeCyclic } from './cyclic.js';
import { DynamicEvaluator, decodeDynamic } from './dynamic.js';
import { WindowedEvaluator, decodeWindowedClip } from './stream.js';
import { isStreamHeader } from './streamformat.js';

const KINDS = {
  'dynamic-pde': [decodeDynamic, DynamicEvaluator],
  'cyclic-spine': [decodeCyclic, CyclicEvaluator],
};

function bytesOf(data) {
  if (data instanceof ArrayBuffer) return new Uint8Array(data);
  if (ArrayBuffer.isView(data)) return new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  throw new ClipFormatError('expected an ArrayBuffer or a typed array');
}

/**
 * Decode a clip from its topology and coefficients part (ArrayBuffers or typed arrays). Synchronous; does
 * not check the topology_id hash (use loadClip for that).
 */
export function decodeClip(topology, coefficients) {
  const topo = decodeContainer(topology);
  const coef = decodeContainer(coefficients, { skip: (name) => /^window_\d+$/.test(name) });
  if (coef.header.part === 'coefficients' && isStreamHeader(coef.header)) {
    // the streamable layout (docs/format.md §3.10): its windows decode when first evaluated
    const clip = decodeWindowedClip(topology, coefficients);
    clip.topologyId = coef.header.topology_id ?? null;
    return clip;
  }
  if (topo.header.part !== 'topology') {
    throw new ClipFormatError(`expected a topology part, got ${JSON.stringify(topo.header.part)}`);
  }
  if (coef.header.part !== 'coefficients') {
    throw new ClipFormatError(`expected a coefficients part, got ${JSON.stringify(coef.header.part)}`);
  }
  const kind = coef.header.kind;
  if (!(kind in KINDS)) {
    throw new ClipFormatError(
      `unknown clip kind ${JSON.stringify(kind)} (known: ${Object.keys(KINDS).join(', ')})`,
    );
  }
  const clip = KINDS[kind][0](topo, coef);
  clip.topologyId = coef.header.topology_id ?? null;
  return clip;
}

/** The two parts {topology, coefficients, header} (Uint8Array views) of a CLIP file's bytes. */
export function splitClipFile(data) {
  const { header, arrays } = decodeContainer(data);
  if (
    header.part !== 'clip-file' ||
    !arrays.topology ||
    !arrays.coefficients ||
    arrays.topology.dtype !== '<u1' ||
    arrays.coefficients.dtype !== '<u1'
  ) {
    throw new ClipFormatError('not a pdeanim CLIP file');
  }
  checkFormatVersion(header, 'clip-file');
  return { topology: arrays.topology.data, coefficients: arrays.coefficients.data, header };
}

/** Decode a CLIP file (one container holding both parts). Synchronous; loadClipFile checks the hash. */
export function decodeClipFile(data) {
  const parts = splitClipFile(data);
  return decodeClip(parts.topology, parts.coefficients);
}

/** SHA-256 hex of bytes (WebCrypto: browsers in secure contexts and node >= 19). */
export async function sha256Hex(data) {
  const subtle = globalThis.crypto?.subtle;
  if (!subtle) return null;
  const bytes = bytesOf(data);
  const digest = await subtle.digest('SHA-256', bytes.slice().buffer);
  return Array.from(new Uint8Array(digest), (b) => b.toString(16).padStart(2, '0')).join('');
}

/**
 * Decode a clip and check that the coefficients were made for this topology part (topology_id = SHA-256 of
 * the topology bytes). The check is skipped where WebCrypto is unavailable (plain-HTTP pages).
 */
export async function loadClip(topology, coefficients) {
  const clip = decodeClip(topology, coefficients);
  if (clip.topologyId) {
    const have = await sha256Hex(topology);
    if (have !== null && have !== clip.topologyId) {
      throw new ClipFormatError(
        'the coefficients were made for another topology part (topology_id mismatch)',
      );
    }
  }
  return clip;
}

/** loadClip for a CLIP file's bytes. */
export async function loadClipFile(data) {
  const parts = splitClipFile(data);
  return loadClip(parts.topology, parts.coefficients);
}

/**
 * Fetch a URL as an ArrayBuffer with optional headers (e.g. {Authorization: 'Bearer KEY'}); throws an Error
 * with the server's error message on a non-2xx answer.
 */
export async function fetchBuffer(url, { headers = {}, fetch: fetchFn = globalThis.fetch, signal } = {}) {
  const res = await fetchFn(url, { headers: { Accept: 'application/octet-stream', ...headers }, signal });
  if (!res.ok) {
    let detail = '';
    try {
      const body = await res.json();
      detail = body?.error?.message ? `: ${body.error.message}` : '';
    } catch {
      /* not JSON */
    }
    throw new Error(`GET ${url} answered ${res.status}${detail}`);
  }
  return res.arrayBuffer();
}

/**
 * Fetch and decode a clip from two URLs: {topology, coefficients, headers}. With key, sends
 * Authorization: Bearer key. Resolves to the decoded clip (topology_id checked) with .bytes = {topology,
 * coefficients} (sizes of the bodies as received).
 */
export async function fetchClip({ topology, coefficients, key, headers = {}, fetch: fetchFn, signal }) {
  const h = key ? { Authorization: `Bearer ${key}`, ...headers } : headers;
  const [tb, cb] = await Promise.all([
    fetchBuffer(topology, { headers: h, fetch: fetchFn, signal }),
    fetchBuffer(coefficients, { headers: h, fetch: fetchFn, signal }),
  ]);
  const clip = await loadClip(tb, cb);
  clip.bytes = { topology: tb.byteLength, coefficients: cb.byteLength };
  return clip;
}

/**
 * Fetch and decode clip clipId from a pdeanim service at baseUrl (GET /v1/clips/{id}/topology and
 * /coefficients, Authorization: Bearer key).
 */
export async function fetchServiceClip(baseUrl, clipId, { key, headers = {}, fetch: fetchFn, signal } = {}) {
  const base = `${String(baseUrl).replace(/\/+$/, '')}/v1/clips/${encodeURIComponent(clipId)}`;
  return fetchClip({
    topology: `${base}/topology`,
    coefficients: `${base}/coefficients`,
    key,
    headers,
    fetch: fetchFn,
    signal,
  });
}

/** Fetch and decode a CLIP file from a URL. */
export async function fetchClipFile(url, { key, headers = {}, fetch: fetchFn, signal } = {}) {
  const h = key ? { Authorization: `Bearer ${key}`, ...headers } : headers;
  return loadClipFile(await fetchBuffer(url, { headers: h, fetch: fetchFn, signal }));
}

/**
 * The CPU evaluator of a decoded clip: evaluator.evaluate(t, out) writes (V, 3) float32 positions in the
 * original vertex order at normalised clip time t (looping clips wrap, others clamp to [0, 1]). prepared: a
 * dynamic clip's timeIndex() made elsewhere (in a Web Worker, with the GPU tables).
 */
export function createEvaluator(clip, prepared = null) {
  if (clip?.windowed) return new WindowedEvaluator(clip); // a clip played while it downloads (stream.js)
  const entry = KINDS[clip?.kind];
  if (!entry) throw new ClipFormatError(`unknown clip kind ${JSON.stringify(clip?.kind)}`);
  return new entry[1](clip, prepared);
}
