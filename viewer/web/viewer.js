// palpate's live viewer: the organ shaded by displacement magnitude, the
// tools, their contacts and forces, and the rates, from palpate-viewer's
// WebSocket (/ws). The wire format is in docs/viewer.md. Units: the scene is
// in metres, as the messages are; the panel converts at display (mm, N).
//
// This file holds the organ, the wire and the render loop; camera.js,
// legend.js, exaggeration.js, tools.js, contacts.js, region.js and panel.js
// one concept each.

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { boxOf, fitToFreeArea, frameOrgan, placeCamera, projectCorners, toolsViewpoint } from './camera.js';
import { EXAGGERATION_PARAMETER, createExaggerationControl, parseExaggeration } from './exaggeration.js';
import { MIN_SCALE_M, PeakHoldScale, colourAt, drawLegendBar, legendMeaning, mm } from './legend.js';
import { addEvent, renderModel, renderRates, renderToolTable } from './panel.js';
import { ContactLayer, NO_POINTS, listContactPoints, readContactPoints } from './contacts.js';
import { ToolLayer, toolColour } from './tools.js';
import { NO_REGION, organIndexWithout, readRegion, regionIndex } from './region.js';

const GEOMETRY_FRAME = 1;
const SURFACE_FRAME = 2;
const MAX_CONTACTS = 256;
const FIXED_COLOR = new THREE.Color(0x5a6270);
const FIXED_MARKER_COLOR = 0x7fdbff;
// The cut region: one colour (the stream gives its positions, not how far
// they moved, so it cannot be shaded by displacement).
const REGION_COLOR = 0xd08770;

const parameters = new URLSearchParams(location.search);
const wantedModel = parameters.get('model');           // ?model=ID: which model (default: the first)
const maxFps = Number(parameters.get('fps')) || 60;    // ?fps=N: render at most N frames per second
const followTools = parameters.get('follow') !== '0';  // ?follow=0: the camera stays where it is
const askedExaggeration = parseExaggeration(parameters.get(EXAGGERATION_PARAMETER));  // ?exaggerate=1|5|20

// What the page shows, for people (the panel) and for tests (window.palpateViewer).
const view = {
  connected: false,
  modelId: null,
  vertexCount: 0,
  triangleCount: 0,
  complianceVertexCount: 0,
  surfacesReceived: 0,
  lastSequence: 0,
  source: '',
  maxDisplacement_m: 0,   // of the last surface frame drawn, true (not exaggerated)
  colourScale_m: MIN_SCALE_M,  // the legend's peak-hold top value
  exaggeration: askedExaggeration.factor,
  exaggerationWarning: askedExaggeration.warning,
  streamEnded: false,     // palpated stopped serving the model: drawn at rest
  firstOrganFrame: null,  // { maxOffset_m, surfacesReceived }: the first frame drawn with the organ
  fixedMarkers: 0,
  contacts: 0,            // markers drawn: contact points, or a request's constrained vertices
  contactPoints: 0,       // of them, the tools' contact points (on triangles)
  vertexLoads: 0,         // of them, a request's constrained vertices (no contact points)
  topologyVersion: 0,     // of the served cut region drawn; 0: none
  organTriangles: 0,      // the organ's triangles drawn (its own less those the region covers)
  regionTriangles: 0,     // the region's triangles drawn
  regionVertices: 0,
  tools: {},
  framesRendered: 0,
  events: [],
  status: null,
};
window.palpateViewer = view;

// ---------------------------------------------------------------- the scene
const canvas = document.getElementById('scene');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x1d2127);
const camera = new THREE.PerspectiveCamera(40, 1, 0.001, 100);
camera.up.set(0, 0, 1);
const controls = new OrbitControls(camera, canvas);
controls.enableDamping = true;
let userMovedCamera = false, framedTools = false;
controls.addEventListener('start', () => { userMovedCamera = true; });
scene.add(new THREE.HemisphereLight(0xffffff, 0x30343c, 1.0));
const sun = new THREE.DirectionalLight(0xffffff, 1.2);
scene.add(sun);
scene.add(sun.target);
const rig = { camera, controls, sun };

const panel = document.getElementById('panel');
const PANEL_GAP_PX = 8;
function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  renderer.setSize(w, h, false);
  fitToFreeArea(camera, w, h, panel.getBoundingClientRect().right + PANEL_GAP_PX);
  // A framing fits one aspect ratio: frame again unless someone moved it.
  if (organ && !userMovedCamera && !framedTools) frameOrgan(rig, organ);
}
window.addEventListener('resize', resize);

