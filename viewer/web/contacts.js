// What the tools touch, and the force each exerts on the organ there.
// A tool state carries its contact points (docs/viewer.md, "Surface
// frame"): a sphere in the tool's colour where its tip presses a triangle,
// a cube where its jaws hold the surface, and an arrow of the tool's colour
// from each point. A request's state has no contact points: a red dot and a
// red arrow on each constrained vertex instead. The force on each tool is
// the yellow arrow at its tip (tools.js). Units: m and N.

import * as THREE from 'three';
import { arrow, setArrow, toolColour } from './tools.js';

const NO_VERTEX = 0xffffffff;
const VERTEX_LOAD_COLOR = 0xff3355;

/** A surface frame's contact points when it has none. */
export const NO_POINTS = { count: 0, toolIds: [], tool: new Uint32Array(0), held: new Uint32Array(0),
                           vertices: new Uint32Array(0), weights: new Float32Array(0),
                           position: new Float32Array(0), force: new Float32Array(0) };

/**
 * The tools' contact points at offset o of a surface frame (data: its
 * DataView), after the constrained vertices; none from a bridge older than
 * them (the frame ends before). readString(data, o) gives [text, next offset].
 */
export function readContactPoints(data, o, readString) {
  if (o + 4 > data.byteLength) return NO_POINTS;
  const buffer = data.buffer, nt = data.getUint32(o, true), toolIds = [];
  o += 4;
  for (let t = 0; t < nt; ++t) { let id; [id, o] = readString(data, o); toolIds.push(id); }
  const count = data.getUint32(o, true);
  o += 4;
  const tool = new Uint32Array(buffer, o, count), held = new Uint32Array(buffer, o + 4 * count, count);
  o += 8 * count;
  const vertices = new Uint32Array(buffer, o, 3 * count), weights = new Float32Array(buffer, o + 12 * count, 3 * count);
  o += 24 * count;
  const position = new Float32Array(buffer, o, 3 * count), force = new Float32Array(buffer, o + 12 * count, 3 * count);
  // end: where what follows the points starts (the cut region, region.js).
  return { count, toolIds, tool, held, vertices, weights, position, force, end: o + 24 * count };
}

/** The points as plain objects (true positions, m; forces, N), for tests. */
export function listContactPoints(points) {
  const out = [];
  for (let c = 0; c < points.count; ++c)
    out.push({ tool_id: points.toolIds[points.tool[c]], held: points.held[c] === 1,
               position: Array.from(points.position.subarray(3 * c, 3 * c + 3)),
               force: Array.from(points.force.subarray(3 * c, 3 * c + 3)) });
  return out;
}

// Where a contact point is drawn: on the drawn (possibly exaggerated)
// triangle, Σ w_i x_i of its drawn vertices (p: their positions, nv of
// them); at its streamed position when a vertex is unknown to the page.
function pointOnDrawnSurface(points, c, p, nv, out) {
  out.set(0, 0, 0);
  for (let i = 0; i < 3; ++i) {
    const v = points.vertices[3 * c + i], w = points.weights[3 * c + i];
    if (w === 0) continue;
    if (v === NO_VERTEX || v >= nv) return out.fromArray(points.position, 3 * c);
    out.x += w * p[3 * v]; out.y += w * p[3 * v + 1]; out.z += w * p[3 * v + 2];
  }
  return out;
}

/** The markers and arrows of the shown state's contacts, at most `capacity`. */
export class ContactLayer {
  constructor(scene, capacity) {
    const markers = (geometry) => {
      const m = new THREE.InstancedMesh(geometry, new THREE.MeshBasicMaterial({ color: 0xffffff }), capacity);
      m.count = 0;
      m.frustumCulled = false;
      m.setColorAt(0, new THREE.Color());  // makes the per-instance colours
      scene.add(m);
      return m;
    };
    this.scene = scene;
    this.capacity = capacity;
    this.tips = markers(new THREE.SphereGeometry(1, 12, 8));
    this.held = markers(new THREE.BoxGeometry(1.8, 1.8, 1.8));
    this.vertexLoads = markers(new THREE.SphereGeometry(1, 12, 8));
    this.arrows = [];
  }

  /**
   * Draws `points` (readContactPoints) on the drawn surface `p` (3·nv, m),
   * or, when there are none, the constrained vertices `index` (drawn
   * indices) with their forces `force` (3 per vertex); markers of radius r.
   * Returns the counts drawn: { arrows, points, vertexLoads }.
   */
  show(points, index, force, p, nv, r) {
    const m = new THREE.Matrix4(), at = new THREE.Vector3(), f = new THREE.Vector3(), colour = new THREE.Color();
    let arrows = 0, tips = 0, held = 0, loads = 0;
    const place = (mesh, n, hex) => {
      m.makeScale(r, r, r).setPosition(at);
      mesh.setMatrixAt(n, m);
      mesh.setColorAt(n, colour.setHex(hex));
      while (this.arrows.length <= arrows) this.arrows.push(arrow(this.scene, hex));
      this.arrows[arrows].setColor(hex);
      setArrow(this.arrows[arrows++], at, f, 4 * r);
    };
    for (let c = 0; c < points.count && arrows < this.capacity; ++c) {
      pointOnDrawnSurface(points, c, p, nv, at);
      f.fromArray(points.force, 3 * c);
      const hex = toolColour(points.toolIds[points.tool[c]] ?? '');
      if (points.held[c]) place(this.held, held++, hex);
      else place(this.tips, tips++, hex);
    }
    if (points.count === 0) {
      for (let c = 0; c < index.length && arrows < this.capacity; ++c) {
        const v = index[c];
        if (v === NO_VERTEX || v >= nv) continue;
        at.set(p[3 * v], p[3 * v + 1], p[3 * v + 2]);
        f.set(force[3 * c], force[3 * c + 1], force[3 * c + 2]);
        place(this.vertexLoads, loads++, VERTEX_LOAD_COLOR);
      }
    }
    for (let c = arrows; c < this.arrows.length; ++c) this.arrows[c].visible = false;
    for (const [mesh, n] of [[this.tips, tips], [this.held, held], [this.vertexLoads, loads]]) {
      mesh.count = n;
      mesh.instanceMatrix.needsUpdate = true;
      mesh.instanceColor.needsUpdate = true;
    }
    return { arrows, points: tips + held, vertexLoads: loads };
  }

  /** The contact points' markers as drawn (tips, then held): centre (m), colour, held. */
  drawnPoints() {
    const out = [], m = new THREE.Matrix4(), at = new THREE.Vector3(), colour = new THREE.Color();
    for (const [mesh, held] of [[this.tips, false], [this.held, true]])
      for (let n = 0; n < mesh.count; ++n) {
        mesh.getMatrixAt(n, m);
        mesh.getColorAt(n, colour);
        out.push({ held, position: at.setFromMatrixPosition(m).toArray(), colour: colour.getHex() });
      }
    return out;
  }
}
