// node tools/web/screenshot-tiles.mjs TILESET_DIR OUT.png EYE TARGET UP FOV WIDTH HEIGHT [LOOK]
// Serve TILESET_DIR and the page tiles/main.js (bundled with esbuild) on localhost, load it in
// Debian's headless Chromium (playwright-core), wait until the tiles the view needs are drawn and
// save the canvas as OUT.png. EYE, TARGET and UP are "x,y,z" in world units. Prints one JSON line
// (the models loaded so far, the tiles drawn and their triangles); exits 1 on any error. With
// several eyes ("x,y,z;x,y,z;..."): a fly-through, one view after another in one page (tiles
// loaded stay loaded), OUT a name with %d for the view's number, a JSON line a view. LOOK: silhouette (white on
// black, the default) or own (the tiles' own materials: a baked scan's lit colors).
import { createServer } from 'node:http';
import { readFile, writeFile } from 'node:fs/promises';
import { join, normalize, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';
import * as esbuild from 'esbuild';
import { chromium } from 'playwright-core';

const [tilesetDir, out, eye, target, up, fov, width, height, look] = process.argv.slice(2);
if (!height) {
  console.error('usage: screenshot-tiles.mjs TILESET_DIR OUT.png EYE TARGET UP FOV WIDTH HEIGHT [LOOK]');
  process.exit(2);
}
const here = dirname(fileURLToPath(import.meta.url));
const bundle = await esbuild.build({
  entryPoints: [join(here, 'tiles', 'main.js')],
  bundle: true, format: 'esm', write: false, logLevel: 'error',
});
const page = '<!doctype html><html><body style="margin:0;background:#000">' +
  '<script type="module" src="/main.js"></script></body></html>';
const types = { '.json': 'application/json', '.glb': 'model/gltf-binary' };
const server = createServer(async (request, response) => {
  const path = decodeURIComponent(new URL(request.url, 'http://localhost').pathname);
  try {
    if (path === '/') {
      response.writeHead(200, { 'content-type': 'text/html' }).end(page);
    } else if (path === '/main.js') {
      response.writeHead(200, { 'content-type': 'text/javascript' }).end(bundle.outputFiles[0].text);
    } else if (path.startsWith('/tiles/')) {
      const file = normalize(join(tilesetDir, path.slice('/tiles/'.length)));
      if (!file.startsWith(normalize(tilesetDir))) throw new Error('outside the tileset');
      const extension = file.slice(file.lastIndexOf('.'));
      response.writeHead(200, { 'content-type': types[extension] ?? 'application/octet-stream' })
        .end(await readFile(file));
    } else {
      response.writeHead(404).end();
    }
  } catch {
    response.writeHead(404).end();
  }
});
await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));
const address = `http://127.0.0.1:${server.address().port}`;
// As root, with this machine's closed network: no sandbox, no background connections; WebGL on
// the CPU (SwiftShader).
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM ?? '/usr/bin/chromium',
  args: ['--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
    '--disable-quic', '--no-first-run', '--disable-background-networking',
    '--disable-component-update', '--disable-sync'],
});
let failed = false;
try {
  const tab = await browser.newPage({ viewport: { width: Number(width), height: Number(height) } });
  const errors = [];
  tab.on('pageerror', (error) => errors.push(String(error)));
  const query = new URLSearchParams({ tileset: `${address}/tiles/tileset.json`, eye, target, up,
    fov, width, height, look: look ?? 'silhouette' });
  await tab.goto(`${address}/?${query}`);
  const first = await tab.waitForFunction(
    () => window.tilesReady ?? (window.tilesError ? { error: window.tilesError } : null),
    null, { timeout: 240000, polling: 250 });
  const views = eye.split(';').length;
  for (let i = 0; i < views; i++) {
    const ready = i === 0 ? first : await (async () => {
      await tab.evaluate((view) => window.view(view), i);
      return tab.waitForFunction(
        () => window.tilesReady ?? (window.tilesError ? { error: window.tilesError } : null),
        null, { timeout: 240000, polling: 250 });
    })();
    const result = await ready.jsonValue();
    if (result.error || errors.length) throw new Error(result.error ?? errors.join('; '));
    await writeFile(views > 1 ? out.replace('%d', String(i)) : out,
      await tab.locator('canvas').screenshot());
    console.log(JSON.stringify(views > 1 ? { view: i, ...result } : result));
  }
} catch (error) {
  console.error(`screenshot-tiles: ${error.message ?? error}`);
  failed = true;
} finally {
  await browser.close();
  server.close();
}
process.exit(failed ? 1 : 0);
