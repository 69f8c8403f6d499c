// The haptic tools as the page draws them, and the force arrows (on each
// tool, and at each contact on the organ). Units: m and N, as the messages.

import * as THREE from 'three';

export const ARROW_M_PER_N = 0.005;  // force arrows: 5 mm per newton
const STATE_COLORS = { free: 0xb8c0cc, touching: 0xffb454, grasping: 0xff6b6b };
// The colour of each tool's contact points and their arrows, picked from the
// tool's id (the same on every page): clear of the displacement colours
// (viridis), of the yellow force on a tool and of the red request markers.
const TOOL_COLOURS = [0x4fc3ff, 0xff8c42, 0xe15bff, 0xffffff, 0x00e0b0, 0xff5fa2];
export function toolColour(id) {
  let h = 0;
  for (const ch of id) h = (31 * h + ch.codePointAt(0)) >>> 0;
  return TOOL_COLOURS[h % TOOL_COLOURS.length];
}

// Arrows are drawn over everything: a force on the organ points into it and
// the force on a tool along its shaft, where both would be hidden.
export function arrow(scene, colour) {
  const a = new THREE.ArrowHelper(new THREE.Vector3(0, 0, 1), new THREE.Vector3(), 1, colour);
  for (const part of [a.line, a.cone]) { part.material.depthTest = false; part.renderOrder = 10; }
  a.visible = false;
  scene.add(a);
  return a;
}

export function setArrow(a, origin, force, headScale) {
  const length = force.length() * ARROW_M_PER_N;
  if (length < 1e-5) { a.visible = false; return; }
  a.position.copy(origin);
  a.setDirection(force.clone().normalize());
  const head = Math.min(0.35 * length, headScale);
  a.setLength(length, head, 0.5 * head);
  a.visible = true;
}

// A grasper in its frame (docs/dds.md, ToolPose): hinge at the origin, shaft
// along -z, tip (sphere or capsule, the contact shape, translucent) and jaws
// (opening in the x-z plane) along +z.
function makeTool(scene, g) {
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
  const force = arrow(scene, 0xffe14d);
  scene.add(group);
  return { group, tipMaterial, jaws, force, geometry: g };
}

/** Every tool of the last tools message; those of another model than the page's are hidden. */
export class ToolLayer {
  constructor(scene) { this.scene = scene; this.tools = new Map(); }

  update(list, organId) {
    const seen = new Set();
    for (const t of list) {
      seen.add(t.tool_id);
      let tool = this.tools.get(t.tool_id);
      if (!tool) { tool = makeTool(this.scene, t.geometry); this.tools.set(t.tool_id, tool); }
      const visible = organId !== null && t.model_id === organId;
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
    for (const [id, tool] of this.tools)
      if (!seen.has(id)) { tool.group.visible = false; tool.force.visible = false; }
  }
}
