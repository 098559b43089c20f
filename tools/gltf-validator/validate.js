#!/usr/bin/env node
// Validate GLB/glTF bytes with the Khronos glTF-Validator and print the report as JSON on stdout.
// Usage: node validate.js FILE.glb        -> one report object
//        node validate.js < FILE.glb      -> one report object (bytes read from stdin)
//        node validate.js A.glb B.glb ... -> a JSON array of reports, in argument order
// Exit status: 0 when a report was produced (whatever it says), 2 on unreadable input or validator failure.
'use strict';
const fs = require('fs');
const path = require('path');
const validator = require('gltf-validator');

function readStdin() {
  const chunks = [];
  let chunk;
  const buf = Buffer.alloc(1 << 16);
  for (;;) {
    let n;
    try {
      n = fs.readSync(0, buf, 0, buf.length, null);
    } catch (e) {
      if (e.code === 'EAGAIN') continue;
      if (e.code === 'EOF') break;
      throw e;
    }
    if (n === 0) break;
    chunk = Buffer.from(buf.subarray(0, n));
    chunks.push(chunk);
  }
  return Buffer.concat(chunks);
}

function validate(bytes, uri) {
  return validator.validateBytes(new Uint8Array(bytes), {
    uri: uri,
    maxIssues: 0, // report every issue
    writeTimestamp: false,
    externalResourceFunction: (ref) => Promise.reject(new Error(`external resources are not allowed: ${ref}`)),
  });
}

async function main() {
  const args = process.argv.slice(2);
  if (args.length === 0 || (args.length === 1 && args[0] === '-')) {
    const report = await validate(readStdin(), 'stdin.glb');
    process.stdout.write(JSON.stringify(report));
    return;
  }
  const reports = [];
  for (const file of args) {
    reports.push(await validate(fs.readFileSync(file), path.basename(file)));
  }
  process.stdout.write(JSON.stringify(args.length === 1 ? reports[0] : reports));
}

main().catch((err) => {
  process.stderr.write(`validate.js: ${err && err.stack ? err.stack : err}\n`);
  process.exit(2);
});
