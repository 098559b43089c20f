// Fetching over real HTTP (a local node server with the service's routes and error shape): the bearer key is
// sent, both parts are decoded and their sizes reported, and errors carry the server's reason.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { createServer } from 'node:http';
import { join } from 'node:path';
import { createEvaluator, fetchClipFile, fetchServiceClip, splitClipFile } from '../src/index.js';
import { FIXTURES, expected, manifest, readBytes } from './helpers.mjs';

const man = manifest();
const c = man.cases.find((x) => x.motion === 'rigid' && x.looping);
const file = readBytes(join(FIXTURES, c.clip));
const parts = splitClipFile(file);

function serve() {
  const seen = [];
  const server = createServer((req, res) => {
    seen.push({ url: req.url, auth: req.headers.authorization });
    const body = {
      '/v1/clips/abc/topology': parts.topology,
      '/v1/clips/abc/coefficients': parts.coefficients,
      '/v1/clips/wrong/topology': parts.coefficients,
      '/v1/clips/wrong/coefficients': parts.coefficients,
      '/files/x.clip': file,
    }[req.url];
    if (req.headers.authorization !== 'Bearer k1') {
      res.writeHead(401, { 'Content-Type': 'application/json' });
      res.end(JSON.stringify({ error: { code: 'unauthorized', message: 'unknown API key' } }));
    } else if (!body) {
      res.writeHead(404, { 'Content-Type': 'application/json' });
      res.end(JSON.stringify({ error: { code: 'not_found', message: 'no such clip' } }));
    } else {
      res.writeHead(200, { 'Content-Type': 'application/octet-stream' });
      res.end(Buffer.from(body));
    }
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve({ server, seen })));
}

test('fetchServiceClip downloads both parts with the key and evaluates like the fixture', async () => {
  const { server, seen } = await serve();
  try {
    const base = `http://127.0.0.1:${server.address().port}/`;
    const clip = await fetchServiceClip(base, 'abc', { key: 'k1' });
    assert.deepEqual(clip.bytes, {
      topology: parts.topology.length,
      coefficients: parts.coefficients.length,
    });
    assert.deepEqual(
      seen.map((s) => s.auth),
      ['Bearer k1', 'Bearer k1'],
    );
    const got = createEvaluator(clip).evaluate(c.t[3]);
    const want = expected(c).subarray(3 * got.length, 4 * got.length);
    assert.ok(got.every((v, i) => Math.abs(v - want[i]) <= 1e-6 * c.diagonal));
    const viaFile = await fetchClipFile(`${base}files/x.clip`, { key: 'k1' });
    assert.equal(viaFile.nVertices, clip.nVertices);
    await assert.rejects(fetchServiceClip(base, 'abc', { key: 'bad' }), /401: unknown API key/);
    await assert.rejects(fetchServiceClip(base, 'nope', { key: 'k1' }), /404: no such clip/);
    await assert.rejects(fetchServiceClip(base, 'wrong', { key: 'k1' }), /expected a topology part/);
  } finally {
    server.close();
  }
});
