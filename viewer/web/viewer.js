// palpate's live viewer: the organ shaded by displacement magnitude, the
// tools, their contacts and forces, and the rates, from palpate-viewer's
// WebSocket (/ws). The wire format is in docs/viewer.md. Units: the scene is
// in metres, as the messages are; the panel converts at display (mm, N).

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const GEOMETRY_FRAME = 1;
const SURFACE_FRAME = 2;
const NO_VERTEX = 0xffffffff;
const MM_PER_M = 1000;
const ARROW_M_PER_N = 0.005;         // force arrows: 5 mm per newton
const MIN_SCALE_M = 0.0005;          // the colour scale never goes below 0.5 mm
const SCALE_HALF_LIFE_S = 3;         // then follows the peak, decaying
const MAX_CONTACTS = 256;
const FIXED_COLOR = new THREE.Color(0x5a6270);
const STATE_COLORS = { free: 0xb8c0cc, touching: 0xffb454, grasping: 0xff6b6b };

const parameters = new URLSearchParams(location.search);
const wantedModel = parameters.get('model');           // ?model=ID: which model (default: the first)
const maxFps = Number(parameters.get('fps')) || 60;    // ?fps=N: render at most N frames per second
const followTools = parameters.get('follow') !== '0';  // ?follow=0: the camera stays where it is

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
  maxDisplacement_m: 0,   // of the last surface frame drawn
  colourScale_m: MIN_SCALE_M,
  contacts: 0,
  tools: {},
  framesRendered: 0,
  events: [],
  status: null,
};
window.palpateViewer = view;
// The largest distance of a drawn free vertex from its rest position, m,
// read back from the geometry the renderer draws (0 before any model).
view.drawnDisplacement = () => {
  if (!organ) return 0;
  const p = organ.mesh.geometry.attributes.position.array, r = organ.rest;
  let max = 0;
  for (let i = 0; i < 3 * organ.ns; i += 3)
    max = Math.max(max, Math.hypot(p[i] - r[i], p[i + 1] - r[i + 1], p[i + 2] - r[i + 2]));
  return max;
};

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
let userMovedCamera = false;
controls.addEventListener('start', () => { userMovedCamera = true; });
scene.add(new THREE.HemisphereLight(0xffffff, 0x30343c, 1.0));
const sun = new THREE.DirectionalLight(0xffffff, 1.2);
scene.add(sun);
scene.add(sun.target);

function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
}
window.addEventListener('resize', resize);
resize();

// A perceptual colour map (viridis, 6 stops) for |u| / scale in [0, 1].
// The stops are sRGB; vertex colours are linear in three.js, so the mesh
// uses a linearised copy and the legend (a 2D canvas) the sRGB one.
const VIRIDIS = [[0.267, 0.005, 0.329], [0.254, 0.265, 0.530], [0.164, 0.471, 0.558],
                 [0.134, 0.659, 0.518], [0.478, 0.821, 0.318], [0.993, 0.906, 0.144]];
const VIRIDIS_LINEAR = VIRIDIS.map((rgb) => new THREE.Color().setRGB(...rgb, THREE.SRGBColorSpace).toArray());
function colourAt(t, out, offset, stops = VIRIDIS_LINEAR) {
  const x = Math.min(Math.max(t, 0), 1) * (stops.length - 1);
  const i = Math.min(Math.floor(x), stops.length - 2), f = x - i;
  for (let c = 0; c < 3; ++c) out[offset + c] = stops[i][c] * (1 - f) + stops[i + 1][c] * f;
}
(function drawLegend() {
  const bar = document.getElementById('legend-bar'), g = bar.getContext('2d');
  const rgb = [0, 0, 0];
  for (let x = 0; x < bar.width; ++x) {
    colourAt(x / (bar.width - 1), rgb, 0, VIRIDIS);
    g.fillStyle = `rgb(${rgb.map((v) => Math.round(255 * v)).join(',')})`;
    g.fillRect(x, 0, 1, bar.height);
  }
})();

// ---------------------------------------------------------------- the organ
let organ = null;  // { id, mesh, rest, magnitude, nv, ns, radius, centre }

function disposeOrgan() {
  if (!organ) return;
  scene.remove(organ.mesh);
  organ.mesh.geometry.dispose();
  organ.mesh.material.dispose();
  organ = null;
}

