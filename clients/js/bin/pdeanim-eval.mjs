#!/usr/bin/env node
// pdeanim-eval: evaluate a pdeanim clip at times t and write little-endian float32 (K, V, 3) positions.

import { readFileSync, writeFileSync } from 'node:fs';
import { parseArgs } from 'node:util';
import { ClipFormatError, createEvaluator, loadClip, splitClipFile } from '../src/index.js';

const USAGE = `usage: pdeanim-eval CLIP --t T1,T2,...|all --out FILE.bin
       pdeanim-eval --coefficients COEF --topology TOPO --t T1,T2,...|all --out FILE.bin

Evaluates a pdeanim clip (a CLIP file, or its two parts) at normalised times t and writes the positions
as little-endian float32 (K, V, 3) in the original vertex order (K times, V vertices). --t all: every
source frame. Clips that do not loop take t in [0, 1]; looping ones any t (period 1), as \`pdeanim frame\`.`;

class UsageError extends Error {}

function fail(message) {
  process.stderr.write(`pdeanim-eval: error: ${message}\n`);
  process.exit(2);
}

function read(path, what) {
  try {
    return readFileSync(path);
  } catch (err) {
    throw new UsageError(
      `cannot read ${what} ${path}: ${err.code === 'ENOENT' ? 'no such file' : err.message}`,
    );
  }
}

/** The source frames' normalised times (t of frame k), as `pdeanim frame --t all`. */
function frameTimes(clip) {
  const ft = clip.frameTimes;
  const span = ft.length > 1 ? ft[ft.length - 1] - ft[0] : 0;
  return Array.from(ft, (x) => (span > 0 ? (x - ft[0]) / span : 0));
}

function parseTimes(text) {
  if (String(text).trim().toLowerCase() === 'all') return 'all';
  const parts = String(text)
    .split(',')
    .map((s) => s.trim());
  if (!parts.length || parts.some((s) => s === ''))
    throw new UsageError(`--t must be a comma-separated list of numbers, got ${JSON.stringify(text)}`);
  return parts.map((s) => {
    const t = Number(s);
    if (!Number.isFinite(t))
      throw new UsageError(`--t values must be finite numbers, got ${JSON.stringify(s)}`);
    return t;
  });
}

/** '--t -0.3,1' as '--t=-0.3,1': values of the string options may start with a dash (negative times). */
function joinValues(argv) {
  const out = [];
  for (let i = 0; i < argv.length; i++) {
    if (['--t', '--out', '--coefficients', '--topology'].includes(argv[i]) && i + 1 < argv.length) {
      out.push(`${argv[i]}=${argv[i + 1]}`);
      i++;
    } else out.push(argv[i]);
  }
  return out;
}

/** The clip's two parts from a CLIP file (the positional) or from --coefficients and --topology. */
function readParts(o, positionals) {
  if (positionals.length === 1) {
    if (o.coefficients !== undefined || o.topology !== undefined) {
      throw new UsageError('give either a CLIP file or --coefficients and --topology, not both');
    }
    return splitClipFile(read(positionals[0], 'clip file'));
  }
  if (o.coefficients === undefined || o.topology === undefined) {
    throw new UsageError('give a CLIP file, or both --coefficients COEF and --topology TOPO');
  }
  const coefficients = read(o.coefficients, 'coefficients part');
  return { coefficients, topology: read(o.topology, 'topology part') };
}

async function main(argv) {
  let parsed;
  try {
    parsed = parseArgs({
      args: joinValues(argv),
      allowPositionals: true,
      options: {
        t: { type: 'string' },
        out: { type: 'string' },
        coefficients: { type: 'string' },
        topology: { type: 'string' },
        help: { type: 'boolean', short: 'h' },
      },
    });
  } catch (err) {
    throw new UsageError(err.message);
  }
  const { values: o, positionals } = parsed;
  if (o.help) {
    process.stdout.write(`${USAGE}\n`);
    return;
  }
  if (positionals.length > 1)
    throw new UsageError(`expected at most one CLIP file, got ${positionals.length} paths`);
  if (o.t === undefined) throw new UsageError('--t is required');
  if (o.out === undefined) throw new UsageError('--out is required');
  let times = parseTimes(o.t);
  const { topology, coefficients } = readParts(o, positionals);
  const clip = await loadClip(topology, coefficients);
  if (times === 'all') times = frameTimes(clip);
  const bad = clip.looping ? undefined : times.find((t) => !(t >= 0 && t <= 1));
  if (bad !== undefined) throw new UsageError(`--t must lie in [0, 1] for this clip (it does not loop), got ${bad}`);
  const ev = createEvaluator(clip);
  const N = clip.nVertices * 3;
  const out = new Float32Array(times.length * N);
  times.forEach((t, k) => ev.evaluate(t, out.subarray(k * N, (k + 1) * N)));
  const bytes = new Uint8Array(out.buffer);
  if (new Uint8Array(new Uint16Array([1]).buffer)[0] !== 1) {
    // big-endian host: swap to little-endian
    const view = new DataView(out.buffer);
    for (let i = 0; i < out.length; i++) view.setFloat32(i * 4, out[i], true);
  }
  try {
    writeFileSync(o.out, bytes);
  } catch (err) {
    throw new UsageError(`cannot write ${o.out}: ${err.message}`);
  }
  process.stderr.write(`pdeanim-eval: wrote ${times.length} x ${clip.nVertices} x 3 float32 to ${o.out}\n`);
}

main(process.argv.slice(2)).catch((err) => {
  if (err instanceof UsageError) fail(`${err.message}\n${USAGE}`);
  if (err instanceof ClipFormatError) fail(err.message);
  throw err;
});
