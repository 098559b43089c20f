// Decode the pdeanim binary container: magic, version, JSON header, little-endian arrays (docs/format.md §1);
// an array may be stored as one zstd frame ("zstd") or byte planes in one zstd frame ("shuffle-zstd").

// The zstd decoder is installed by zstd.js (which index.js and three.js import): a Web Worker, which cannot
// resolve the bare specifier 'fzstd', installs it from a URL instead.
let Decompress = null;

/** Install the zstd streaming decoder (fzstd's Decompress class) used for encoded arrays. */
export function setZstdDecompress(cls) {
  Decompress = cls;
}

export const MAGIC = 'PDEANIM\0';
/** The container version this build reads (the uint32 at byte 8). */
export const CONTAINER_VERSION = 1;
/** The array encodings a container may use. */
export const ENCODINGS = Object.freeze(['zstd', 'shuffle-zstd']);
/** The clip format every part and CLIP file is written in (docs/format.md): readers accept any "1.<minor>". */
export const FORMAT_VERSION = '1.0';

/** The format features this reader implements (a part's `required` list may name only these). */
export const SUPPORTED_FEATURES = Object.freeze(['bones', 'stream']);

/**
 * Throw ClipFormatError unless a part's header.format_version is "1.<minor>" (minor versions only add header
 * keys or arrays that readers ignore; another major version changes the layout) and every feature its
 * `required` list names is one this reader implements (checkRequired).
 */
export function checkFormatVersion(header, part) {
  const version = header?.format_version;
  const ok = typeof version === 'string' && /^1\.[0-9]+$/.test(version);
  if (!ok) {
    throw new ClipFormatError(
      `unsupported clip format version ${JSON.stringify(version ?? null)} in the ${part} part (this build reads 1.x)`,
    );
  }
  checkRequired(header, part);
}

/**
 * The features a part's header requires (`required`: a list of strings, absent = none), after refusing, with
 * a ClipFormatError naming them and the supported set, any this reader lacks: the part would be drawn wrong.
 */
export function checkRequired(header, part) {
  const required = header?.required ?? [];
  if (!Array.isArray(required) || !required.every((x) => typeof x === 'string')) {
    throw new ClipFormatError(`the ${part} part's 'required' must be a list of feature names, got ${JSON.stringify(required)}`);
  }
  const missing = required.filter((x) => !SUPPORTED_FEATURES.includes(x));
  if (missing.length) {
    throw new ClipFormatError(
      `the ${part} part requires format feature(s) ${missing.map((x) => JSON.stringify(x)).join(', ')} that this ` +
        `reader lacks (it supports: ${SUPPORTED_FEATURES.join(', ')}); update pdeanim to play it`,
    );
  }
  return required;
}

/** Error thrown for anything that is not a valid pdeanim clip, part or container. */
export class ClipFormatError extends Error {
  constructor(message) {
    super(message);
    this.name = 'ClipFormatError';
  }
}

/**
 * Largest magnitude of a position-scale number a reader accepts (docs/format.md §5): rest coordinates, knots,
 * rigid centres and translations, cyclic rest positions and spine coefficients. With the space basis at most
 * 2 and the time weights below 2^25, no frame of such a clip overflows float32.
 */
export const VALUE_LIMIT = 2 ** 96;

/** Throw ClipFormatError unless every value is finite and at most VALUE_LIMIT in magnitude. */
export function checkBounded(values, what) {
  for (let i = 0; i < values.length; i++) {
    if (!(Math.abs(values[i]) <= VALUE_LIMIT)) {
      throw new ClipFormatError(`${what} hold a value above 2^96 in magnitude or not finite (frames would not be finite)`);
    }
  }
}

const DTYPES = {
  '<f4': [Float32Array, 4],
  '<f8': [Float64Array, 8],
  '<i4': [Int32Array, 4],
  '<u4': [Uint32Array, 4],
  '<i2': [Int16Array, 2],
  '<u2': [Uint16Array, 2],
  '<u1': [Uint8Array, 1],
  '<i1': [Int8Array, 1],
};

const LITTLE_ENDIAN = new Uint8Array(new Uint16Array([1]).buffer)[0] === 1;

function asBytes(data) {
  if (data instanceof Uint8Array) return data;
  if (data instanceof ArrayBuffer) return new Uint8Array(data);
  if (ArrayBuffer.isView(data)) return new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  throw new ClipFormatError('expected an ArrayBuffer or a typed array');
}

