// Usage: node validate-many.js FILE.glb...
// Prints {"FILE": {"numErrors": n, "numWarnings": n, "messages": [...]}, ...}
// for every file, the Khronos glTF validator's counts and its first
// error messages; exits 1 when any file has errors.
const fs = require('fs');
const validator = require('gltf-validator');

async function main(files) {
  const out = {};
  let errors = 0;
  for (const file of files) {
    const data = new Uint8Array(fs.readFileSync(file));
    const report = await validator.validateBytes(data, { maxIssues: 20 });
    const issues = report.issues;
    out[file] = {
      numErrors: issues.numErrors,
      numWarnings: issues.numWarnings,
      messages: issues.messages.filter((m) => m.severity === 0).map((m) => `${m.code}: ${m.message}`),
    };
    errors += issues.numErrors;
  }
  // Set the exit code rather than exiting, so a long report written to a
  // pipe is flushed whole.
  process.stdout.write(JSON.stringify(out, null, 2) + '\n');
  process.exitCode = errors > 0 ? 1 : 0;
}

const files = process.argv.slice(2);
if (files.length === 0) {
  console.error('usage: node validate-many.js FILE.glb...');
  process.exit(2);
}
main(files).catch((e) => {
  console.error(String(e));
  process.exit(2);
});
