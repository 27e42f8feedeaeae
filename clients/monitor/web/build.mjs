// Builds the monitor's web app: bundles src/main.js (and three.js) with esbuild into
// <outdir>/app.js and copies index.html and style.css beside it. The output is a build product
// (clients/monitor/CMakeLists.txt puts it in <build>/share/cell-monitor/web); never commit it.
//   node build.mjs --outdir DIR [--dev]
import { existsSync } from 'node:fs';
import { copyFile, mkdir } from 'node:fs/promises';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const args = process.argv.slice(2);
const outIndex = args.indexOf('--outdir');
if (outIndex < 0 || !args[outIndex + 1]) {
  console.error('usage: node build.mjs --outdir DIR [--dev]');
  process.exit(2);
}
const outdir = args[outIndex + 1];
const dev = args.includes('--dev');
if (!existsSync(join(here, 'node_modules', 'esbuild')) || !existsSync(join(here, 'node_modules', 'three'))) {
  console.error(`build.mjs: ${join(here, 'node_modules')} is missing or incomplete: run ` +
    'scripts/install-deps.sh (it runs `npm ci` in clients/monitor/web)');
  process.exit(1);
}
const { build } = await import('esbuild');
await mkdir(outdir, { recursive: true });
try {
  await build({
    entryPoints: [join(here, 'src', 'main.js')],
    bundle: true,
    format: 'esm',
    target: ['es2022'],
    minify: !dev,
    sourcemap: true,
    legalComments: 'linked',
    outfile: join(outdir, 'app.js'),
    logLevel: 'warning',
  });
} catch (e) {
  console.error(`build.mjs: esbuild failed: ${e.message}`);
  process.exit(1);
}
for (const f of ['index.html', 'style.css']) await copyFile(join(here, 'src', f), join(outdir, f));
console.log(`build.mjs: web app built into ${outdir}`);
