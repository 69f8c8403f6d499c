// End-to-end test of the live viewer in headless Chromium (Debian's package,
// driven by playwright-core): the page served by palpate-viewer must draw
// the organ, move it when palpate-pliers presses it, draw the contact, and
// let it go back to rest when the tool leaves. Screenshots go to --out.
//
// Started by tests/viewer/viewer_e2e.sh inside a private network namespace, with
// palpated and palpate-viewer already running.
//
//   node viewer_e2e.mjs --url URL --pliers PATH --gesture TOML --model ID --out DIR

import { spawn } from 'node:child_process';
import { mkdirSync } from 'node:fs';
import { request } from 'node:http';
import { connect } from 'node:net';
import { join } from 'node:path';
import { parseArgs } from 'node:util';
import { chromium } from 'playwright-core';

const { values: args } = parseArgs({
  options: {
    url: { type: 'string' }, pliers: { type: 'string' }, gesture: { type: 'string' },
    model: { type: 'string' }, out: { type: 'string' },
    chromium: { type: 'string', default: process.env.PALPATE_CHROMIUM || '/usr/bin/chromium' },
  },
});
for (const key of ['url', 'pliers', 'gesture', 'model', 'out'])
  if (!args[key]) { console.error(`viewer_e2e: --${key} is required`); process.exit(2); }
mkdirSync(args.out, { recursive: true });

// Tolerances, each with its reason.
const MIN_ORGAN_PIXELS = 0.05;     // the organ covers at least 5 % of the canvas at rest
const PRESS_DEPTH_M = 0.001;       // steady-press goes 3-5 mm deep: the drawn organ moves > 1 mm
const FLOAT32_M = 1e-6;            // positions travel as float32: 1 µm on a 0.1 m organ
const MIN_CHANGED_PIXELS = 0.005;  // pressing changes at least 0.5 % of the pixels
const REST_M = 1e-6;               // back at rest: every drawn vertex within 1 µm of its rest position
const TIMEOUT_MS = 20000;

let failures = 0;
function check(condition, what, detail) {
  console.log(`${condition ? 'ok  ' : 'FAIL'} ${what}${detail === undefined ? '' : `: ${detail}`}`);
  if (!condition) failures += 1;
}

// A downsampled grey image of the WebGL canvas (its drawing buffer is preserved).
async function grab(page) {
  return page.evaluate(() => {
    const source = document.getElementById('scene');
    const w = 160, h = 100, c = document.createElement('canvas');
    c.width = w; c.height = h;
    const g = c.getContext('2d');
    g.drawImage(source, 0, 0, w, h);
    const rgba = g.getImageData(0, 0, w, h).data;
    const grey = [];
    for (let i = 0; i < rgba.length; i += 4) grey.push((rgba[i] + rgba[i + 1] + rgba[i + 2]) / 3);
    return grey;
  });
}
const BACKGROUND_GREY = (0x1d + 0x21 + 0x27) / 3;
const share = (grey, keep) => grey.filter(keep).length / grey.length;

// The largest distance between a drawn compliance vertex and its rest
// position, read back from the geometry the renderer draws.
async function drawnDisplacement(page) {
  return page.evaluate(() => window.palpateViewer.drawnDisplacement());
}

// One raw HTTP request (no URL normalisation): { status, type }.
function raw(method, path, headers = {}) {
  const { hostname, port } = new URL(args.url);
  return new Promise((resolve) => {
    const r = request({ hostname, port, method, path, headers }, (res) => {
      res.resume();
      resolve({ status: res.statusCode, type: res.headers['content-type'] || '' });
    });
    r.on('upgrade', (res, socket) => { socket.destroy(); resolve({ status: res.statusCode, type: '' }); });
    r.on('error', (e) => resolve({ status: 0, type: e.message }));
    r.end();
  });
}

// 0. The bridge serves the page and three.js, and nothing else.
{
  const three = await raw('GET', '/vendor/three/build/three.module.js');
  check(three.status === 200 && three.type.startsWith('text/javascript'), 'three.js is served', `${three.status} ${three.type}`);
  for (const path of ['/../CMakeLists.txt', '/vendor/three/../../package.json', '/%2e%2e/CMakeLists.txt', '/missing.js'])
    check((await raw('GET', path)).status === 404, `${path} is not served`);
  check((await raw('POST', '/')).status === 405, 'POST is refused');
  const upgrade = { Connection: 'Upgrade', Upgrade: 'websocket', 'Sec-WebSocket-Version': '13',
                    'Sec-WebSocket-Key': 'dGhlIHNhbXBsZSBub25jZQ==' };
  check((await raw('GET', '/ws', { ...upgrade, Origin: 'http://evil.example' })).status === 403,
    'a WebSocket from another origin is refused');
  check((await raw('GET', '/ws', upgrade)).status === 101, 'a WebSocket without an origin is accepted');
  // Garbage instead of HTTP: the connection is dropped, the bridge goes on
  // (the page below is served by the same process).
  const { hostname, port } = new URL(args.url);
  await new Promise((resolve) => {
    const socket = connect(Number(port), hostname, () => socket.end('\x00\xffNOT HTTP\r\n\r\n'.repeat(64)));
    socket.on('close', resolve);
    socket.on('error', resolve);
    socket.resume();
  });
  check((await raw('GET', '/')).status === 200, 'still serving after garbage');
}

