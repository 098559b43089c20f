// pdeanim: decode and evaluate pdeanim clips (dynamic-PDE and cyclic-spine) in browsers and node.

import './zstd.js';

export {
  ClipFormatError,
  decodeContainer,
  checkFormatVersion,
  CONTAINER_VERSION,
  ENCODINGS,
  FORMAT_VERSION,
  SUPPORTED_FEATURES,
  checkRequired,
  setZstdDecompress,
} from './container.js';
export { BonePose, decodeBones } from './bones.js';
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
  TIME_PDE,
  TIME_SPLINE,
  checkTime,
  vertexBasis,
  vertexBase,
} from './dynamic.js';
export { CyclicEvaluator } from './cyclic.js';
export {
  StreamingClip,
  WindowedClip,
  WindowedEvaluator,
  WindowPendingError,
  decodeWindowedClip,
  openRange,
} from './stream.js';
export { STREAM_FEATURE, decodeStreamHead, decodeStreamWindow, isStreamHeader, streamIndex } from './streamformat.js';
export { spaceBasis, timePair, rigidTimePair, locate } from './basis.js';
export { computeNormals, boundingBoxDiagonal, ringNormals, triangleFrame, vertexRings } from './geometry.js';
