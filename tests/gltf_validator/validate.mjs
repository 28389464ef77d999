// Validate glTF/GLB files with the Khronos glTF validator: `node validate.mjs FILE...` prints one
// JSON line per file, the validator's report ({issues: {numErrors, numWarnings, numInfos,
// messages: [{code, message, severity, pointer}]}, ...}); exits 1 where the validator could not
// read a file. Used by tests/addon/test_gltf_validator.py (`npm ci` here installs the validator).
import { readFile } from 'node:fs/promises';
import { validateBytes } from 'gltf-validator';

let status = 0;
for (const path of process.argv.slice(2)) {
  try {
    const report = await validateBytes(new Uint8Array(await readFile(path)), { uri: path });
    console.log(JSON.stringify(report));
  } catch (error) {
    console.error(`${path}: ${error}`);
    status = 1;
  }
}
process.exit(status);