function loadGeometry(id, nv, ns, rest, triangles) {
  disposeOrgan();
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(rest.slice(), 3));
  const colours = new Float32Array(3 * nv);
  for (let v = 0; v < nv; ++v) {
    if (v < ns) colourAt(0, colours, 3 * v);
    else FIXED_COLOR.toArray(colours, 3 * v);  // attached: never moves
  }
  geometry.setAttribute('color', new THREE.BufferAttribute(colours, 3));
  geometry.setIndex(new THREE.BufferAttribute(triangles.slice(), 1));
  geometry.computeVertexNormals();
  geometry.computeBoundingSphere();
  const material = new THREE.MeshStandardMaterial({ vertexColors: true, roughness: 0.55, metalness: 0.0 });
  const mesh = new THREE.Mesh(geometry, material);
  scene.add(mesh);
  const { center, radius } = geometry.boundingSphere;
  organ = { id, mesh, rest, magnitude: new Float32Array(ns), nv, ns, radius, centre: center.clone() };
  view.modelId = id;
  view.vertexCount = nv;
  view.complianceVertexCount = ns;
  view.triangleCount = triangles.length / 3;
  userMovedCamera = false;
  frameCamera(center, new THREE.Vector3(0.2, -1, 0.55), 2.6 * radius);
}

function frameCamera(target, direction, distance) {
  controls.target.copy(target);
  camera.position.copy(target).addScaledVector(direction.clone().normalize(), distance);
  sun.position.copy(camera.position).add(new THREE.Vector3(0, 0, distance));
  sun.target.position.copy(target);
  camera.near = distance / 100;
  camera.far = distance * 20;
  camera.updateProjectionMatrix();
  controls.update();
}

let peak = { value: 0, time: 0 };
function applySurface(ns, displacement, contactIndex, contactForce) {
  if (!organ || ns !== organ.ns) return;
  const position = organ.mesh.geometry.attributes.position;
  const colour = organ.mesh.geometry.attributes.color;
  const p = position.array, rest = organ.rest, mag = organ.magnitude;
  let max = 0;
  for (let a = 0; a < ns; ++a) {
    const dx = displacement[3 * a], dy = displacement[3 * a + 1], dz = displacement[3 * a + 2];
    p[3 * a] = rest[3 * a] + dx;
    p[3 * a + 1] = rest[3 * a + 1] + dy;
    p[3 * a + 2] = rest[3 * a + 2] + dz;
    mag[a] = Math.hypot(dx, dy, dz);
    if (mag[a] > max) max = mag[a];
  }
  // The scale follows the peak up at once and down with a half-life, so a
  // release fades rather than flashes.
  const now = performance.now() / 1000;
  const decayed = peak.value * Math.pow(0.5, (now - peak.time) / SCALE_HALF_LIFE_S);
  if (max >= decayed) peak = { value: max, time: now };
  const scale = Math.max(MIN_SCALE_M, max >= decayed ? max : decayed);
  for (let a = 0; a < ns; ++a) colourAt(mag[a] / scale, colour.array, 3 * a);
  position.needsUpdate = true;
  colour.needsUpdate = true;
  organ.mesh.geometry.computeVertexNormals();
  organ.mesh.geometry.computeBoundingSphere();
  view.maxDisplacement_m = max;
  view.colourScale_m = scale;
  document.getElementById('legend-max').textContent = `${(scale * MM_PER_M).toFixed(2)} mm`;
  document.getElementById('displacement').textContent =
    `max ${(max * MM_PER_M).toFixed(2)} mm · ${contactIndex.length} constrained vertices`;
  showContacts(contactIndex, contactForce);
}

// Contact points (small spheres on the deformed surface) and the force the
// tool exerts on the organ at each (red arrows, ARROW_M_PER_N); the force
// on each tool is the yellow arrow at its tip.
const contactMarkers = new THREE.InstancedMesh(
  new THREE.SphereGeometry(1, 12, 8),
  new THREE.MeshBasicMaterial({ color: 0xff3355 }), MAX_CONTACTS);
contactMarkers.count = 0;
contactMarkers.frustumCulled = false;
scene.add(contactMarkers);
const contactArrows = [];

// Arrows are drawn over everything: a force on the organ points into it and
// the force on a tool along its shaft, where both would be hidden.
function arrow(colour) {
  const a = new THREE.ArrowHelper(new THREE.Vector3(0, 0, 1), new THREE.Vector3(), 1, colour);
  for (const part of [a.line, a.cone]) { part.material.depthTest = false; part.renderOrder = 10; }
  a.visible = false;
  scene.add(a);
  return a;
}

function setArrow(a, origin, force, headScale) {
  const length = force.length() * ARROW_M_PER_N;
  if (length < 1e-5) { a.visible = false; return; }
  a.position.copy(origin);
  a.setDirection(force.clone().normalize());
  const head = Math.min(0.35 * length, headScale);
  a.setLength(length, head, 0.5 * head);
  a.visible = true;
}

