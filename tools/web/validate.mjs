// node tools/web/validate.mjs FILE.glb...: the Khronos glTF validator on each file. Prints one
// JSON line per file (its issue counts and messages) and exits 1 when any file has an error.
import { readFile } from 'node:fs/promises';
import validator from 'gltf-validator';

let failed = false;
for (const path of process.argv.slice(2)) {
  const report = await validator.validateBytes(new Uint8Array(await readFile(path)), {
    uri: path,
    maxIssues: 100,
  });
  const { numErrors, numWarnings, numInfos, numHints, messages } = report.issues;
  failed ||= numErrors > 0;
  console.log(JSON.stringify({
    file: path,
    errors: numErrors,
    warnings: numWarnings,
    infos: numInfos,
    hints: numHints,
    messages: messages.map((m) => `${m.severity === 0 ? 'error' : m.severity === 1 ? 'warning' : 'info'} ${m.code} ${m.pointer ?? ''}: ${m.message}`),
  }));
}
process.exit(failed ? 1 : 0);
