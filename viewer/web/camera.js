// Where the camera stands: framed on the whole organ at rest, its
// attachment in sight, or (when tools come near) on the tools. Units: m.
//
// The model description gives the browser the drawn surface only: the
// compliance vertices first, then the fixed (attached) ones; it marks no
// tumour (an inner volume), so the organ's framing is its bounding box, which
// holds the tumour too.

import * as THREE from 'three';

// The view when nothing says better (no attachment): from the front (−y),
// a little to the right and above, as a surgeon faces a lying organ.
const DEFAULT_DIRECTION = new THREE.Vector3(0.2, -1, 0.55).normalize();
// The organ's box fills at most this share of the half-width and half-height
// of the view: a small margin. The box's corners lie outside a rounded organ,
// so the organ itself keeps a wider one.
const FILL = 0.95;

/** The axis-aligned box of vertices [first, last) of positions (xyz…). */
export function boxOf(positions, first = 0, last = positions.length / 3) {
  const box = new THREE.Box3(), p = new THREE.Vector3();
  for (let v = first; v < last; ++v) box.expandByPoint(p.fromArray(positions, 3 * v));
  return box;
}

export function boxCorners(box) {
  const corners = [];
  for (const x of [box.min.x, box.max.x])
    for (const y of [box.min.y, box.max.y])
      for (const z of [box.min.z, box.max.z]) corners.push(new THREE.Vector3(x, y, z));
  return corners;
}

/**
 * The direction, from the organ's centre towards the camera, that shows the
 * attached region (drawn vertices [ns, nv)) and the organ beside it: halfway
 * between "straight at the attachment" and the default view made
 * perpendicular to it (45° off the attachment, so its patch is seen and the
 * organ's side is not hidden behind it). The default view when nothing is
 * attached, or the attachment surrounds the centre.
 */
export function attachmentViewDirection(rest, ns, nv, centre) {
  if (nv <= ns) return DEFAULT_DIRECTION.clone();
  const attached = new THREE.Vector3(), p = new THREE.Vector3();
  for (let v = ns; v < nv; ++v) attached.add(p.fromArray(rest, 3 * v));
  attached.divideScalar(nv - ns).sub(centre);
  if (attached.lengthSq() < 1e-18) return DEFAULT_DIRECTION.clone();
  attached.normalize();
  const side = DEFAULT_DIRECTION.clone().addScaledVector(attached, -DEFAULT_DIRECTION.dot(attached));
  if (side.lengthSq() < 1e-6) side.crossVectors(attached, new THREE.Vector3(0, 0, 1));  // attached in front
  if (side.lengthSq() < 1e-6) side.set(0, -1, 0);
  const direction = attached.add(side.normalize()).normalize();
  // Orbit controls cannot turn about z when looking straight along it.
  if (Math.abs(direction.z) > 0.97) direction.add(new THREE.Vector3(0, -0.3, 0)).normalize();
  return direction;
}

/** The camera's right and up axes when it looks along −direction with `up` up (as Object3D.lookAt). */
function viewAxes(direction, up) {
  const right = new THREE.Vector3().crossVectors(up, direction);
  if (right.lengthSq() < 1e-12) right.set(1, 0, 0);  // looking along up: any right will do
  right.normalize();
  return { right, up: new THREE.Vector3().crossVectors(direction, right) };
}

/**
 * The smallest distance from target, along direction, from which a
 * perspective camera (vertical field of view fovDeg, aspect w/h, up vector
 * `up`) sees every point in `points` within FILL of its half-width and
 * half-height. For a point q = p − target at distance D the depth is
 * D − q·d, so it is in view when |q·right| ≤ FILL·tan(hfov/2)·(D − q·d) and
 * |q·upAxis| ≤ FILL·tan(vfov/2)·(D − q·d): D ≥ q·d + |q·right| / (FILL·tanH),
 * and the same with the up axis.
 */
export function fitDistance(points, target, direction, up, fovDeg, aspect) {
  const tanV = FILL * Math.tan(THREE.MathUtils.degToRad(fovDeg) / 2), tanH = tanV * aspect;
  const { right, up: upAxis } = viewAxes(direction, up);
  const q = new THREE.Vector3();
  let distance = 0;
  for (const p of points) {
    q.subVectors(p, target);
    const along = q.dot(direction);
    distance = Math.max(distance, along + Math.abs(q.dot(right)) / tanH, along + Math.abs(q.dot(upAxis)) / tanV);
  }
  return distance;
}