function typedArray(bytes, lo, dtype, count) {
  const [Ctor, size] = DTYPES[dtype];
  const abs = bytes.byteOffset + lo;
  if (size === 1) return new Ctor(bytes.buffer, abs, count);
  if (LITTLE_ENDIAN && abs % size === 0) return new Ctor(bytes.buffer, abs, count);
  // unaligned view (a container inside a CLIP file) or a big-endian host: copy through a DataView
  const out = new Ctor(count);
  const view = new DataView(bytes.buffer, abs, count * size);
  const get = {
    '<f4': 'getFloat32',
    '<f8': 'getFloat64',
    '<i4': 'getInt32',
    '<u4': 'getUint32',
    '<i2': 'getInt16',
    '<u2': 'getUint16',
  }[dtype];
  for (let i = 0; i < count; i++) out[i] = view[get](i * size, true);
  return out;
}

/**
 * Walk the zstd frame (RFC 8878) in stored: one frame with no dictionary whose header declares its content
 * size, blocks inside the bytes, nothing after it. Returns the declared size (checked before anything is
 * decompressed: a corrupt header cannot make the decoder allocate a huge buffer).
 */
function zstdFrame(stored, label) {
  const bad = (why) => new ClipFormatError(`${label}: bad zstd data (${why})`);
  const n = stored.length;
  if (n < 6 || stored[0] !== 0x28 || stored[1] !== 0xb5 || stored[2] !== 0x2f || stored[3] !== 0xfd) {
    throw bad('not a zstd frame');
  }
  const fhd = stored[4];
  if (fhd & 8) throw bad('reserved frame header bit set');
  const single = (fhd >> 5) & 1;
  const dictBytes = [0, 1, 2, 4][fhd & 3];
  const sizeBytes = [single, 2, 4, 8][fhd >> 6];
  let pos = 5 + (single ? 0 : 1);
  if (pos + dictBytes + sizeBytes > n) throw bad('truncated frame header');
  let dict = 0;
  for (let i = 0; i < dictBytes; i++) dict += stored[pos + i] * 2 ** (8 * i);
  if (dict !== 0) throw bad('the frame needs a dictionary');
  pos += dictBytes;
  if (sizeBytes === 0) throw new ClipFormatError(`${label}: the zstd frame does not declare its content size`);
  let declared = 0;
  for (let i = 0; i < sizeBytes; i++) declared += stored[pos + i] * 2 ** (8 * i);
  if (sizeBytes === 2) declared += 256;
  pos += sizeBytes;
  for (let last = 0; !last; ) {
    if (pos + 3 > n) throw bad('truncated frame');
    const h = stored[pos] | (stored[pos + 1] << 8) | (stored[pos + 2] << 16);
    last = h & 1;
    const type = (h >> 1) & 3;
    if (type === 3) throw bad('reserved block type');
    pos += 3 + (type === 1 ? 1 : h >>> 3);
    if (pos > n) throw bad('truncated frame');
  }
  pos += (fhd >> 2) & 1 ? 4 : 0; // content checksum
  if (pos > n) throw bad('truncated frame');
  if (pos !== n) throw bad(`${n - pos} bytes after the frame`);
  return declared;
}

/** The element bytes of an encoded array: decompressed (exactly size bytes) and, for shuffle-zstd, unshuffled. */
function decodeArrayBytes(stored, encoding, itemsize, count, label) {
  const size = count * itemsize;
  const declared = zstdFrame(stored, label);
  if (declared !== size) {
    throw new ClipFormatError(`${label}: zstd frame holds ${declared} bytes, expected ${size}`);
  }
  if (Decompress === null) throw new ClipFormatError(`${label}: no zstd decoder installed (import 'pdeanim')`);
  let raw = new Uint8Array(size);
  let got = 0;
  const inflate = new Decompress((chunk) => {
    if (got + chunk.length > size) {
      throw new ClipFormatError(`${label} decompresses to more than the expected ${size} bytes`);
    }
    raw.set(chunk, got);
    got += chunk.length;
  });
  try {
    inflate.push(stored, true);
  } catch (err) {
    if (err instanceof ClipFormatError) throw err;
    throw new ClipFormatError(`${label}: bad zstd data (${err.message})`);
  }
  if (got !== size) throw new ClipFormatError(`${label} decompresses to ${got} bytes, expected ${size}`);
  if (encoding === 'shuffle-zstd' && itemsize > 1) {
    // byte j of element i sits at j * count + i
    const planes = raw;
    raw = new Uint8Array(size);
    if (itemsize === 4 && LITTLE_ENDIAN) unshuffle4(planes, count, new Uint32Array(raw.buffer));
    else {
      for (let j = 0; j < itemsize; j++) {
        const plane = planes.subarray(j * count, (j + 1) * count);
        for (let i = 0, o = j; i < count; i++, o += itemsize) raw[o] = plane[i];
      }
    }
  }
  return raw;
}