drawLegendBar(document.getElementById('legend-bar'));
document.getElementById('legend-meaning').textContent = legendMeaning();
const colourScale = new PeakHoldScale();
createExaggerationControl({
  container: document.getElementById('exaggeration'),
  stateLine: document.getElementById('exaggeration-state'),
  warningLine: document.getElementById('exaggeration-warning'),
  initial: askedExaggeration,
  onChange: (factor) => { view.exaggeration = factor; if (organ) { drawSurface(); dirty = true; } },
});

// ---------------------------------------------------------------- the organ
// { id, mesh, fixedMarkers, rest, restNormal, triangles, displacement, magnitude,
//   contactIndex, contactForce, points, nv, ns, box, centre, radius, region }: displacement
// (3·ns, m) is the last streamed one, true; the mesh draws it exaggerated.
// triangles: every triangle of the description (the mesh may draw fewer:
// those the cut region covers are left out). region: { version, mesh, hidden }
// of the served cut region drawn (hidden: the triangles it covers, as
// streamed), version 0 and no mesh without one.
let organ = null;

function disposeRegion() {
  if (!organ || !organ.region.mesh) return;
  const m = organ.region.mesh;
  scene.remove(m); m.geometry.dispose(); m.material.dispose();
  organ.region.mesh = null;
}

function disposeOrgan() {
  if (!organ) return;
  disposeRegion();
  for (const o of [organ.mesh, organ.fixedMarkers]) { scene.remove(o); o.geometry.dispose(); o.material.dispose(); }
  organ = null;
}

function loadGeometry(id, nv, ns, rest, triangles) {
  disposeOrgan();
  const geometry = new THREE.BufferGeometry();
  // The rest positions, copied: the first frame drawn is the rest shape
  // until a surface of this model's current stream arrives.
  geometry.setAttribute('position', new THREE.BufferAttribute(rest.slice(), 3));
  const colours = new Float32Array(3 * nv);
  for (let v = 0; v < nv; ++v) {
    if (v < ns) colourAt(0, colours, 3 * v);
    else FIXED_COLOR.toArray(colours, 3 * v);  // attached: never moves
  }
  geometry.setAttribute('color', new THREE.BufferAttribute(colours, 3));
  geometry.setIndex(new THREE.BufferAttribute(triangles.slice(), 1));
  geometry.computeVertexNormals();
  const material = new THREE.MeshStandardMaterial({ vertexColors: true, roughness: 0.55, metalness: 0.0 });
  const mesh = new THREE.Mesh(geometry, material);
  scene.add(mesh);
  const box = boxOf(rest);
  const centre = box.getCenter(new THREE.Vector3());
  const radius = box.getSize(new THREE.Vector3()).length() / 2;
  organ = { id, mesh, rest, nv, ns, box, centre, radius, displacement: new Float32Array(3 * ns),
            magnitude: new Float32Array(ns), contactIndex: new Uint32Array(0), contactForce: new Float32Array(0),
            points: NO_POINTS, triangles: triangles.slice(),
            region: { version: 0, mesh: null, hidden: new Uint32Array(0) } };
  organ.restNormal = geometry.attributes.normal.array.slice();
  organ.fixedMarkers = makeFixedMarkers(rest, organ.restNormal, ns, nv, radius);
  scene.add(organ.fixedMarkers);
  view.modelId = id;
  view.vertexCount = nv;
  view.complianceVertexCount = ns;
  view.triangleCount = triangles.length / 3;
  view.organTriangles = triangles.length / 3;
  view.topologyVersion = 0;
  view.regionTriangles = view.regionVertices = 0;
  view.fixedMarkers = nv - ns;
  view.firstOrganFrame = null;
  showStreamEnded(false);
  colourScale.reset();
  showContacts();
  userMovedCamera = false;
  framedTools = false;
  frameOrgan(rig, organ);
}

// A dot on each attached vertex, lifted off the surface along its normal so
// that the surface does not hide half of it.
function makeFixedMarkers(rest, normal, ns, nv, radius) {
  const lift = 0.004 * radius;
  const at = new Float32Array(3 * (nv - ns));
  for (let v = ns; v < nv; ++v)
    for (let c = 0; c < 3; ++c) at[3 * (v - ns) + c] = rest[3 * v + c] + lift * normal[3 * v + c];
  const markers = new THREE.BufferGeometry();
  markers.setAttribute('position', new THREE.BufferAttribute(at, 3));
  return new THREE.Points(markers, new THREE.PointsMaterial({ color: FIXED_MARKER_COLOR, size: 4, sizeAttenuation: false }));
}

