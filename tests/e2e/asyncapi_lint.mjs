// SPDX-License-Identifier: GPL-3.0-or-later
// Lints the AsyncAPI document of the WebSocket stream as the server serves it (`sphles schema
// asyncapi`, with the OpenAPI components it refers to) with the AsyncAPI initiative's own parser
// (@asyncapi/parser, npm, pinned in package-lock.json): it validates the document against the
// AsyncAPI 3.0 meta-schema, resolves every $ref and applies its Spectral rule set. Every finding
// is printed; an error fails (exit 1).
// Usage: node asyncapi_lint.mjs ASYNCAPI.json
import { readFileSync } from 'node:fs';
import { Parser } from '@asyncapi/parser';

const file = process.argv[2];
if (!file) {
  console.error('usage: node asyncapi_lint.mjs ASYNCAPI.json');
  process.exit(2);
}
const severities = ['error', 'warning', 'info', 'hint'];
const diagnostics = await new Parser().validate(readFileSync(file, 'utf8'), { source: file });
for (const d of diagnostics)
  console.log(`${severities[d.severity] ?? d.severity} ${d.code} at ${d.path.join('.') || '(root)'}: ${d.message}`);
const errors = diagnostics.filter((d) => d.severity === 0).length;
console.log(`${file}: ${errors} error(s), ${diagnostics.length - errors} other finding(s)`);
process.exit(errors ? 1 : 0);
