#!/usr/bin/env node
// face-api's own face-recognition network (npm's @vladmandic/face-api under
// TensorFlow.js, installed by scripts/install_deps.sh into .tools/node) on
// face crops: the reference the LibTorch port (avatar/metrics/
// face_recognition.h) is tested against. Each crop: a 150x150 binary PPM
// (P6); its descriptor: 128 numbers.
//   node scripts/face_descriptors.cjs OUT.json CROP.ppm... [--modules DIR]
// OUT.json: {"backend": "wasm" or "cpu", "face_api": version, "descriptors": [[128 numbers], ...]}
const fs = require('fs');
const path = require('path');

const args = process.argv.slice(2);
const at = args.indexOf('--modules');
const modules = at >= 0 ? args[at + 1] : path.join(__dirname, '..', '.tools', 'node', 'node_modules');
const [outPath, ...crops] = args.filter((a, i) => a !== '--modules' && (at < 0 || i !== at + 1));
if (!outPath || crops.length === 0) {
  console.error('usage: face_descriptors.cjs OUT.json CROP.ppm... [--modules DIR]');
  process.exit(2);
}
const faceapi = require(path.join(modules, '@vladmandic', 'face-api', 'dist', 'face-api.node-wasm.js'));
const tf = faceapi.tf;
const modelDir = path.join(modules, '@vladmandic', 'face-api', 'model');

// A binary PPM: magic, width, height and maximum after whitespace (and
// comments), one whitespace byte, then the pixels.
function readPpm(file) {
  const bytes = fs.readFileSync(file);
  const fields = [];
  let i = 0;
  const space = (c) => c === 0x20 || c === 0x09 || c === 0x0a || c === 0x0d;
  while (fields.length < 4) {
    while (i < bytes.length && space(bytes[i])) i++;
    if (bytes[i] === 0x23) {
      while (i < bytes.length && bytes[i] !== 0x0a) i++;
      continue;
    }
    let field = '';
    while (i < bytes.length && !space(bytes[i])) field += String.fromCharCode(bytes[i++]);
    if (!field) throw new Error(file + ': not a PPM image');
    fields.push(field);
  }
  i++;
  const [magic, width, height, max] = [fields[0], +fields[1], +fields[2], +fields[3]];
  if (magic !== 'P6' || max !== 255 || bytes.length < i + width * height * 3)
    throw new Error(file + ': not an 8-bit binary PPM (P6) image');
  return tf.tensor3d(new Int32Array(bytes.subarray(i, i + width * height * 3)), [height, width, 3], 'int32');
}

(async () => {
  let backend = 'wasm';
  try {
    await tf.setBackend('wasm');
    await tf.ready();
  } catch (e) {
    backend = 'cpu';  // plain JavaScript: slower, the same network
    await tf.setBackend('cpu');
    await tf.ready();
  }
  const manifest = JSON.parse(fs.readFileSync(path.join(modelDir, 'face_recognition_model-weights_manifest.json'), 'utf8'));
  const data = Buffer.concat(manifest.flatMap((g) => g.paths.map((p) => fs.readFileSync(path.join(modelDir, p)))));
  const specs = manifest.flatMap((g) => g.weights);
  faceapi.nets.faceRecognitionNet.loadFromWeightMap(
    tf.io.decodeWeights(data.buffer.slice(data.byteOffset, data.byteOffset + data.length), specs));
  const descriptors = [];
  for (const crop of crops) {
    const image = readPpm(crop);
    descriptors.push(Array.from(await faceapi.nets.faceRecognitionNet.computeFaceDescriptor(image)));
    image.dispose();
  }
  const version = JSON.parse(fs.readFileSync(path.join(modules, '@vladmandic', 'face-api', 'package.json'), 'utf8')).version;
  fs.writeFileSync(outPath, JSON.stringify({ backend, face_api: version, descriptors }));
})().catch((e) => {
  console.error('face_descriptors: ' + e.message);
  process.exit(1);
});