function showContacts(index, force) {
  const p = organ.mesh.geometry.attributes.position.array;
  const r = Math.max(organ.radius * 0.006, 0.0008);
  const m = new THREE.Matrix4(), at = new THREE.Vector3(), f = new THREE.Vector3();
  let n = 0;
  for (let c = 0; c < index.length && n < MAX_CONTACTS; ++c) {
    const v = index[c];
    if (v === NO_VERTEX || v >= organ.nv) continue;
    at.set(p[3 * v], p[3 * v + 1], p[3 * v + 2]);
    m.makeScale(r, r, r).setPosition(at);
    contactMarkers.setMatrixAt(n, m);
    while (contactArrows.length <= n) contactArrows.push(arrow(0xff3355));
    f.set(force[3 * c], force[3 * c + 1], force[3 * c + 2]);
    setArrow(contactArrows[n], at, f, 4 * r);
    ++n;
  }
  for (let c = n; c < contactArrows.length; ++c) contactArrows[c].visible = false;
  contactMarkers.count = n;
  contactMarkers.instanceMatrix.needsUpdate = true;
  view.contacts = n;
}

// ---------------------------------------------------------------- the tools
// A grasper in its frame (docs/dds.md, ToolPose): hinge at the origin, shaft
// along -z, tip (sphere or capsule, the contact shape, translucent) and jaws
// (opening in the x-z plane) along +z.
const toolGroups = new Map();

function makeTool(g) {
  const group = new THREE.Group();
  const metal = new THREE.MeshStandardMaterial({ color: 0x9aa4b1, roughness: 0.35, metalness: 0.6 });
  const shaftRadius = Math.max(g.jaw_width, 0.004) / 2;
  const shaft = new THREE.Mesh(new THREE.CylinderGeometry(shaftRadius, shaftRadius, 0.25, 20), metal);
  shaft.rotation.x = Math.PI / 2;
  shaft.position.z = -0.125;
  group.add(shaft);
  const tipMaterial = new THREE.MeshStandardMaterial({ color: STATE_COLORS.free, transparent: true, opacity: 0.45 });
  const tip = g.tip === 'sphere'
    ? new THREE.Mesh(new THREE.SphereGeometry(g.tip_radius, 24, 16), tipMaterial)
    : new THREE.Mesh(new THREE.CapsuleGeometry(g.tip_radius, g.tip_length, 8, 20), tipMaterial);
  if (g.tip !== 'sphere') { tip.rotation.x = Math.PI / 2; tip.position.z = g.tip_length / 2; }
  group.add(tip);
  const jaws = [];
  for (const side of [-1, 1]) {
    const pivot = new THREE.Group();
    const jaw = new THREE.Mesh(new THREE.BoxGeometry(0.001, g.jaw_width, g.jaw_length || 0.001), metal);
    jaw.position.z = (g.jaw_length || 0.001) / 2;
    pivot.add(jaw);
    pivot.userData.side = side;
    group.add(pivot);
    jaws.push(pivot);
  }
  const force = arrow(0xffe14d);
  scene.add(group);
  return { group, tipMaterial, jaws, force, geometry: g };
}

function updateTools(list) {
  const seen = new Set();
  for (const t of list) {
    seen.add(t.tool_id);
    let tool = toolGroups.get(t.tool_id);
    if (!tool) { tool = makeTool(t.geometry); toolGroups.set(t.tool_id, tool); }
    const visible = organ !== null && t.model_id === organ.id;
    tool.group.visible = visible;
    const [w, x, y, z] = t.orientation;
    tool.group.position.fromArray(t.position);
    tool.group.quaternion.set(x, y, z, w).normalize();
    for (const jaw of tool.jaws) jaw.rotation.y = jaw.userData.side * t.jaw_angle / 2;
    tool.tipMaterial.color.setHex(STATE_COLORS[t.state] ?? STATE_COLORS.free);
    // The force the organ exerts on the tool, drawn at the tip.
    const tipCentre = new THREE.Vector3(0, 0, tool.geometry.tip === 'sphere' ? 0 : tool.geometry.tip_length)
      .applyQuaternion(tool.group.quaternion).add(tool.group.position);
    setArrow(tool.force, tipCentre, new THREE.Vector3().fromArray(t.force), 0.006);
    tool.force.visible &&= visible;
  }
  for (const [id, tool] of toolGroups)
    if (!seen.has(id)) { tool.group.visible = false; tool.force.visible = false; }
  view.tools = Object.fromEntries(list.map((t) => [t.tool_id, t]));
  frameTools(list);
  renderToolTable(list);
}

