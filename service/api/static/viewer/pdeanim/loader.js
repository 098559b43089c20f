// PDEClipLoader: a three.js Loader for pdeanim clips (load, loadAsync, onProgress, setPath,
// setRequestHeader, setWithCredentials, the LoadingManager), decoding in a Web Worker where one can run. A
// clip of the streamable layout (docs/format.md §3.10) plays while it downloads: the loader resolves once
// its first time window is decoded, with a StreamingClip that fetches and decodes the rest as it plays.

import { Loader } from 'three';
import { decodeClipFile, loadClipFile } from './clip.js';
import { decodeClipOffThread, openStreamOffThread } from './offthread.js';
import { StreamingClip, openRange, progressEvent } from './stream.js';
import { containerHeader, containerPrefix, isStreamHeader, streamIndex } from './streamformat.js';

/** A service clip URL (…/v1/clips/ID): its two parts are …/topology and …/coefficients. */
const SERVICE_CLIP = /\/v1\/clips\/[^/?#]+\/?(?:[?#].*)?$/;

/** Bytes of a response read so far, with the reader to read more: fill(n) until n bytes from offset 0 are held. */
class BodyReader {
  constructor(opened, onChunk) {
    this.reader = opened.reader;
    this.queue = opened.queue;
    this.onChunk = onChunk;
    this.done = false;
  }

  /** Read until the resource's first `end` bytes have arrived (false when the body ends before). */
  async fill(end) {
    while (this.queue.position + this.queue.length < end) {
      const { value, done } = await this.reader.read();
      if (done) {
        this.done = true;
        return false;
      }
      this.queue.append(value);
      this.onChunk(value.byteLength);
    }
    return true;
  }

  /** Bytes [from, from + n) of the resource (from at or after the queue's position). */
  async bytes(from, n) {
    if (!(await this.fill(from + n))) throw new Error('the response ended early (truncated clip?)');
    this.queue.skip(from - this.queue.position);
    return this.queue.take(n);
  }

  /** The rest of the body, from the queue's position, as one buffer. */
  async rest() {
    while (!this.done) await this.fill(Infinity);
    return this.queue.take(this.queue.length);
  }
}

/**
 * Loads a CLIP file (`pdeanim fit --out X.clip`) or a clip of a pdeanim service (a URL ending in
 * /v1/clips/ID: both parts are fetched, with setRequestHeader({Authorization: 'Bearer KEY'})) and resolves
 * with the decoded clip. Decoding and the GPU tables run in a Web Worker where one can run (setWorker(false)
 * keeps them on the main thread); onProgress gets ProgressEvents whose loaded/total add up over both parts.
 *
 * Streamable clips (format 1.2, feature "stream"; a service clip is asked for that layout: GET
 * …/coefficients?layout=stream) resolve as soon as their first time window is decoded, with a StreamingClip
 * (stream.js): players show it at once, the rest downloads as it plays, and at most setMaxWindows(n) windows
 * stay decoded (evicted behind the play head, fetched again with an HTTP Range request on a seek or a loop).
 * setStreaming(false) asks a service for the whole layout and waits for the whole body.
 */
export class PDEClipLoader extends Loader {
  constructor(manager) {
    super(manager);
    this.useWorker = true;
    this.textureWidth = 4096;
    this.streaming = true;
    this.maxWindows = 4;
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

  /** Play streamable clips while they download (default true; false: the whole body first). */
  setStreaming(on) {
    this.streaming = Boolean(on);
    return this;
  }

  /** How many time windows of a streamable clip stay decoded at once (default 4, at least 2). */
  setMaxWindows(n) {
    if (!(Number.isInteger(n) && n >= 2)) throw new RangeError(`maxWindows must be an integer >= 2, got ${n}`);
    this.maxWindows = n;
    return this;
  }

  load(url, onLoad, onProgress, onError) {
    const full = this.manager.resolveURL(this.path + url);
    this.manager.itemStart(full);
    this._load(full, onProgress)
      .then((clip) => {
        onLoad?.(clip);
        this.manager.itemEnd(full);
      })
      .catch((err) => {
        if (onError) onError(err);
        else console.error(err);
        this.manager.itemError(full);
        this.manager.itemEnd(full);
      });
  }

  /** fetch options of this loader's requests (its headers and credentials). */
  _requestOptions() {
    return { headers: { ...this.requestHeader }, credentials: this.withCredentials ? 'include' : 'same-origin' };
  }

  /**
   * Fetch url (a CLIP file, or a service clip's two parts) and decode it: whole, or, for the streamable
   * layout, up to its first window (the StreamingClip goes on reading).
   */
  async _load(url, onProgress) {
    const base = url.replace(/[?#].*$/, '').replace(/\/$/, '');
    const service = SERVICE_CLIP.test(url);
    const keys = service ? ['topology', 'coefficients'] : ['file'];
    const loaded = Object.fromEntries(keys.map((k) => [k, 0]));
    const total = Object.fromEntries(keys.map((k) => [k, 0]));
    const report = () => {
      if (!onProgress) return;
      const sum = (o) => Object.values(o).reduce((a, b) => a + b, 0);
      const all = keys.every((k) => total[k] > 0);
      onProgress(progressEvent('progress', { lengthComputable: all, loaded: sum(loaded), total: all ? sum(total) : 0 }));
    };
    const options = this._requestOptions();
    const main = service ? `${base}/coefficients${this.streaming ? '?layout=stream' : ''}` : url;
    const mainKey = service ? 'coefficients' : 'file';
    let topologyJob = null;
    if (service) {
      topologyJob = openRange(`${base}/topology`, 0, options).then((opened) => {
        total.topology = opened.total;
        return new BodyReader(opened, (n) => {
          loaded.topology += n;
          report();
        }).rest();
      });
      topologyJob.catch(() => {}); // (awaited below; a failure of the other request comes first)
    }
    // a clip without a streamable layout (a cyclic clip: 422 not_streamable) is read whole from the plain route
    const plain = (err) => {
      if (!(service && this.streaming && err?.status === 422 && err?.code === 'not_streamable')) throw err;
      return openRange(`${base}/coefficients`, 0, options);
    };
    const opened = await openRange(main, 0, options).catch(plain);
    total[mainKey] = opened.total;
    const body = new BodyReader(opened, (n) => {
      loaded[mainKey] += n;
      report();
    });
    const whole = async (topology) => {
      const bytes = await body.rest();
      return this._decode(topology ? { topology, coefficients: bytes } : { file: bytes });
    };
    // the header of the file or part: a streamable part's index says where its windows lie
    if (!(await body.fill(16))) return whole(await topologyJob);
    let start = 0;
    let header = await this._header(body, 0);
    let topology;
    if (header.part === 'clip-file') {
      if (!this.streaming || !isStreamHeader(header)) return whole(null);
      const { topology: ta, coefficients: ca } = header.arrays ?? {};
      if (!ta || !ca) return whole(null); // (refused by the whole-file decoder with its message)
      const dataStart = containerPrefix(body.queue.peek(16)).dataStart;
      topology = await body.bytes(dataStart + ta.offset, ta.nbytes);
      start = dataStart + ca.offset;
      if (!(await body.fill(start + 16))) throw new Error('the response ended early (truncated clip?)');
      body.queue.skip(start - body.queue.position);
      header = await this._header(body, start);
    } else {
      topology = await topologyJob;
      if (!this.streaming || !isStreamHeader(header)) return whole(topology);
    }
    return this._stream({ body, opened, header, start, topology, main, options, report, loaded, mainKey });
  }

  /** The JSON header of the container starting at resource offset start (its bytes read, not consumed). */
  async _header(body, start) {
    const { dataStart } = containerPrefix(body.queue.peek(16));
    if (!(await body.fill(start + dataStart))) throw new Error('the response ended early (truncated clip?)');
    return containerHeader(body.queue.peek(dataStart));
  }

  /** A streamable coefficients part from resource offset start: its head decoded, then its windows as they come. */
  async _stream({ body, opened, header, start, topology, main, options, report, loaded, mainKey }) {
    const index = streamIndex(header);
    const dataStart = containerPrefix(body.queue.peek(16)).dataStart;
    const head = await body.bytes(start, dataStart + index[0].offset);
    const decoder = await openStreamOffThread({ topology, head }, { useWorker: this.useWorker, width: this.textureWidth });
    const windows = decoder.shell.index.map((w) => ({
      ...w,
      s0: w.a,
      s1: w.b,
      offset: start + dataStart + w.offset,
      length: w.nbytes,
    }));
    const fetcher = {
      open: (from) => openRange(main, from, options),
      decode: decoder.decode,
      forget: decoder.forget,
      close: decoder.close,
      decoder,
    };
    const clip = new StreamingClip(decoder.shell, windows, fetcher, { maxWindows: this.maxWindows });
    clip.gpuTables = decoder.tables;
    // the first request goes on as the clip's first read (its progress still reported)
    const base = loaded[mainKey];
    clip.addEventListener('progress', (e) => {
      if (clip.stream?.reader !== opened.reader) return;
      loaded[mainKey] = base + e.detail.loaded;
      report();
    });
    clip._adopt(opened, 0);
    await clip.firstWindow.promise;
    return clip;
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
