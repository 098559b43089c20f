// pdeanim: decode and evaluate pdeanim clips (dynamic-PDE and cyclic-spine) in browsers and node.

import './zstd.js';

export {
  ClipFormatError,
  decodeContainer,
  CONTAINER_VERSION,
  CONTAINER_VERSIONS,
  ENCODINGS,
  setZstdDecompress,
} from './container.js';
export {
  decodeClip,
  decodeClipFile,
  splitClipFile,
  loadClip,
  loadClipFile,
  fetchBuffer,
  fetchClip,
  fetchClipFile,
  fetchServiceClip,
  createEvaluator,
  sha256Hex,
} from './clip.js';
export {
  DynamicEvaluator,
  checkTime,
  DYNAMIC_FORMAT_VERSION,
  DYNAMIC_FORMAT_VERSIONS,
  DYNAMIC_TOPOLOGY_VERSIONS,
  vertexBasis,
  vertexBase,
} from './dynamic.js';
export { CyclicEvaluator } from './cyclic.js';
export { spaceBasis, timePair, rigidTimePair, hermiteWeights, locate } from './basis.js';
export { computeNormals, boundingBoxDiagonal, triangleFrame } from './geometry.js';