// Until the user moves the camera, it looks at the tools from beside their
// shafts once they come near the organ.
let framedTools = false;
function frameTools(list) {
  if (!followTools || framedTools || userMovedCamera || !organ) return;
  const near = list.filter((t) => t.model_id === organ.id && t.state !== 'free');
  if (near.length === 0) return;
  const target = new THREE.Vector3(), back = new THREE.Vector3(), side = new THREE.Vector3();
  for (const t of near) {
    const q = new THREE.Quaternion(t.orientation[1], t.orientation[2], t.orientation[3], t.orientation[0]);
    target.add(new THREE.Vector3().fromArray(t.position));
    back.add(new THREE.Vector3(0, 0, -1).applyQuaternion(q));
    side.add(new THREE.Vector3(0, 1, 0).applyQuaternion(q));
  }
  target.divideScalar(near.length);
  // From outside the organ (back along the shafts and away from its centre),
  // a little from the side so that the shafts do not hide the tips.
  const outward = target.clone().sub(organ.centre).normalize();
  const direction = back.normalize().add(outward).normalize().add(side.normalize().multiplyScalar(0.45));
  frameCamera(target, direction, 2.0 * organ.radius);
  framedTools = true;
}

// ---------------------------------------------------------------- the panel
function cell(text, cls) { const td = document.createElement('td'); td.textContent = text; if (cls) td.className = cls; return td; }
function row(...cells) { const tr = document.createElement('tr'); tr.append(...cells); return tr; }
const fixed = (v, digits) => (Number.isFinite(v) ? v.toFixed(digits) : '–');

function renderModel(m) {
  document.getElementById('model').textContent =
    `${m.model_id}: ${m.vertex_count} surface vertices (${m.compliance_vertex_count} free), ` +
    `${m.triangle_count} triangles · ${m.material}`;
}

function renderToolTable(list) {
  const body = document.querySelector('#tools tbody');
  body.replaceChildren(row(cell('tool'), cell('state'), cell('|F| N', 'num'), cell('contacts', 'num'), cell('grip N', 'num')),
    ...list.map((t) => row(cell(t.tool_id), cell(t.watchdog ? 'watchdog' : t.state, `state-${t.state}`),
      cell(fixed(Math.hypot(...t.force), 3), 'num'), cell(String(t.contacts), 'num'), cell(fixed(t.grip_force, 2), 'num'))));
}

const counters = { frames: 0, surfaces: 0, tools: 0, since: performance.now() };
function renderRates() {
  const now = performance.now(), dt = (now - counters.since) / 1000;
  const page = { fps: counters.frames / dt, surfaces: counters.surfaces / dt, tools: counters.tools / dt };
  counters.frames = counters.surfaces = counters.tools = 0;
  counters.since = now;
  view.pageRates = page;
  const s = view.status, d = s?.daemon, b = s?.bridge;
  const rows = [
    ['page frames / s', fixed(page.fps, 0)],
    ['surface frames drawn / s', fixed(page.surfaces, 0)],
    ['tool updates / s', fixed(page.tools, 0)],
    ['bridge: surfaces / s', fixed(b?.surface_hz, 0)],
    ['bridge: poses / s', fixed(b?.pose_hz, 0)],
    ['bridge: feedback / s', fixed(b?.feedback_hz, 0)],
    ['daemon: surface Hz', fixed(d?.surface_rate_hz, 0)],
    ['daemon: requests / s', fixed(d?.request_rate_hz, 0)],
    ['daemon: tool tick p50 / p99 µs', d ? `${fixed(d.tool_compute.p50_us, 0)} / ${fixed(d.tool_compute.p99_us, 0)}` : '–'],
  ];
  document.querySelector('#rates tbody').replaceChildren(...rows.map(([k, v]) => row(cell(k), cell(v, 'num'))));
}
setInterval(renderRates, 1000);

function addEvent(e) {
  const text = e.type === 'warning' ? `warning: ${e.message}`
    : `${e.tool_id}: ${e.kind}${e.kind === 'grasp' ? ` (${e.held_vertices} vertices)` : ''}`;
  view.events.push(text);
  const list = document.getElementById('events');
  const li = document.createElement('li');
  li.textContent = text;
  list.prepend(li);
  while (list.children.length > 8) list.lastChild.remove();
}

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
    applySurface(ns, displacement, contactIndex, contactForce);
    view.surfacesReceived += 1;
    view.lastSequence = sequence;
    view.source = source;
    counters.surfaces += 1;
  }
}

function onText(message) {
  dirty = true;
  switch (message.type) {
    case 'model':
      if ((organ && organ.id !== message.model_id) || (!organ && wantedModel && message.model_id !== wantedModel)) return;
      renderModel(message);
      break;
    case 'tools': updateTools(message.tools); counters.tools += 1; break;
    case 'status': view.status = message; break;
    case 'event': case 'warning': addEvent(message); break;
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
connect();

// Frames are drawn when something changed (a message, the camera, the
// window), at most maxFps per second: an idle page costs nothing, and a busy
// one leaves the CPU to palpated's 1 kHz loop on small machines.
let dirty = true, lastRender = 0;
function markDirty() { dirty = true; }
window.addEventListener('resize', markDirty);
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
}
requestAnimationFrame(render);
