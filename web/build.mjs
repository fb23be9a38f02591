// Bundles the report page's code (web/report/main.js) with the parts of three.js it imports into
// one minified script, the file given as the first argument (apps/CMakeLists.txt embeds it).
import * as esbuild from 'esbuild';
import { fileURLToPath } from 'node:url';
import { dirname, join } from 'node:path';

const here = dirname(fileURLToPath(import.meta.url));
await esbuild.build({
  entryPoints: [join(here, 'report', 'main.js')],
  bundle: true,
  minify: true,
  format: 'iife',
  target: 'es2020',
  legalComments: 'eof',
  logLevel: 'warning',
  outfile: process.argv[2],
});
