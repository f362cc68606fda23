#!/usr/bin/env node
// Runs a TensorFlow.js graph model (model.json and its weight shards) with
// TensorFlow.js itself (npm's @tensorflow/tfjs and its WebAssembly backend,
// installed by scripts/install_deps.sh into .tools/node): the reference the
// LibTorch graph runner (vision/graph_model.h) is tested against.
//   node scripts/tfjs_graph.cjs MODEL.json OUT_DIR NAME=FILE:D0xD1x... ... [--outputs A,B] [--backend wasm|cpu]
// Each input: a placeholder's name, a file of little-endian float32 values and
// its shape. Writes OUT_DIR/outputs.json ({"backend", "tfjs", "outputs":
// [{"name", "shape", "file"}]}) and one float32 file per output.
const fs = require('fs');
const path = require('path');

const args = process.argv.slice(2);
let modules = path.join(__dirname, '..', '.tools', 'node', 'node_modules');
let wantedOutputs = null;
let backend = 'wasm';
const positional = [];
for (let i = 0; i < args.length; i++) {
  if (args[i] === '--modules') modules = args[++i];
  else if (args[i] === '--outputs') wantedOutputs = args[++i].split(',');
  else if (args[i] === '--backend') backend = args[++i];
  else positional.push(args[i]);
}
const [modelPath, outDir, ...inputSpecs] = positional;
if (!modelPath || !outDir) {
  console.error('usage: tfjs_graph.cjs MODEL.json OUT_DIR NAME=FILE:D0xD1x... [--outputs A,B] [--backend wasm|cpu]');
  process.exit(2);
}
const tf = require(path.join(modules, '@tensorflow', 'tfjs'));
require(path.join(modules, '@tensorflow', 'tfjs-backend-wasm'));

function readInput(spec) {
  const eq = spec.indexOf('=');
  const colon = spec.lastIndexOf(':');
  if (eq < 0 || colon < eq) throw new Error('bad input ' + spec + ' (NAME=FILE:D0xD1x...)');
  const name = spec.slice(0, eq);
  const file = spec.slice(eq + 1, colon);
  const dims = spec.slice(colon + 1);
  const shape = dims === '' ? [] : dims.split('x').map(Number);
  const bytes = fs.readFileSync(file);
  const values = new Float32Array(bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.length));
  return [name, tf.tensor(values, shape, 'float32')];
}

(async () => {
  try {
    await tf.setBackend(backend);
    await tf.ready();
  } catch (e) {
    backend = 'cpu';  // plain JavaScript: slower, the same graph
    await tf.setBackend('cpu');
    await tf.ready();
  }
  const json = JSON.parse(fs.readFileSync(modelPath, 'utf8'));
  const dir = path.dirname(modelPath);
  const data = Buffer.concat(json.weightsManifest.flatMap((g) => g.paths.map((p) => fs.readFileSync(path.join(dir, p)))));
  const artifacts = {
    modelTopology: json.modelTopology,
    format: json.format,
    generatedBy: json.generatedBy,
    convertedBy: json.convertedBy,
    signature: json.signature,
    userDefinedMetadata: json.userDefinedMetadata,
    weightSpecs: json.weightsManifest.flatMap((g) => g.weights),
    weightData: data.buffer.slice(data.byteOffset, data.byteOffset + data.length),
  };
  const model = await tf.loadGraphModel(tf.io.fromMemory(artifacts));
  const feeds = {};
  for (const spec of inputSpecs) {
    const [name, tensor] = readInput(spec);
    feeds[name] = tensor;
  }
  const names = wantedOutputs || model.outputNodes;
  let results = await model.executeAsync(feeds, names);
  if (!Array.isArray(results)) results = [results];
  fs.mkdirSync(outDir, { recursive: true });
  const outputs = [];
  for (let i = 0; i < results.length; i++) {
    const values = await results[i].data();
    const file = path.join(outDir, 'output_' + i + '.f32');
    fs.writeFileSync(file, Buffer.from(new Float32Array(values).buffer));
    outputs.push({ name: names[i], shape: results[i].shape, file });
  }
  fs.writeFileSync(path.join(outDir, 'outputs.json'), JSON.stringify({ backend, tfjs: tf.version.tfjs, outputs }));
})().catch((e) => {
  console.error('tfjs_graph: ' + e.message);
  process.exit(1);
});
