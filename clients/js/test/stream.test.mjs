// The streamable layout (docs/format.md §3.10) in JS: windows evaluate as the whole clip, a damaged index is
// refused, and PDEClipLoader plays a long clip while it downloads: first window before the last byte, at most
// maxWindows windows decoded, the download held back (backpressure) ahead of the play head, a seek back
// fetched again with an HTTP Range request.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import { ClipFormatError, createEvaluator, decodeClip, sha256Hex } from '../src/index.js';
import { PDEClipLoader } from '../src/three.js';
import { gpuLayout, frameView, frameTexels, timeUniforms } from '../src/gpu.js';
import { StreamingClip, WindowedClip } from '../src/stream.js';
import { FIXTURES, edited, manifest, readBytes } from './helpers.mjs';
import { splitClipFile } from '../src/clip.js';
import { clipFile, longSource, rangeServer, sourceOf, streamPart } from './streamhelpers.mjs';

const man = manifest();
const byName = (name) => man.cases.find((c) => c.name === name);
const partsOf = (name) => splitClipFile(readBytes(join(FIXTURES, byName(name).clip)));
const times = (n) => Array.from({ length: n }, (_, k) => k / (n - 1));

for (const name of ['fit-absolute-chord-pde', 'fit-rigid-paper-loop', 'fit-displacement-chord-loop']) {
  test(`${name} in the streamable layout evaluates as the whole clip, bit for bit, in windows of 1 and 2 segments`, () => {
    const parts = partsOf(name);
    const src = sourceOf(parts);
    const whole = createEvaluator(src.clip);
    for (const per of [1, 2]) {
      const clip = decodeClip(parts.topology, streamPart(src, per));
      assert.ok(clip instanceof WindowedClip && clip.windowed);
      assert.equal(clip.nWindows, Math.ceil(src.clip.nSegments / per));
      const ev = createEvaluator(clip);
      for (const t of [...times(41), ...(src.clip.looping ? [-0.3, 1.25] : [])]) {
        assert.deepEqual(ev.evaluate(t), whole.evaluate(t), `t=${t}`);
      }
      assert.ok(clip.decoded.size <= clip.maxWindows, 'windows decoded in memory stay bounded');
    }
  });
}

