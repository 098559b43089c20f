// Decode the pdeanim binary container: magic, version, JSON header, little-endian arrays (docs/format.md §1).

export const MAGIC = 'PDEANIM\0';
export const CONTAINER_VERSION = 1;

/** Error thrown for anything that is not a valid pdeanim clip, part or container. */
export class ClipFormatError extends Error {
  constructor(message) {
    super(message);
    this.name = 'ClipFormatError';
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
 * Decode container bytes into {header, arrays}; each array is {dtype, shape, data} with data a typed
 * array (a view on the input where alignment allows). Throws ClipFormatError.
 */
export function decodeContainer(data) {
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
    const shape = Array.isArray(spec?.shape) ? spec.shape.map(Number) : null;
    const dtype = spec?.dtype;
    if (
      !shape ||
      !(dtype in DTYPES) ||
      shape.some((s) => !Number.isInteger(s) || s < 0) ||
      !Number.isInteger(spec.offset) ||
      !Number.isInteger(spec.nbytes) ||
      spec.offset < 0
    ) {
      throw new ClipFormatError(`bad array entry ${JSON.stringify(name)} in container header`);
    }
    const count = shape.reduce((a, b) => a * b, 1);
    if (spec.nbytes !== count * DTYPES[dtype][1]) {
      throw new ClipFormatError(`array ${JSON.stringify(name)} has an inconsistent dtype or size`);
    }
    const lo = start + spec.offset;
    if (lo + spec.nbytes > bytes.byteLength) {
      throw new ClipFormatError(`array ${JSON.stringify(name)} lies outside the container (truncated file?)`);
    }
    arrays[name] = { dtype, shape, data: typedArray(bytes, lo, dtype, count) };
  }
  return { header, arrays };
}
