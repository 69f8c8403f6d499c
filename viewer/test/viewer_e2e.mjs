// End-to-end test of the live viewer in headless Chromium (Debian's package,
// driven by playwright-core): the page served by palpate-viewer must draw
// the organ at rest first, framed whole with its attachment in sight, say
// what its legend means, exaggerate the drawn shape by the asked factor (and
// only the shape), move the organ when palpate-pliers presses it, draw the
// tool's contact points where the surface stream puts them (a request's
// constrained vertex otherwise; the vertices the jaws hold as cubes), let
// it go back to rest when the tool leaves, and show a page that
// opens after palpated stopped the rest shape, not palpated's last state.
// Screenshots go to --out.
//
// Started by tests/viewer/viewer_e2e.sh inside a private network namespace, with
// palpated and palpate-viewer already running.
//
//   node viewer_e2e.mjs --url URL --pliers PATH --client PATH --gesture TOML --model ID
//                       --vertex ID --palpated-pid PID --out DIR
//
// --vertex: a free surface vertex (mesh id) for palpate-client's requests;
// --palpated-pid: the test stops palpated (SIGTERM) at the end.

import { execFile, spawn } from 'node:child_process';
import { mkdirSync } from 'node:fs';
import { request } from 'node:http';
import { connect } from 'node:net';
import { dirname, join } from 'node:path';
import { parseArgs } from 'node:util';
import { chromium } from 'playwright-core';

const { values: args } = parseArgs({
  options: {
    url: { type: 'string' }, pliers: { type: 'string' }, client: { type: 'string' }, gesture: { type: 'string' },
    model: { type: 'string' }, vertex: { type: 'string' }, 'palpated-pid': { type: 'string' }, out: { type: 'string' },
    chromium: { type: 'string', default: process.env.PALPATE_CHROMIUM || '/usr/bin/chromium' },
  },
});
for (const key of ['url', 'pliers', 'client', 'gesture', 'model', 'vertex', 'palpated-pid', 'out'])
  if (!args[key]) { console.error(`viewer_e2e: --${key} is required`); process.exit(2); }
mkdirSync(args.out, { recursive: true });

// Tolerances, each with its reason.
const MIN_ORGAN_PIXELS = 0.05;     // the organ covers at least 5 % of the canvas at rest
const PRESS_DEPTH_M = 0.001;       // steady-press goes 3-5 mm deep: the drawn organ moves > 1 mm
const FLOAT32_M = 1e-6;            // positions travel as float32: 1 µm on a 0.1 m organ
const MIN_CHANGED_PIXELS = 0.005;  // pressing changes at least 0.5 % of the pixels
const REST_M = 1e-6;               // back at rest: every drawn vertex within 1 µm of its rest position
const REQUEST_M = 0.002;           // palpate-client imposes 2 mm at --vertex
const REQUEST_SEEN_M = 0.0015;     // ... so the streamed maximum is at least that (2 mm, less float32)
// Drawn = rest + factor × displacement, stored as float32: a coordinate of a
// 0.1 m organ rounds by ≤ 7.5e-9 m, and comparing ×5 with 5 × (×1) adds six
// such roundings: 1e-7 m bounds it with room, 20 µm below the 4 × 2 mm
// difference it must tell apart.
const EXAGGERATED_M = 1e-7;
const COLOUR = 1e-6;               // same frame, same arithmetic: colours agree to float32 rounding
const NDC = 1e-9;                  // projected corners: inside [-1, 1] up to double rounding
const MIN_FILL = 0.5;              // the framed box spans ≥ half the free view along its tighter axis
const MIN_ATTACHED_FACING = 0.5;   // most attached vertices face the camera: the attachment is in sight
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

// Runs palpate-client request on the model with extra arguments; resolves to its output.
function clientRequest(...extra) {
  return new Promise((resolve, reject) => {
    execFile(args.client, ['request', '--model', args.model, ...extra], (error, stdout, stderr) => {
      if (error || !/request \d+: ok/.test(stdout)) reject(new Error(`palpate-client request ${extra.join(' ')}: ${stdout}${stderr}`));
      else resolve(stdout);
    });
  });
}
const displace = () => clientRequest('--displacement', `${args.vertex}:0,0,${-REQUEST_M}`);
const restRequest = () => clientRequest();  // no constraint: the organ back at rest