const browser = await chromium.launch({
  executablePath: args.chromium,
  args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
         '--disable-background-networking', '--disable-component-update', '--disable-sync',
         '--no-first-run', '--disable-quic'],
});
let pliers = null;
try {
  const page = await browser.newPage({ viewport: { width: 1000, height: 640 } });
  const errors = [];
  page.on('pageerror', (e) => errors.push(e.message));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  await page.goto(`${args.url}?model=${encodeURIComponent(args.model)}&fps=30&follow=0`);  // a still camera: pixels change only with the scene

  // 1. The organ is drawn, at rest.
  await page.waitForFunction(() => {
    const v = window.palpateViewer;
    return v && v.connected && v.vertexCount > 0 && v.surfacesReceived > 0 && v.framesRendered > 1;
  }, null, { timeout: TIMEOUT_MS });
  await page.waitForTimeout(300);
  const rest = await page.evaluate(() => ({ ...window.palpateViewer }));
  check(rest.modelId === args.model, 'the page shows the model', rest.modelId);
  check(rest.triangleCount > 0 && rest.vertexCount >= rest.complianceVertexCount,
    'the description arrived', `${rest.vertexCount} vertices, ${rest.triangleCount} triangles`);
  const restImage = await grab(page);
  const organPixels = share(restImage, (g) => Math.abs(g - BACKGROUND_GREY) > 12);
  check(organPixels > MIN_ORGAN_PIXELS, 'the organ is drawn', `${(100 * organPixels).toFixed(1)} % of the canvas`);
  const restDrawn = await drawnDisplacement(page);
  check(restDrawn < REST_M, 'at rest before the press', `${restDrawn.toExponential(2)} m`);
  await page.screenshot({ path: join(args.out, 'viewer-rest.png') });

  // 2. A scripted tool presses: the organ moves under it.
  pliers = spawn(args.pliers, [args.gesture, '--model', args.model, '--tool', 'left', '-q'],
                 { stdio: ['ignore', 'inherit', 'inherit'] });
  const pliersDone = new Promise((resolve) => pliers.on('exit', (code, signal) => resolve({ code, signal })));
  await page.waitForFunction((depth) => {
    const v = window.palpateViewer, left = v.tools.left;
    return left && left.state === 'touching' && v.maxDisplacement_m > depth && v.contacts > 0;
  }, PRESS_DEPTH_M, { timeout: TIMEOUT_MS });
  await page.waitForTimeout(300);  // a few frames
  // One evaluation: the state and the drawn geometry of the same frame.
  const pressed = await page.evaluate(() => ({ ...window.palpateViewer, drawn: window.palpateViewer.drawnDisplacement() }));
  const pressedDrawn = pressed.drawn;
  check(pressedDrawn > PRESS_DEPTH_M, 'the drawn organ moves under the tool', `${(pressedDrawn * 1000).toFixed(2)} mm`);
  check(Math.abs(pressedDrawn - pressed.maxDisplacement_m) < FLOAT32_M,
    'the drawn displacement is the streamed one', `${pressedDrawn} vs ${pressed.maxDisplacement_m} m`);
  check(pressed.contacts > 0, 'contact points are drawn', pressed.contacts);
  check(pressed.source === 'tool:left', 'the state comes from the tool', pressed.source);
  const left = pressed.tools.left;
  check(Math.hypot(...left.force) > 0, 'the tool feels a force', `${Math.hypot(...left.force).toFixed(3)} N`);
  const pressedImage = await grab(page);
  const changed = share(pressedImage.map((g, i) => Math.abs(g - restImage[i])), (d) => d > 12);
  check(changed > MIN_CHANGED_PIXELS, 'the picture changes', `${(100 * changed).toFixed(1)} % of the pixels`);
  await page.screenshot({ path: join(args.out, 'viewer-press.png') });

  // 3. The tool goes away (its client is stopped: the daemon's watchdog
  //    ramps the contact out); the organ returns to rest.
  pliers.kill('SIGTERM');
  await pliersDone;
  pliers = null;
  await page.waitForFunction((rest) => window.palpateViewer.drawnDisplacement() < rest, REST_M,
                             { timeout: TIMEOUT_MS }).catch(() => {});
  const after = await drawnDisplacement(page);
  check(after < REST_M, 'back at rest once the tool is gone', `${after.toExponential(2)} m`);
  await page.screenshot({ path: join(args.out, 'viewer-after.png') });

  const status = await page.evaluate(() => window.palpateViewer.status);
  check(status && status.daemon && status.daemon.models === 1, 'the daemon status reaches the page');
  check(errors.length === 0, 'no errors in the page', errors.join(' | '));
} catch (e) {
  console.log(`FAIL ${e.message}`);
  failures += 1;
} finally {
  if (pliers) pliers.kill('SIGKILL');
  await browser.close();
}
console.log(failures === 0 ? 'viewer_e2e: all checks passed' : `viewer_e2e: ${failures} check(s) failed`);
console.log(`viewer_e2e: screenshots in ${args.out}`);
process.exit(failures === 0 ? 0 : 1);
