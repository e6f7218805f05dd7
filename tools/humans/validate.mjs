// Validate every .glb in data/humans with the Khronos glTF validator (npm gltf-validator).
// Usage: node tools/humans/validate.mjs [dir]   -- exits 1 if any file has an error.
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import validator from 'gltf-validator';

const here = path.dirname(fileURLToPath(import.meta.url));
const dir = process.argv[2] || path.join(here, '..', '..', 'data', 'humans');
const files = fs.readdirSync(dir).filter((f) => f.endsWith('.glb')).sort();
if (files.length === 0) {
  console.error(`no .glb files in ${dir}`);
  process.exit(1);
}
let bad = 0;
for (const f of files) {
  const data = new Uint8Array(fs.readFileSync(path.join(dir, f)));
  const r = await validator.validateBytes(data, { uri: f, maxIssues: 100 });
  const n = r.issues;
  console.log(`${f}: errors ${n.numErrors}, warnings ${n.numWarnings}, infos ${n.numInfos}, hints ${n.numHints}`);
  for (const m of n.messages.slice(0, 10)) {
    if (m.severity <= 1) console.log(`  [${m.severity === 0 ? 'ERROR' : 'WARN'}] ${m.code} ${m.pointer || ''}: ${m.message}`);
  }
  if (n.numErrors > 0) bad++;
}
console.log(`${files.length - bad} passed, ${bad} failed`);
process.exit(bad ? 1 : 0);
