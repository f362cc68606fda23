#!/usr/bin/env node
// Serves the repository's scripts/web pages (or, with --dir, that folder's
// files), .tools/node/node_modules and one file over HTTP on localhost, opens
// PAGE?QUERY in headless Chromium (puppeteer-core, software WebGL), waits for
// the page's window.done and writes a PNG of the viewport (--full-page 1: the
// whole page). Console errors and requests for missing files fail the run.
//   node scripts/web/screenshot.cjs --page mesh_frame.html --file FILE --query 'frame=3&...'
//        --width W --height H --out PNG [--chromium /usr/bin/chromium]
//   node scripts/web/screenshot.cjs --dir ws/export --page report.html --width 1200 --height 900 --out PNG
const fs = require('fs');
const http = require('http');
const path = require('path');

const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const root = path.join(__dirname, '..', '..');
const modules = path.join(root, '.tools', 'node', 'node_modules');
const puppeteer = require(path.join(modules, 'puppeteer-core'));
const { kChromiumFlags } = require('./chromium.cjs');
const types = { '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript', '.glb': 'model/gltf-binary',
                '.json': 'application/json', '.wasm': 'application/wasm', '.ply': 'application/octet-stream' };

const missing = [];
const server = http.createServer((request, response) => {
  const url = decodeURIComponent(request.url.split('?')[0]);
  if (url === '/favicon.ico') { response.writeHead(204); response.end(); return; }
  let file = null;
  if (url.startsWith('/node_modules/')) file = path.join(modules, url.slice('/node_modules/'.length));
  else if (args.file && url === '/file' + path.extname(args.file)) file = args.file;
  else file = path.join(args.dir || __dirname, url.slice(1));
  fs.readFile(file, (error, data) => {
    if (error) { missing.push(url); response.writeHead(404); response.end(); return; }
    response.writeHead(200, { 'Content-Type': types[path.extname(file)] || 'application/octet-stream' });
    response.end(data);
  });
});

server.listen(0, '127.0.0.1', async () => {
  const port = server.address().port;
  const width = Number(args.width), height = Number(args.height);
  const browser = await puppeteer.launch({
    executablePath: args.chromium || '/usr/bin/chromium',
    headless: true,
    args: [...kChromiumFlags, '--disable-quic'],
  });
  const errors = [];
  let code = 0;
  try {
    const page = await browser.newPage();
    page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
    page.on('pageerror', (e) => errors.push(String(e)));
    await page.setViewport({ width, height, deviceScaleFactor: 1 });
    const fileQuery = args.file ? `file=/file${path.extname(args.file)}&` : '';
    const url = `http://127.0.0.1:${port}/${args.page}?${fileQuery}width=${width}&height=${height}&${args.query || ''}`;
    await page.goto(url);
    await page.waitForFunction('window.done || window.failed', { timeout: 120000 });
    const failed = await page.evaluate('window.failed');
    if (failed) throw new Error(failed);
    if (args['full-page'] === '1') await page.screenshot({ path: args.out, fullPage: true });
    else await page.screenshot({ path: args.out, clip: { x: 0, y: 0, width, height } });
    if (missing.length) throw new Error('missing files: ' + missing.join(', '));
    if (errors.length) throw new Error('console errors: ' + errors.join(' | '));
  } catch (error) {
    console.error(`screenshot: ${error.message || error}`);
    code = 1;
  }
  await browser.close();
  server.close();
  process.exit(code);
});
