#!/usr/bin/env node
// Validates a .glb or .gltf with the Khronos glTF-Validator (npm's
// gltf-validator, installed by scripts/install_deps.sh into .tools/node).
// Prints the error and warning counts and every message; exits 1 when the
// validator reports an error. The validator does not know every extension:
// --extension-attributes NAME sets apart its "invalid attribute name" errors
// on attributes NAME defines ("NAME:..."), on a primitive or in its morph
// targets, which are reported but not counted.
//   node scripts/validate_gltf.cjs FILE [--validator DIR] [--extension-attributes NAME]
const fs = require('fs');
const path = require('path');

const args = process.argv.slice(2);
const file = args[0];
const at = args.indexOf('--validator');
const validatorDir = at >= 0 ? args[at + 1] : path.join(__dirname, '..', '.tools', 'node', 'node_modules', 'gltf-validator');
const ext = args.indexOf('--extension-attributes');
const extension = ext >= 0 ? args[ext + 1] : null;
if (!file) {
  console.error('usage: validate_gltf.cjs FILE [--validator DIR]');
  process.exit(2);
}
const validator = require(validatorDir);
validator
  .validateBytes(new Uint8Array(fs.readFileSync(file)), {
    maxIssues: 10000,
    // Extensions the validator does not know are reported as info, not errors.
    externalResourceFunction: () => Promise.reject(new Error('no external resources')),
  })
  .then((report) => {
    const issues = report.issues;
    // The extension's attributes on the primitive and in its morph targets.
    const setApart = (m) => extension && m.severity === 0 && m.code === 'MESH_PRIMITIVE_INVALID_ATTRIBUTE' &&
                            /\/(attributes|targets\/\d+)\//.test(m.pointer || '') &&
                            (m.pointer || '').includes(`/${extension}:`);
    const errors = issues.messages.filter((m) => m.severity === 0 && !setApart(m)).length;
    const apart = issues.messages.filter(setApart).length;
    console.log(`${path.basename(file)}: ${errors} errors, ${issues.numWarnings} warnings, ` +
                `${issues.numInfos} infos, ${issues.numHints} hints (glTF-Validator ${report.validatorVersion})` +
                (apart ? `; ${apart} attributes of ${extension}, which this validator does not know, set apart` : ''));
    for (const m of issues.messages.filter((m) => !setApart(m)))
      console.log(`  severity ${m.severity} ${m.code}: ${m.message} (${m.pointer || ''})`);
    process.exit(errors > 0 ? 1 : 0);
  })
  .catch((error) => {
    console.error(`${file}: the validator failed: ${error}`);
    process.exit(1);
  });
