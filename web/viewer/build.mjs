// Bundles the viewer into dist/ (index.html, viewer.css, viewer.js): a static page that works
// from any HTTP root. The Protobuf schema is common/proto/recording.proto, embedded as text.
import * as esbuild from 'esbuild';
import { copyFileSync, mkdirSync, rmSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const dist = join(here, 'dist');
rmSync(dist, { recursive: true, force: true });
mkdirSync(dist, { recursive: true });

const result = await esbuild.build({
  entryPoints: [join(here, 'src', 'main.js')],
  bundle: true,
  format: 'iife',
  platform: 'browser',
  target: ['es2020'],
  minify: true,
  sourcemap: false,
  legalComments: 'eof',
  loader: { '.proto': 'text' },
  outfile: join(dist, 'viewer.js'),
  logLevel: 'warning',
  metafile: true,
});
for (const f of ['index.html', 'viewer.css']) copyFileSync(join(here, 'src', f), join(dist, f));
const bytes = Object.values(result.metafile.outputs).reduce((s, o) => s + o.bytes, 0);
console.log(`build-viewer: wrote ${dist} (${(bytes / 1024).toFixed(0)} KiB)`);
