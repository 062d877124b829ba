// Validates every .glb under the given folders with the Khronos glTF validator (npm
// `gltf-validator`). Prints one line per file and exits non-zero if any file has an error.
//
//   node .ci/validate_glb.mjs out/simulate [more folders or files...]
import { readFileSync, readdirSync, statSync } from 'node:fs';
import { join } from 'node:path';
import { createRequire } from 'node:module';

const require = createRequire(import.meta.url);
const validator = require('gltf-validator');

function walk(path, found) {
  if (statSync(path).isDirectory()) {
    for (const name of readdirSync(path).sort()) walk(join(path, name), found);
  } else if (path.endsWith('.glb')) {
    found.push(path);
  }
  return found;
}

const files = process.argv.slice(2).flatMap((p) => walk(p, []));
if (files.length === 0) {
  console.error('validate_glb: no .glb files found under', process.argv.slice(2).join(' '));
  process.exit(1);
}
let failed = 0;
for (const file of files) {
  const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), {
    uri: file,
    maxIssues: 50,
  });
  const { numErrors, numWarnings, numInfos } = report.issues;
  console.log(`${file}: ${numErrors} errors, ${numWarnings} warnings, ${numInfos} infos`);
  for (const m of report.issues.messages.filter((m) => m.severity === 0).slice(0, 10)) {
    console.log(`  error ${m.code} at ${m.pointer}: ${m.message}`);
  }
  if (numErrors > 0) failed++;
}
console.log(`glTF validator: ${files.length - failed} of ${files.length} files without errors`);
process.exit(failed ? 1 : 0);