/** Near and far planes that hold every point seen from target + distance·direction. */
export function depthRange(points, target, direction, distance) {
  let nearest = Infinity, farthest = 0;
  for (const p of points) {
    const depth = distance - p.clone().sub(target).dot(direction);
    nearest = Math.min(nearest, depth);
    farthest = Math.max(farthest, depth);
  }
  // Room to zoom and orbit (the far plane) without clipping the organ.
  return { near: Math.max(Math.min(distance / 100, 0.5 * nearest), distance / 1e4), far: Math.max(20 * distance, 2 * farthest) };
}

/**
 * Puts the camera at target + distance·direction looking at target, the
 * orbit controls around target and the sun behind the camera, above it.
 */
export function placeCamera({ camera, controls, sun }, target, direction, distance, planes) {
  controls.target.copy(target);
  camera.position.copy(target).addScaledVector(direction.clone().normalize(), distance);
  sun.position.copy(camera.position).add(new THREE.Vector3(0, 0, distance));
  sun.target.position.copy(target);
  camera.near = planes?.near ?? distance / 100;
  camera.far = planes?.far ?? distance * 20;
  camera.updateProjectionMatrix();
  controls.update();
}

/**
 * Sets the camera's aspect for a canvas of width × height px whose left
 * `covered` px the panel hides, and shifts its image so that what it looks
 * at is in the middle of the rest (unless the panel takes most of a narrow
 * window: then the panel is ignored). Leaves camera.userData.freeAspect, the
 * aspect of the free part, for framing, and .freeNdcLeft, where the free part
 * starts in normalised device coordinates.
 */
export function fitToFreeArea(camera, width, height, covered) {
  const hidden = covered < 0.6 * width ? covered : 0;
  camera.aspect = width / Math.max(height, 1);
  if (hidden > 0) camera.setViewOffset(width, height, -hidden / 2, 0, width, height);
  else camera.clearViewOffset();
  camera.userData.freeAspect = (width - hidden) / Math.max(height, 1);
  camera.userData.freeNdcLeft = -1 + 2 * hidden / Math.max(width, 1);
  camera.updateProjectionMatrix();
}

/** Frames the organ at rest: its whole bounding box, its attachment in sight. */
export function frameOrgan(rig, organ) {
  const { camera } = rig;
  const corners = boxCorners(organ.box);
  const direction = attachmentViewDirection(organ.rest, organ.ns, organ.nv, organ.centre);
  const aspect = camera.userData.freeAspect ?? camera.aspect;
  const distance = fitDistance(corners, organ.centre, direction, camera.up, camera.fov, aspect);
  placeCamera(rig, organ.centre, direction, distance, depthRange(corners, organ.centre, direction, distance));
}

/** Where the page's camera projects the corners of box: [[x, y, z]] in normalised device coordinates. */
export function projectCorners(camera, box) {
  camera.updateMatrixWorld();
  return boxCorners(box).map((c) => c.project(camera).toArray());
}

/**
 * Where to look at tools that came near the organ (`near`: their tools
 * messages): at their mean position, from outside the organ (back along the
 * shafts and away from its centre), a little from the side so that the
 * shafts do not hide the tips. { target, direction }.
 */
export function toolsViewpoint(near, organCentre) {
  const target = new THREE.Vector3(), back = new THREE.Vector3(), side = new THREE.Vector3();
  for (const t of near) {
    const q = new THREE.Quaternion(t.orientation[1], t.orientation[2], t.orientation[3], t.orientation[0]);
    target.add(new THREE.Vector3().fromArray(t.position));
    back.add(new THREE.Vector3(0, 0, -1).applyQuaternion(q));
    side.add(new THREE.Vector3(0, 1, 0).applyQuaternion(q));
  }
  target.divideScalar(near.length);
  const outward = target.clone().sub(organCentre).normalize();
  const direction = back.normalize().add(outward).normalize().add(side.normalize().multiplyScalar(0.45));
  return { target, direction };
}