// Free vertex a is drawn at rest + factor × displacement; colours stay true.
function drawSurface() {
  const position = organ.mesh.geometry.attributes.position, p = position.array;
  const rest = organ.rest, u = organ.displacement, factor = view.exaggeration;
  for (let i = 0; i < 3 * organ.ns; ++i) p[i] = rest[i] + factor * u[i];
  position.needsUpdate = true;
  organ.mesh.geometry.computeVertexNormals();
  organ.mesh.geometry.computeBoundingSphere();
  showContacts();
}

function applySurface(ns, displacement, contactIndex, contactForce, points) {
  if (!organ || ns !== organ.ns) return;
  const colour = organ.mesh.geometry.attributes.color, mag = organ.magnitude;
  organ.displacement.set(displacement);
  let max = 0;
  for (let a = 0; a < ns; ++a) {
    mag[a] = Math.hypot(displacement[3 * a], displacement[3 * a + 1], displacement[3 * a + 2]);
    if (mag[a] > max) max = mag[a];
  }
  const scale = colourScale.update(max, performance.now() / 1000);
  for (let a = 0; a < ns; ++a) colourAt(mag[a] / scale, colour.array, 3 * a);
  colour.needsUpdate = true;
  organ.contactIndex = contactIndex;
  organ.contactForce = contactForce;
  organ.points = points;
  drawSurface();
  view.maxDisplacement_m = max;
  view.colourScale_m = scale;
  document.getElementById('legend-max').textContent = `peak-hold ${mm(scale)}`;
  document.getElementById('displacement').textContent =
    `max now ${mm(max)} · ` + (points.count > 0
      ? `${points.count} contact point${points.count === 1 ? '' : 's'} on ${contactIndex.length} loaded vertices`
      : `${contactIndex.length} constrained vertices`);
}

// The served cut region of a surface frame (region.js): its own mesh at the
// streamed positions (true: the exaggeration multiplies the organ's
// displacement only), and the organ without the triangles it covers. Both
// index buffers are rebuilt only when its topology version changes (a cut);
// version 0 (no region) draws the organ whole, as without the fields.
function applyRegion(region) {
  const r = organ.region;
  const nrv = region.positions.length / 3;
  if (region.version !== r.version) {
    r.version = region.version;
    r.hidden = Uint32Array.from(region.hidden);
    const index = organIndexWithout(organ.triangles, region.hidden);
    organ.mesh.geometry.setIndex(new THREE.BufferAttribute(index, 1));
    view.organTriangles = index.length / 3;
    disposeRegion();
    if (region.version !== 0) {
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3 * nrv), 3));
      geometry.setIndex(new THREE.BufferAttribute(regionIndex(region.triangles, nrv), 1));
      const material = new THREE.MeshStandardMaterial({ color: REGION_COLOR, roughness: 0.55, metalness: 0.0 });
      r.mesh = new THREE.Mesh(geometry, material);
      scene.add(r.mesh);
    }
    view.topologyVersion = region.version;
    view.regionTriangles = r.mesh ? r.mesh.geometry.index.count / 3 : 0;
    view.regionVertices = r.mesh ? nrv : 0;
    organ.mesh.geometry.computeVertexNormals();
  }
  if (!r.mesh) return;
  const position = r.mesh.geometry.attributes.position;
  if (position.array.length !== region.positions.length) return;  // not this topology's: wait for the next
  position.array.set(region.positions);
  position.needsUpdate = true;
  r.mesh.geometry.computeVertexNormals();
  r.mesh.geometry.computeBoundingSphere();
}

// palpated stopped serving the model (the bridge's surface_ended): its last
// state is gone with it, so the organ is drawn at rest, and the page says so.
function endStream() {
  applySurface(organ.ns, new Float32Array(3 * organ.ns), new Uint32Array(0), new Float32Array(0), NO_POINTS);
  applyRegion(NO_REGION);
  colourScale.reset();
  view.source = '';
  showStreamEnded(true);
}

function showStreamEnded(ended) {
  view.streamEnded = ended;
  document.getElementById('stream-ended').hidden = !ended;
}

// The contacts of the shown state (contacts.js).
const contactLayer = new ContactLayer(scene, MAX_CONTACTS);

