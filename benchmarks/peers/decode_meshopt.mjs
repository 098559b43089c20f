// Rewrite a GLB that uses EXT_meshopt_compression or KHR_meshopt_compression as a plain GLB (every
// compressed buffer view decoded with meshoptimizer's own decoder), so the benchmark can read it with
// pdeanim's glTF reader and score it.
// Usage: node decode_meshopt.mjs IN.glb OUT.glb
import { readFileSync, writeFileSync } from 'node:fs';
import { MeshoptDecoder } from 'meshoptimizer';

const MESHOPT = ['EXT_meshopt_compression', 'KHR_meshopt_compression'];
const [input, output] = process.argv.slice(2);
const glb = readFileSync(input);
if (glb.readUInt32LE(0) !== 0x46546c67) throw new Error(`${input} is not a GLB`);
let offset = 12;
let json = null;
let bin = null;
while (offset < glb.length) {
  const len = glb.readUInt32LE(offset);
  const type = glb.readUInt32LE(offset + 4);
  const body = glb.subarray(offset + 8, offset + 8 + len);
  if (type === 0x4e4f534a) json = JSON.parse(body.toString('utf8'));
  else if (type === 0x004e4942) bin = body;
  offset += 8 + len;
}
await MeshoptDecoder.ready;
const parts = [];
let size = 0;
const views = json.bufferViews.map((view) => {
  const ext = view.extensions && (view.extensions.EXT_meshopt_compression || view.extensions.KHR_meshopt_compression);
  let data;
  if (ext) {
    const src = bin.subarray(ext.byteOffset || 0, (ext.byteOffset || 0) + ext.byteLength);
    data = new Uint8Array(ext.count * ext.byteStride);
    MeshoptDecoder.decodeGltfBuffer(data, ext.count, ext.byteStride, src, ext.mode, ext.filter || 'NONE');
  } else if (view.buffer === 0 && bin) {
    data = bin.subarray(view.byteOffset || 0, (view.byteOffset || 0) + view.byteLength);
  } else {
    data = new Uint8Array(view.byteLength); // a fallback-only buffer view: no data needed
  }
  const pad = (4 - (size % 4)) % 4;
  if (pad) { parts.push(new Uint8Array(pad)); size += pad; }
  const out = { buffer: 0, byteOffset: size, byteLength: data.length };
  if (ext && ext.byteStride && ext.mode === 'ATTRIBUTES') out.byteStride = ext.byteStride;
  else if (view.byteStride) out.byteStride = view.byteStride;
  if (view.target) out.target = view.target;
  parts.push(data);
  size += data.length;
  return out;
});
const pad = (4 - (size % 4)) % 4;
if (pad) { parts.push(new Uint8Array(pad)); size += pad; }
json.bufferViews = views;
json.buffers = [{ byteLength: size }];
for (const key of ['extensionsUsed', 'extensionsRequired']) {
  if (json[key]) json[key] = json[key].filter((e) => !MESHOPT.includes(e));
}
let text = Buffer.from(JSON.stringify(json), 'utf8');
text = Buffer.concat([text, Buffer.alloc((4 - (text.length % 4)) % 4, 0x20)]);
const binary = Buffer.concat(parts.map((p) => Buffer.from(p.buffer, p.byteOffset, p.byteLength)));
const header = Buffer.alloc(12);
header.writeUInt32LE(0x46546c67, 0);
header.writeUInt32LE(2, 4);
header.writeUInt32LE(12 + 8 + text.length + 8 + binary.length, 8);
const chunk = (type, body) => {
  const h = Buffer.alloc(8);
  h.writeUInt32LE(body.length, 0);
  h.writeUInt32LE(type, 4);
  return Buffer.concat([h, body]);
};
writeFileSync(output, Buffer.concat([header, chunk(0x4e4f534a, text), chunk(0x004e4942, binary)]));