// Until page's state came from palpate-client (not a tool) and shows at least
// depth, or (depth 0) is back at rest.
async function waitForRequestState(page, depth) {
  await page.waitForFunction((d) => {
    const v = window.palpateViewer;
    return d > 0 ? v.source !== '' && !v.source.startsWith('tool:') && v.maxDisplacement_m > d
                 : v.maxDisplacement_m === 0 && v.drawnDisplacement() === 0;
  }, depth, { timeout: TIMEOUT_MS });
}

// What a page drew, in one evaluation so that every field is of one frame.
async function drawnFrame(page) {
  return page.evaluate(() => {
    const v = window.palpateViewer;
    return { sequence: v.lastSequence, factor: v.exaggeration, positions: v.drawnPositions(), rest: v.restPositions(),
             displacement: v.trueDisplacement(), colours: v.vertexColours(), scale: v.colourScale_m,
             ns: v.complianceVertexCount, max: v.maxDisplacement_m };
  });
}

// The largest |drawn − (rest + factor × displacement)| over the free vertices.
function exaggerationError(d, factor) {
  let worst = 0;
  for (let i = 0; i < 3 * d.ns; ++i)
    worst = Math.max(worst, Math.abs(d.positions[i] - (d.rest[i] + factor * d.displacement[i])));
  return worst;
}
const largestDifference = (a, b) => a.reduce((m, x, i) => Math.max(m, Math.abs(x - b[i])), a.length === b.length ? 0 : Infinity);

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
const errors = [];
const query = (extra = '') => `${args.url}?model=${encodeURIComponent(args.model)}&fps=30&follow=0${extra}`;  // a still camera
async function openPage(url) {
  const page = await browser.newPage({ viewport: { width: 1000, height: 640 } });
  page.on('pageerror', (e) => errors.push(e.message));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  await page.goto(url);
  await page.waitForFunction(() => {
    const v = window.palpateViewer;
    return v && v.connected && v.vertexCount > 0 && v.firstOrganFrame !== null && v.framesRendered > 1;
  }, null, { timeout: TIMEOUT_MS });
  return page;
}
const text = (page, selector) => page.evaluate((s) => document.querySelector(s).textContent, selector);
const shown = (page, selector) => page.evaluate((s) => !document.querySelector(s).hidden, selector);