function showContacts() {
  const r = Math.max(organ.radius * 0.006, 0.0008);
  const drawn = contactLayer.show(organ.points, organ.contactIndex, organ.contactForce,
                                  organ.mesh.geometry.attributes.position.array, organ.nv, r);
  view.contacts = drawn.arrows;
  view.contactPoints = drawn.points;
  view.vertexLoads = drawn.vertexLoads;
}

// ---------------------------------------------------------------- for tests
// Read back from the geometry the renderer draws; plain arrays, m.
function largestOffset(count) {
  if (!organ) return 0;
  const p = organ.mesh.geometry.attributes.position.array, r = organ.rest;
  let max = 0;
  for (let i = 0; i < 3 * count; i += 3)
    max = Math.max(max, Math.hypot(p[i] - r[i], p[i + 1] - r[i + 1], p[i + 2] - r[i + 2]));
  return max;
}
// The largest distance of a drawn free vertex from its rest position (0 before any model).
view.drawnDisplacement = () => largestOffset(organ ? organ.ns : 0);
view.drawnPositions = () => (organ ? Array.from(organ.mesh.geometry.attributes.position.array) : []);
// The triangles the renderer draws: the organ's (index triples into its
// vertices) and the cut region's (into the region's), and the region's positions.
view.drawnOrganTriangles = () => (organ ? Array.from(organ.mesh.geometry.index.array) : []);
view.drawnRegionTriangles = () => (organ && organ.region.mesh ? Array.from(organ.region.mesh.geometry.index.array) : []);
view.hiddenTriangles = () => (organ ? Array.from(organ.region.hidden) : []);  // as streamed
view.drawnRegionPositions = () =>
  (organ && organ.region.mesh ? Array.from(organ.region.mesh.geometry.attributes.position.array) : []);
view.restPositions = () => (organ ? Array.from(organ.rest) : []);
view.trueDisplacement = () => (organ ? Array.from(organ.displacement) : []);
view.vertexColours = () => (organ ? Array.from(organ.mesh.geometry.attributes.color.array) : []);
// The contact points as streamed (true positions, m; forces, N) and as the
// renderer draws them: the centres and colours of the markers (tips, then held).
view.streamedContactPoints = () => listContactPoints(organ ? organ.points : NO_POINTS);
view.drawnContactPoints = () => contactLayer.drawnPoints();
view.toolColour = (id) => toolColour(id);
view.projectedBoxCorners = () => (organ ? projectCorners(camera, organ.box) : []);
view.freeNdcLeft = () => camera.userData.freeNdcLeft;  // the panel covers x < this
// The share of attached vertices whose (rest) normal faces the camera.
view.attachedFacingCamera = () => {
  if (!organ || organ.nv === organ.ns) return 0;
  const p = organ.rest, n = organ.restNormal;
  let facing = 0;
  for (let v = organ.ns; v < organ.nv; ++v) {
    const d = [0, 1, 2].map((c) => camera.position.getComponent(c) - p[3 * v + c]);
    if (d[0] * n[3 * v] + d[1] * n[3 * v + 1] + d[2] * n[3 * v + 2] > 0) ++facing;
  }
  return facing / (organ.nv - organ.ns);
};

// ---------------------------------------------------------------- the tools
const toolLayer = new ToolLayer(scene);

function updateTools(list) {
  toolLayer.update(list, organ ? organ.id : null);
  view.tools = Object.fromEntries(list.map((t) => [t.tool_id, t]));
  frameTools(list);
  renderToolTable(list, toolColour);
}

// Until the user moves the camera, it turns to the tools once they come near the organ.
function frameTools(list) {
  if (!followTools || framedTools || userMovedCamera || !organ) return;
  const near = list.filter((t) => t.model_id === organ.id && t.state !== 'free');
  if (near.length === 0) return;
  const { target, direction } = toolsViewpoint(near, organ.centre);
  placeCamera(rig, target, direction, 2.0 * organ.radius);
  framedTools = true;
}

// ---------------------------------------------------------------- the panel
const counters = { frames: 0, surfaces: 0, tools: 0, since: performance.now() };
setInterval(() => {
  const now = performance.now(), dt = (now - counters.since) / 1000;
  view.pageRates = { fps: counters.frames / dt, surfaces: counters.surfaces / dt, tools: counters.tools / dt };
  counters.frames = counters.surfaces = counters.tools = 0;
  counters.since = now;
  renderRates(view.pageRates, view.status);
}, 1000);

