// Installs fzstd (pure-JS zstd) as the container's decoder: imported for its side effect by the package's
// entry points; Web Workers install it from a URL instead (worker.js).

import { Decompress } from 'fzstd';
import { setZstdDecompress } from './container.js';

setZstdDecompress(Decompress);
