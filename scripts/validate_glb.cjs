#!/usr/bin/env node
// Validates GLB files with the Khronos glTF validator (npm package `gltf-validator`, installed
// into scripts/node_modules by scripts/test.sh from scripts/package.json).
//
// Usage: node scripts/validate_glb.cjs FILE.glb...
// Prints one JSON line per file: {"file", "errors", "warnings", "infos", "hints", "messages"}
// (messages: every error and warning, "<code> at <pointer>: <message>"), then exits 1 when any
// file has an error, 2 on bad usage or when the validator cannot be loaded.
'use strict';

const fs = require('fs');
const path = require('path');

let validator;
try {
  validator = require('gltf-validator');
} catch (e) {
  console.error('validate_glb: cannot load the npm package gltf-validator (run `npm ci` in scripts/, as scripts/test.sh does): ' + e.message);
  process.exit(2);
}

async function main() {
  const files = process.argv.slice(2);
  if (files.length === 0) {
    console.error('usage: node scripts/validate_glb.cjs FILE.glb...');
    process.exit(2);
  }
  let failed = false;
  for (const file of files) {
    const bytes = new Uint8Array(fs.readFileSync(file));
    const report = await validator.validateBytes(bytes, {
      uri: path.basename(file),
      maxIssues: 0,
      externalResourceFunction: (uri) => Promise.reject(new Error('external resource ' + uri + ' (a GLB must be self-contained)')),
    });
    const issues = report.issues;
    const messages = issues.messages
      .filter((m) => m.severity <= 1)
      .map((m) => `${m.code} at ${m.pointer || m.offset || '/'}: ${m.message}`);
    const line = {
      file,
      errors: issues.numErrors,
      warnings: issues.numWarnings,
      infos: issues.numInfos,
      hints: issues.numHints,
      messages,
    };
    if (issues.numErrors > 0) {
      failed = true;
    }
    process.stdout.write(JSON.stringify(line) + '\n');
  }
  process.exit(failed ? 1 : 0);
}

main().catch((e) => {
  console.error('validate_glb: ' + (e && e.stack ? e.stack : e));
  process.exit(2);
});