// ---------------------------------------------------------------- the wire
function readString(data, offset) {
  const n = data.getUint32(offset, true);
  const text = new TextDecoder().decode(new Uint8Array(data.buffer, offset + 4, n));
  return [text, offset + 4 + ((n + 3) & ~3)];
}

function onBinary(buffer) {
  dirty = true;
  const data = new DataView(buffer);
  const kind = data.getUint32(0, true);
  let [id, o] = readString(data, 4);
  if (kind === GEOMETRY_FRAME) {
    if (organ && organ.id !== id) return;          // one model per page
    if (!organ && wantedModel && id !== wantedModel) return;
    const nv = data.getUint32(o, true), ns = data.getUint32(o + 4, true), nt = data.getUint32(o + 8, true);
    o += 12;
    const rest = new Float32Array(buffer, o, 3 * nv);
    const triangles = new Uint32Array(buffer, o + 12 * nv, 3 * nt);
    loadGeometry(id, nv, ns, rest, triangles);
  } else if (kind === SURFACE_FRAME) {
    if (!organ || organ.id !== id) return;
    let source;
    [source, o] = readString(data, o);
    const sequence = data.getUint32(o, true) + 2 ** 32 * data.getUint32(o + 4, true);
    const ns = data.getUint32(o + 8, true), nc = data.getUint32(o + 12, true);
    o += 16 + 12;  // counts, then total force (f32 x 3: shown per tool instead)
    const displacement = new Float32Array(buffer, o, 3 * ns);
    o += 12 * ns;
    const contactIndex = new Uint32Array(buffer, o, nc);
    const contactForce = new Float32Array(buffer, o + 4 * nc, 3 * nc);
    o += 16 * nc;
    const points = readContactPoints(data, o, readString);
    applySurface(ns, displacement, contactIndex, contactForce, points);
    if (organ.ns === ns) applyRegion(readRegion(data, points.end));
    showStreamEnded(false);
    view.surfacesReceived += 1;
    view.lastSequence = sequence;
    view.source = source;
    counters.surfaces += 1;
  }
}

// The models palpated announced, to say which are served when ?model= names
// another (as palpate-client and palpate-pliers do).
const announced = new Set();
function showNotServed() {
  const section = document.getElementById('model');
  section.textContent = `model '${wantedModel}' is not served by palpated; served: ` +
    `${[...announced].join(', ')} (change ?model= in the address)`;
  section.className = 'warn';
}

function onText(message) {
  dirty = true;
  switch (message.type) {
    case 'model':
      announced.add(message.model_id);
      if (!organ && wantedModel && message.model_id !== wantedModel) { showNotServed(); return; }
      if (organ && organ.id !== message.model_id) return;
      document.getElementById('model').className = '';
      renderModel(message);
      break;
    case 'surface_ended': if (organ && organ.id === message.model_id) endStream(); break;
    case 'tools': updateTools(message.tools); counters.tools += 1; break;
    case 'status': view.status = message; break;
    case 'event': case 'warning': view.events.push(addEvent(message)); break;
  }
}

function connect() {
  const socket = new WebSocket(`ws://${location.host}/ws`);
  socket.binaryType = 'arraybuffer';
  const badge = document.getElementById('connection');
  socket.onopen = () => { view.connected = true; badge.textContent = 'live'; badge.className = 'ok'; };
  socket.onmessage = (e) => (typeof e.data === 'string' ? onText(JSON.parse(e.data)) : onBinary(e.data));
  socket.onclose = () => {
    view.connected = false;
    badge.textContent = 'bridge gone, retrying…';
    badge.className = 'bad';
    setTimeout(connect, 1000);
  };
}
resize();
connect();

// Frames are drawn when something changed (a message, the camera, the
// window), at most maxFps per second: an idle page costs nothing, and a busy
// one leaves the CPU to palpated's 1 kHz loop on small machines.
let dirty = true, lastRender = 0;
window.addEventListener('resize', () => { dirty = true; });
function render(now) {
  requestAnimationFrame(render);
  if (now - lastRender < 1000 / maxFps - 1) return;
  const moved = controls.update();
  if (!moved && !dirty) return;
  dirty = false;
  lastRender = now;
  renderer.render(scene, camera);
  view.framesRendered += 1;
  counters.frames += 1;
  if (organ && view.firstOrganFrame === null)
    view.firstOrganFrame = { maxOffset_m: largestOffset(organ.nv), surfacesReceived: view.surfacesReceived };
}
requestAnimationFrame(render);
