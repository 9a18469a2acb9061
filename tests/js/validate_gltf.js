// Validates .glb files with the Khronos glTF validator (npm `gltf-validator`) and prints one JSON
// line per file: {"file", "errors", "warnings", "infos", "messages": [...]}. Exit 0 when it ran.
// Usage: NODE_PATH=<dir>/node_modules node validate_gltf.js a.glb [b.glb ...]
const fs = require('fs');
const validator = require('gltf-validator');

(async () => {
  for (const file of process.argv.slice(2)) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), { maxIssues: 100 });
    const issues = report.issues;
    console.log(JSON.stringify({
      file,
      errors: issues.numErrors,
      warnings: issues.numWarnings,
      infos: issues.numInfos,
      messages: issues.messages.filter((m) => m.severity <= 1).map((m) => `${m.code}: ${m.message} (${m.pointer || ''})`),
    }));
  }
})().catch((e) => { console.error(e); process.exit(2); });
