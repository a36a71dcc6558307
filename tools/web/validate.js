// Validate glTF files with the Khronos glTF-Validator; prints one JSON report per file (an array).
// Usage: node validate.js FILE...   (exit 0; the caller reads the reports' issues)
const fs = require("fs");
const path = require("path");
const validator = require("gltf-validator");

async function validate(file) {
  const data = new Uint8Array(fs.readFileSync(file));
  return validator.validateBytes(data, {
    uri: path.basename(file),
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.join(path.dirname(file), decodeURIComponent(uri)), (error, bytes) =>
          error ? reject(error.toString()) : resolve(new Uint8Array(bytes)));
      }),
  });
}

(async () => {
  const reports = [];
  for (const file of process.argv.slice(2)) reports.push(await validate(file));
  process.stdout.write(JSON.stringify(reports, null, 1) + "\n");
})().catch((error) => { console.error(error); process.exit(2); });