try {
  // 1. The organ is drawn, at rest, from its first frame on.
  const page = await openPage(query());
  await page.waitForFunction(() => window.palpateViewer.surfacesReceived > 0, null, { timeout: TIMEOUT_MS });
  await page.waitForTimeout(300);
  const rest = await page.evaluate(() => ({ ...window.palpateViewer }));
  check(rest.modelId === args.model, 'the page shows the model', rest.modelId);
  check(rest.triangleCount > 0 && rest.vertexCount >= rest.complianceVertexCount,
    'the description arrived', `${rest.vertexCount} vertices, ${rest.triangleCount} triangles`);
  check(rest.firstOrganFrame.maxOffset_m <= REST_M, 'the first frame drawn is the rest shape',
    `${rest.firstOrganFrame.maxOffset_m.toExponential(2)} m off`);
  const restImage = await grab(page);
  const organPixels = share(restImage, (g) => Math.abs(g - BACKGROUND_GREY) > 12);
  check(organPixels > MIN_ORGAN_PIXELS, 'the organ is drawn', `${(100 * organPixels).toFixed(1)} % of the canvas`);
  const restDrawn = await drawnDisplacement(page);
  check(restDrawn < REST_M, 'at rest before the press', `${restDrawn.toExponential(2)} m`);
  await page.screenshot({ path: join(args.out, 'viewer-rest.png') });

  // 2. The camera holds the whole organ, clear of the panel, not from afar,
  //    and sees the attachment. The frustum is convex: with the 8 corners of
  //    the box of every drawn vertex inside it, so is every vertex.
  const view = await page.evaluate(() => ({ corners: window.palpateViewer.projectedBoxCorners(),
    left: window.palpateViewer.freeNdcLeft(), facing: window.palpateViewer.attachedFacingCamera(),
    fixed: window.palpateViewer.fixedMarkers }));
  const inside = view.corners.every(([x, y, z]) => x >= view.left - NDC && x <= 1 + NDC && Math.abs(y) <= 1 + NDC && Math.abs(z) <= 1 + NDC);
  check(inside, 'every corner of the organ\'s box is in view, right of the panel',
    view.corners.map((c) => `(${c.map((v) => v.toFixed(2)).join(', ')})`).join(' '));
  const centreX = (view.left + 1) / 2, halfX = (1 - view.left) / 2;
  const fill = Math.max(...view.corners.map(([x, y]) => Math.max(Math.abs(x - centreX) / halfX, Math.abs(y))));
  check(fill >= MIN_FILL, 'the organ fills the view', `${(100 * fill).toFixed(0)} % of the free half-extent`);
  check(view.fixed === rest.vertexCount - rest.complianceVertexCount && view.fixed > 0,
    'every attached vertex has a marker', view.fixed);
  check(view.facing >= MIN_ATTACHED_FACING, 'the attachment faces the camera', `${(100 * view.facing).toFixed(0)} % of its vertices`);

  // 3. The legend says what its numbers are.
  const meaning = await text(page, '#legend-meaning');
  check(/peak-hold/.test(meaning) && /halves every 3 s/.test(meaning) && /"max now" is the largest displacement in the frame/.test(meaning),
    'the legend explains the peak-hold scale and "max now"', meaning);
  check((await text(page, '#legend-max')).startsWith('peak-hold '), 'the scale is labelled peak-hold');
  check((await text(page, '#exaggeration-state')).startsWith('shape true (×1)'), 'the page says the shape is true');

  // 3b. A model palpated does not serve: the page says so and names the served one.
  const wrong = await browser.newPage({ viewport: { width: 1000, height: 640 } });
  await wrong.goto(`${args.url}?model=livr`);
  await wrong.waitForFunction(() => /not served/.test(document.querySelector('#model').textContent),
    null, { timeout: TIMEOUT_MS }).catch(() => {});
  const notServed = await text(wrong, '#model');
  check(notServed === `model 'livr' is not served by palpated; served: ${args.model} (change ?model= in the address)`,
    'a model palpated does not serve is named with the served ones', notServed);
  await wrong.close();

  // 4. A factor that is not offered: ×1, said on the page, and no error.
  const odd = await openPage(query('&exaggerate=7'));
  const oddView = await odd.evaluate(() => window.palpateViewer.exaggeration);
  const warning = await text(odd, '#exaggeration-warning');
  check(oddView === 1 && (await shown(odd, '#exaggeration-warning')) && warning.includes('exaggerate=7'),
    '?exaggerate=7 falls back to ×1 with a note', `×${oddView}: ${warning}`);
  await odd.close();

  // 5. ×5 against ×1 on the same streamed displacement (a static state set
  //    by one request, so both pages end on the same sample).
  const five = await openPage(query('&exaggerate=5'));
  check((await text(five, '#exaggeration-state')).startsWith('shape ×5 exaggerated; colours'), 'the page says the shape is ×5');
  await displace();
  await Promise.all([waitForRequestState(page, REQUEST_SEEN_M), waitForRequestState(five, REQUEST_SEEN_M)]);
  const one = await drawnFrame(page), x5 = await drawnFrame(five);
  const requestMarkers = await page.evaluate(() => ({ points: window.palpateViewer.contactPoints, loads: window.palpateViewer.vertexLoads }));
  check(requestMarkers.points === 0 && requestMarkers.loads === 1,
    'a request\'s state draws its constrained vertex, no contact point', `${requestMarkers.loads} vertices, ${requestMarkers.points} points`);
  check(one.sequence === x5.sequence && largestDifference(one.displacement, x5.displacement) === 0,
    'both pages drew the same sample', `${one.sequence} and ${x5.sequence}`);
  check(exaggerationError(one, 1) <= EXAGGERATED_M, '×1 draws rest + displacement', `${exaggerationError(one, 1).toExponential(2)} m`);
  check(exaggerationError(x5, 5) <= EXAGGERATED_M, '×5 draws rest + 5 × displacement', `${exaggerationError(x5, 5).toExponential(2)} m`);
  let worst = 0;
  for (let i = 0; i < 3 * one.ns; ++i)
    worst = Math.max(worst, Math.abs((x5.positions[i] - x5.rest[i]) - 5 * (one.positions[i] - one.rest[i])));
  check(worst <= EXAGGERATED_M, '×5 moves each vertex 5 times as far as ×1', `${worst.toExponential(2)} m`);
  check(largestDifference(one.colours, x5.colours) <= COLOUR && one.scale === x5.scale && one.max === x5.max,
    'colours and numbers are the true ones at ×5', `scale ${one.scale} and ${x5.scale} m`);
  await five.screenshot({ path: join(args.out, 'viewer-x5.png') });
  await five.close();
  // The buttons: ×20, then back to ×1, on the same sample.
  await page.click('#exaggeration button[data-factor="20"]');
  const x20 = await drawnFrame(page);
  check(x20.factor === 20 && exaggerationError(x20, 20) <= EXAGGERATED_M && page.url().includes('exaggerate=20'),
    'the ×20 button draws rest + 20 × displacement', `${exaggerationError(x20, 20).toExponential(2)} m, ${page.url()}`);
  await page.click('#exaggeration button[data-factor="1"]');
  check(exaggerationError(await drawnFrame(page), 1) <= EXAGGERATED_M, 'the ×1 button draws the true shape again');
  await restRequest();
  await waitForRequestState(page, 0);

  // 6. A scripted tool presses: the organ moves under it.
  pliers = spawn(args.pliers, [args.gesture, '--model', args.model, '--tool', 'left', '-q'],
                 { stdio: ['ignore', 'inherit', 'inherit'] });
  const pliersDone = new Promise((resolve) => pliers.on('exit', (code, signal) => resolve({ code, signal })));
  await page.waitForFunction((depth) => {
    const v = window.palpateViewer, left = v.tools.left;
    return left && left.state === 'touching' && v.maxDisplacement_m > depth && v.contacts > 0;
  }, PRESS_DEPTH_M, { timeout: TIMEOUT_MS });
  await page.waitForTimeout(300);  // a few frames
  // One evaluation: the state and the drawn geometry of the same frame.
  const pressed = await page.evaluate(() => {
    const v = window.palpateViewer;
    return { ...v, drawn: v.drawnDisplacement(), points: v.streamedContactPoints(), markers: v.drawnContactPoints(),
             leftColour: v.toolColour('left') };
  });
  const pressedDrawn = pressed.drawn;
  check(pressedDrawn > PRESS_DEPTH_M, 'the drawn organ moves under the tool', `${(pressedDrawn * 1000).toFixed(2)} mm`);
  check(Math.abs(pressedDrawn - pressed.maxDisplacement_m) < FLOAT32_M,
    'the drawn displacement is the streamed one', `${pressedDrawn} vs ${pressed.maxDisplacement_m} m`);
  check(pressed.contacts > 0, 'contact points are drawn', pressed.contacts);
  // The tool's contact points come from the stream's contact_points: one
  // marker each (tips first, then held), at the point on the drawn surface,
  // which at ×1 is the streamed position (float32 both ways), in the tool's
  // colour; the vertex loads they make are not drawn.
  const streamed = [...pressed.points.filter((q) => !q.held), ...pressed.points.filter((q) => q.held)];
  check(streamed.length > 0 && pressed.contactPoints === streamed.length && pressed.vertexLoads === 0 &&
        pressed.markers.length === streamed.length,
    'one marker per streamed contact point, none on the loaded vertices',
    `${streamed.length} points, ${pressed.markers.length} markers, ${pressed.vertexLoads} vertex markers`);
  const offSurface = streamed.reduce((worst, q, i) => Math.max(worst,
    pressed.markers[i] ? Math.hypot(...q.position.map((x, c) => x - pressed.markers[i].position[c])) : Infinity), 0);
  check(offSurface <= FLOAT32_M, 'each contact point is drawn at its streamed position', `${offSurface.toExponential(2)} m`);
  check(streamed.every((q, i) => q.tool_id === 'left' && !q.held && pressed.markers[i] &&
                                 pressed.markers[i].held === q.held && pressed.markers[i].colour === pressed.leftColour),
    'the points are the left tool\'s tip contacts, drawn in its colour', streamed.map((q) => q.tool_id).join(' '));
  check(streamed.every((q) => Math.hypot(...q.force) > 0 && q.force.every(Number.isFinite)), 'each point has a force');
  check(pressed.source === 'tool:left', 'the state comes from the tool', pressed.source);
  const left = pressed.tools.left;
  check(Math.hypot(...left.force) > 0, 'the tool feels a force', `${Math.hypot(...left.force).toFixed(3)} N`);
  const pressedImage = await grab(page);
  const changed = share(pressedImage.map((g, i) => Math.abs(g - restImage[i])), (d) => d > 12);
  check(changed > MIN_CHANGED_PIXELS, 'the picture changes', `${(100 * changed).toFixed(1)} % of the pixels`);
  await page.screenshot({ path: join(args.out, 'viewer-press.png') });

  // 7. The tool goes away (its client is stopped); the organ returns to rest.
  pliers.kill('SIGTERM');
  await pliersDone;
  pliers = null;
  await page.waitForFunction((rest) => window.palpateViewer.drawnDisplacement() < rest, REST_M,
                             { timeout: TIMEOUT_MS }).catch(() => {});
  const after = await drawnDisplacement(page);
  check(after < REST_M, 'back at rest once the tool is gone', `${after.toExponential(2)} m`);
  await page.screenshot({ path: join(args.out, 'viewer-after.png') });

  // 7b. The jaws grasp (config/gestures/grasp-pull-release.toml, beside
  //     --gesture): the held vertices are drawn as held markers, in the
  //     tool's colour, at their streamed positions. Played up to three
  //     times: on a loaded machine (the ASan build, a round trip of half a
  //     second) one grasp can pass before the page has drawn it; the client
  //     is stopped once the check is made.
  const grasp = spawn(args.pliers, [join(dirname(args.gesture), 'grasp-pull-release.toml'), '--model', args.model,
                                    '--tool', 'left', '--repeat', '3', '-q'],
                      { stdio: ['ignore', 'inherit', 'inherit'] });
  pliers = grasp;
  const graspDone = new Promise((resolve) => grasp.on('exit', resolve));
  await page.waitForFunction(() => {
    const v = window.palpateViewer;
    return v.tools.left && v.tools.left.state === 'grasping' && v.drawnContactPoints().some((q) => q.held);
  }, null, { timeout: TIMEOUT_MS }).catch(() => {});
  const grasped = await page.evaluate(() => {
    const v = window.palpateViewer;
    return { points: v.streamedContactPoints(), markers: v.drawnContactPoints(), leftColour: v.toolColour('left') };
  });
  const heldStreamed = grasped.points.filter((q) => q.held), heldDrawn = grasped.markers.filter((q) => q.held);
  const heldOff = heldStreamed.reduce((worst, q, i) => Math.max(worst,
    heldDrawn[i] ? Math.hypot(...q.position.map((x, c) => x - heldDrawn[i].position[c])) : Infinity), 0);
  check(heldStreamed.length > 0 && heldDrawn.length === heldStreamed.length && heldOff <= FLOAT32_M &&
        heldDrawn.every((q) => q.colour === grasped.leftColour) && heldStreamed.every((q) => q.tool_id === 'left'),
    'the held vertices are drawn as held markers at their streamed positions, in the tool\'s colour',
    `${heldStreamed.length} held, ${heldDrawn.length} drawn, ${heldOff.toExponential(2)} m off`);
  await page.screenshot({ path: join(args.out, 'viewer-grasp.png') });
  grasp.kill('SIGTERM');
  await graspDone;
  pliers = null;

  const status = await page.evaluate(() => window.palpateViewer.status);
  check(status && status.daemon && status.daemon.models === 1, 'the daemon status reaches the page');

  // 8. palpated stops while the organ is displaced: its last state goes with
  //    it. The open page returns to rest and says why; a page opened
  //    afterwards draws the rest shape from its first frame, not that state.
  await displace();
  await waitForRequestState(page, REQUEST_SEEN_M);
  process.kill(Number(args['palpated-pid']), 'SIGTERM');
  await page.waitForFunction(() => window.palpateViewer.streamEnded, null, { timeout: TIMEOUT_MS }).catch(() => {});
  const ended = await page.evaluate(() => ({ ended: window.palpateViewer.streamEnded, drawn: window.palpateViewer.drawnDisplacement() }));
  check(ended.ended && ended.drawn < REST_M && (await shown(page, '#stream-ended')),
    'the open page draws rest and says palpated stopped', `${ended.drawn.toExponential(2)} m`);
  const late = await openPage(query());
  await late.waitForTimeout(300);
  const lateView = await late.evaluate(() => ({ first: window.palpateViewer.firstOrganFrame,
    drawn: window.palpateViewer.drawnDisplacement(), surfaces: window.palpateViewer.surfacesReceived }));
  check(lateView.first.maxOffset_m <= REST_M && lateView.drawn < REST_M && lateView.surfaces === 0,
    'a page opened after palpated stopped draws the rest shape',
    `first frame ${lateView.first.maxOffset_m.toExponential(2)} m off, ${lateView.surfaces} surfaces`);
  await late.screenshot({ path: join(args.out, 'viewer-stopped.png') });

  check(errors.length === 0, 'no errors in the pages', errors.join(' | '));
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
