// PDEClipLoader: a three.js Loader for pdeanim clips (load, loadAsync, onProgress, setPath,
// setRequestHeader, setWithCredentials, the LoadingManager), decoding in a Web Worker where one can run.

import { FileLoader, Loader } from 'three';
import { decodeClipFile, loadClipFile } from './clip.js';
import { decodeClipOffThread } from './offthread.js';

/** A service clip URL (…/v1/clips/ID): its two parts are …/topology and …/coefficients. */
const SERVICE_CLIP = /\/v1\/clips\/[^/?#]+\/?(?:[?#].*)?$/;

/**
 * Loads a CLIP file (`pdeanim fit --out X.clip`) or a clip of a pdeanim service (a URL ending in
 * /v1/clips/ID: both parts are fetched, with setRequestHeader({Authorization: 'Bearer KEY'})) and resolves
 * with the decoded clip. Decoding and the GPU tables run in a Web Worker where one can run (setWorker(false)
 * keeps them on the main thread); onProgress gets ProgressEvents whose loaded/total add up over both parts.
 */
export class PDEClipLoader extends Loader {
  constructor(manager) {
    super(manager);
    this.useWorker = true;
    this.textureWidth = 4096;
  }

  /** Decode in a Web Worker (default true where workers run). */
  setWorker(on) {
    this.useWorker = Boolean(on);
    return this;
  }

  /** Width of the data textures the worker prepares (the renderer's maxTextureSize when smaller). */
  setTextureWidth(width) {
    this.textureWidth = width;
    return this;
  }

  load(url, onLoad, onProgress, onError) {
    const full = this.manager.resolveURL(this.path + url);
    const fail = (err) => {
      if (onError) onError(err);
      else console.error(err);
      this.manager.itemError(full);
    };
    this.manager.itemStart(full);
    this._fetch(full, onProgress)
      .then((parts) => this._decode(parts))
      .then((clip) => {
        onLoad?.(clip);
        this.manager.itemEnd(full);
      })
      .catch((err) => {
        fail(err);
        this.manager.itemEnd(full);
      });
  }

  /** The bytes of url: {file} or, for a service clip URL, {topology, coefficients}. */
  async _fetch(url, onProgress) {
    const base = url.replace(/[?#].*$/, '').replace(/\/$/, '');
    const urls = SERVICE_CLIP.test(url) ? { topology: `${base}/topology`, coefficients: `${base}/coefficients` } : { file: url };
    const loaded = {};
    const total = {};
    const progress = (key) => (event) => {
      loaded[key] = event.loaded;
      total[key] = event.total;
      if (!onProgress) return;
      const sum = (o) => Object.values(o).reduce((a, b) => a + (b || 0), 0);
      const all = Object.keys(urls).every((k) => total[k] > 0);
      const init = { lengthComputable: all, loaded: sum(loaded), total: all ? sum(total) : 0 };
      // node has no ProgressEvent: a plain object with the same fields there
      onProgress(typeof ProgressEvent === 'function' ? new ProgressEvent('progress', init) : { type: 'progress', ...init });
    };
    const entries = await Promise.all(
      Object.entries(urls).map(([key, u]) => {
        const loader = new FileLoader(this.manager);
        loader.setResponseType('arraybuffer');
        loader.setRequestHeader({ Accept: 'application/octet-stream', ...this.requestHeader });
        loader.setWithCredentials(this.withCredentials);
        return loader.loadAsync(u, progress(key)).then((buffer) => [key, buffer]);
      }),
    );
    return Object.fromEntries(entries);
  }

  _decode(parts) {
    return decodeClipOffThread(parts, { useWorker: this.useWorker, width: this.textureWidth });
  }

  /** Decode a CLIP file's bytes on the main thread, synchronously (no topology_id check). */
  parse(buffer) {
    return decodeClipFile(buffer);
  }

  /** Decode a CLIP file's bytes (topology_id checked), in a worker where one can run. */
  parseAsync(buffer) {
    return this.useWorker ? this._decode({ file: buffer }) : loadClipFile(buffer);
  }
}