test('a damaged stream index, or a window disagreeing with it, is refused with a clear message', () => {
  const parts = partsOf('fit-absolute-chord-pde');
  const part = streamPart(sourceOf(parts), 1);
  const damage = (edit) => edited(part, ({ header }) => edit(header.stream.windows, header));
  const cases = [
    [damage((w) => (w[1].t[0] = 0.5)), /damaged stream index: window 1 does not start where window 0 ends/],
    [damage((w) => (w[0].offset += 8)), /damaged stream index: window 0's offset and size do not match its array/],
    [damage((w) => (w[2].knots[1] = 2)), /damaged stream index: window 2's knots must be integers a < b/],
    [damage((w, h) => (h.stream.n_windows = 5)), /damaged stream index: n_windows 5 for 3 windows/],
    [damage((w) => w.pop()), /n_windows 3 for 2 windows/],
  ];
  for (const [bytes, want] of cases) {
    assert.throws(() => decodeClip(parts.topology, bytes), (e) => e instanceof ClipFormatError && want.test(e.message));
  }
  // a window whose own header names other knots than the index
  const swapped = edited(part, ({ header }) => {
    const w = header.stream.windows;
    [w[0].array, w[1].array] = [w[1].array, w[0].array];
  });
  assert.throws(() => decodeClip(parts.topology, swapped), /window 0 is not in array window_0/);
  const clip = decodeClip(parts.topology, part);
  clip.windowBytes = (i) => decodeClip(parts.topology, part).windowBytes(i === 0 ? 1 : i);
  assert.throws(() => createEvaluator(clip).evaluate(0), /window 0: its header \(window 1, knots 1..2\) disagrees with the index/);
});

test('PDEClipLoader plays a long streamable clip while it downloads: first window first, bounded, Range on a seek', async () => {
  const parts = partsOf('fit-absolute-chord-pde');
  const src = longSource(parts, 240); // 240 segments in 24 windows of 10
  const part = streamPart(src, 10);
  const file = clipFile(parts.topology, part, await sha256Hex(parts.topology));
  const whole = createEvaluator(decodeClip(parts.topology, part));
  let release;
  const hold = { at: file.length - 100, release: new Promise((r) => (release = r)) };
  const { server, log, url } = await rangeServer({ '/long.clip': file, '/v1/clips/L/topology': parts.topology, '/v1/clips/L/coefficients': part }, { hold });
  try {
    const progress = [];
    const loader = new PDEClipLoader().setMaxWindows(3);
    const clip = await loader.loadAsync(`${url}/long.clip`, (e) => progress.push(e.loaded));
    // the server has not sent the last 100 bytes (it waits for this line): the first window came before
    assert.ok(clip instanceof StreamingClip && clip.streaming);
    assert.ok(!log[0].done && log[0].sent <= hold.at, 'the loader resolved before the body ended');
    assert.ok(progress.length >= 1 && progress.at(-1) < file.length, 'progress is reported as the chunks come');
    assert.ok(clip.ready(0) && !clip.ready(1));
    assert.deepEqual(createEvaluator(clip).evaluate(0.01), whole.evaluate(0.01));
    release();
    const windowsSeen = [];
    clip.addEventListener('window', (e) => windowsSeen.push(e.detail.index));
    const ev = createEvaluator(clip);
    let most = 0;
    let states = 0;
    for (const t of times(97)) {
      await clip.whenReady(t);
      most = Math.max(most, clip.decoded.size);
      states = Math.max(states, clip.fetcher.decoder.states.size);
      assert.deepEqual(ev.evaluate(t), whole.evaluate(t), `t=${t}`);
    }
    assert.ok(most <= 3, `at most maxWindows = 3 windows decoded at once (saw ${most})`);
    // the decoder's carried states stay bounded too (held windows', the read's, maxWindows checkpoints)
    assert.ok(states <= 2 * 3 + 1, `at most 7 of 24 carried states held at once (saw ${states})`);
    assert.equal(clip.fetcher.decoder.states.size, clip.stateSent.size);
    assert.ok(windowsSeen.length >= 20, 'the windows arrived one by one');
    // a seek back to an evicted window: fetched again from its byte offset with a Range request (206)
    assert.ok(!clip.ready(0.02));
    const before = log.length;
    await clip.whenReady(0.02);
    assert.deepEqual(ev.evaluate(0.02), whole.evaluate(0.02));
    const again = log.slice(before).find((r) => r.range !== null);
    assert.ok(again && again.status === 206, JSON.stringify(log.slice(before)));
    assert.equal(Number(/bytes=(\d+)-/.exec(again.range)[1]), clip.windows[0].offset);
    // the GPU path's per-frame table of a window equals the whole clip's
    const layoutS = gpuLayout(clip, { tables: clip.gpuTables, evaluator: createEvaluator(clip) });
    const wholeClip = decodeClip(parts.topology, part);
    const layoutW = gpuLayout(wholeClip, { tables: clip.gpuTables, evaluator: createEvaluator(wholeClip) });
    const n = frameTexels(layoutS) * 4;
    const [vs, vw] = [frameView(layoutS, new Float32Array(n)), frameView(layoutW, new Float32Array(n))];
    for (const t of [0.02, 0.03, 0.07]) {
      timeUniforms(vs, t);
      timeUniforms(vw, t);
      assert.deepEqual(vs.textures.frame.data, vw.textures.frame.data, `frame table at t=${t}`);
    }
    // knots are carried from window to window: a seek restarts at the latest checkpoint state at or before
    // the window (not at the clip's start), and decodes as the whole clip
    const k = clip.windowAt(0.55);
    const mark = log.length;
    await clip.whenReady(0.55);
    assert.deepEqual(ev.evaluate(0.55), whole.evaluate(0.55));
    const seek = log.slice(mark).find((r) => r.range !== null);
    const from = clip.windows.findIndex((w) => w.offset === Number(/bytes=(\d+)-/.exec(seek.range)[1]));
    assert.ok(from > 0 && from <= k && k - from <= clip.checkpointStride, `restarted at window ${from} for ${k}`);
    clip.close();
    // a service clip: the coefficients part is asked for in the streamable layout, the topology beside it
    const service = await loader.loadAsync(`${url}/v1/clips/L`);
    assert.ok(service.streaming);
    assert.ok(log.some((r) => r.url === '/v1/clips/L/coefficients?layout=stream'));
    await service.whenReady(0.5);
    assert.deepEqual(createEvaluator(service).evaluate(0.5), whole.evaluate(0.5));
    service.close();
  } finally {
    release();
    server.closeAllConnections?.();
    server.close();
  }
});