/** Shuffled 4-byte elements (byte j of element i at j * count + i) into out (little-endian words). */
function unshuffle4(planes, count, out) {
  const b1 = count;
  const b2 = 2 * count;
  const b3 = 3 * count;
  for (let i = 0; i < count; i++) {
    out[i] = (planes[i] | (planes[b1 + i] << 8) | (planes[b2 + i] << 16) | (planes[b3 + i] << 24)) >>> 0;
  }
}

/**
 * One array of a container: its header entry spec checked against the bytes (data starting at byte start)
 * and decoded into {dtype, shape, data[, encoding]}.
 */
function decodeArray(bytes, start, name, spec) {
  const shape = Array.isArray(spec?.shape) ? spec.shape.map(Number) : null;
  const dtype = spec?.dtype;
  if (
    !shape ||
    !(dtype in DTYPES) ||
    shape.some((s) => !Number.isInteger(s) || s < 0) ||
    !Number.isInteger(spec.offset) ||
    !Number.isInteger(spec.nbytes) ||
    spec.offset < 0 ||
    spec.nbytes < 0
  ) {
    throw new ClipFormatError(`bad array entry ${JSON.stringify(name)} in container header`);
  }
  const label = `array ${JSON.stringify(name)}`;
  const encoded = Object.hasOwn(spec, 'encoding');
  const encoding = spec.encoding;
  if (encoded && !ENCODINGS.includes(encoding)) {
    throw new ClipFormatError(
      `${label} has an unknown encoding ${JSON.stringify(encoding)} (known: ${ENCODINGS.join(', ')})`,
    );
  }
  const count = shape.reduce((a, b) => a * b, 1);
  const itemsize = DTYPES[dtype][1];
  if (!Number.isSafeInteger(count * itemsize) || (!encoded && spec.nbytes !== count * itemsize)) {
    throw new ClipFormatError(`${label} has an inconsistent dtype or size`);
  }
  const lo = start + spec.offset;
  if (lo + spec.nbytes > bytes.byteLength) {
    throw new ClipFormatError(`${label} lies outside the container (truncated file?)`);
  }
  if (!encoded) return { dtype, shape, data: typedArray(bytes, lo, dtype, count) };
  const raw = decodeArrayBytes(bytes.subarray(lo, lo + spec.nbytes), encoding, itemsize, count, label);
  return { dtype, shape, data: typedArray(raw, 0, dtype, count), encoding };
}

/**
 * Decode container bytes into {header, arrays}; each array is {dtype, shape, data} with data a typed
 * array (a view on the input where alignment allows). skip: a predicate of the array names not to decode
 * (they may lie beyond the bytes given). Throws ClipFormatError.
 */
export function decodeContainer(data, { skip = null } = {}) {
  const bytes = asBytes(data);
  if (bytes.byteLength < 16) {
    throw new ClipFormatError(`blob of ${bytes.byteLength} bytes is too short to be a pdeanim container`);
  }
  for (let i = 0; i < 8; i++) {
    if (bytes[i] !== MAGIC.charCodeAt(i))
      throw new ClipFormatError('not a pdeanim container (bad magic bytes)');
  }
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const version = view.getUint32(8, true);
  if (version !== CONTAINER_VERSION) {
    throw new ClipFormatError(
      `unsupported container version ${version} (this build reads ${CONTAINER_VERSION})`,
    );
  }
  const hlen = view.getUint32(12, true);
  const start = 16 + hlen;
  if (start > bytes.byteLength) throw new ClipFormatError('truncated container header');
  let header;
  try {
    header = JSON.parse(new TextDecoder('utf-8', { fatal: true }).decode(bytes.subarray(16, start)));
  } catch (err) {
    throw new ClipFormatError(`container header is not valid JSON: ${err.message}`);
  }
  if (header === null || typeof header !== 'object' || Array.isArray(header)) {
    throw new ClipFormatError('container header is not a JSON object');
  }
  const table = header.arrays || {};
  delete header.arrays;
  const arrays = {};
  for (const [name, spec] of Object.entries(table)) {
    // skip (a predicate of array names): arrays left undecoded, e.g. the windows after a streamable clip's head
    if (skip === null || !skip(name)) arrays[name] = decodeArray(bytes, start, name, spec);
  }
  return { header, arrays };
}
