// Usage: node validate.js FILE.glb
// Prints the Khronos glTF validator's report as JSON; exits 1 when it has errors.
const fs = require('fs');
const validator = require('gltf-validator');

const file = process.argv[2];
if (!file) {
  console.error('usage: node validate.js FILE.glb');
  process.exit(2);
}
const data = new Uint8Array(fs.readFileSync(file));
validator
  .validateBytes(data, { maxIssues: 100 })
  .then((report) => {
    console.log(JSON.stringify(report.issues, null, 2));
    process.exit(report.issues.numErrors > 0 ? 1 : 0);
  })
  .catch((e) => {
    console.error(String(e));
    process.exit(2);
  });
