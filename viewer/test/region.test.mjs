// Unit tests of viewer/web/region.js (node --test; no browser, no three.js):
// the served cut region read from the end of a surface frame, and the index
// buffers it changes. CTest: viewer_region_js.

import assert from 'node:assert/strict';
import { test } from 'node:test';
import { NO_REGION, organIndexWithout, readRegion, regionIndex } from '../web/region.js';

// The region's part of a surface frame, after `lead` bytes of what precedes it.
function regionBytes(lead, version, positions, triangles, hidden) {
  const words = 5 + positions.length + triangles.length + hidden.length;
  const buffer = new ArrayBuffer(lead + 4 * words), data = new DataView(buffer);
  let o = lead;
  const u32 = (v) => { data.setUint32(o, v, true); o += 4; };
  u32(version % 2 ** 32); u32(Math.floor(version / 2 ** 32));
  u32(positions.length / 3); u32(triangles.length / 3); u32(hidden.length);
  for (const x of positions) { data.setFloat32(o, x, true); o += 4; }
  triangles.forEach(u32);
  hidden.forEach(u32);
  return data;
}

// Two triangles on a unit square of the organ, a tetrahedron's four faces for the region.
const ORGAN = Uint32Array.from([0, 1, 2, 0, 2, 3, 1, 3, 2]);
const TET = [0, 0, 0, 0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01];
const TET_FACES = [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3];

test('a frame without the region, or with version 0, reads as no region', () => {
  assert.equal(readRegion(new DataView(new ArrayBuffer(8)), undefined), NO_REGION);
  assert.equal(readRegion(new DataView(new ArrayBuffer(8)), 8), NO_REGION);  // ends where the points end
  assert.equal(readRegion(regionBytes(8, 0, [], [], []), 8), NO_REGION);
});

test('a region reads its version, positions, triangles and hidden triangles in place', () => {
  const data = regionBytes(12, 2 ** 32 + 5, TET, TET_FACES, [1]);
  const r = readRegion(data, 12);
  assert.equal(r.version, 2 ** 32 + 5);
  assert.equal(r.positions.length, 12);
  // float32 on the wire: 0.01 m to its float32 value.
  assert.ok(Math.abs(r.positions[3] - 0.01) < 1e-9);
  assert.deepEqual(Array.from(r.triangles), TET_FACES);
  assert.deepEqual(Array.from(r.hidden), [1]);
});

test('a region that announces more than the frame holds is not read', () => {
  const data = regionBytes(0, 3, TET, TET_FACES, [1]);
  const cut = new DataView(data.buffer.slice(0, data.byteLength - 4));
  assert.equal(readRegion(cut, 0), NO_REGION);
});

test('the organ draws every triangle but those the region covers', () => {
  assert.deepEqual(Array.from(organIndexWithout(ORGAN, [])), Array.from(ORGAN));
  assert.notEqual(organIndexWithout(ORGAN, []), ORGAN);  // a copy: the frame is not kept
  assert.deepEqual(Array.from(organIndexWithout(ORGAN, Uint32Array.from([1]))), [0, 1, 2, 1, 3, 2]);
  assert.deepEqual(Array.from(organIndexWithout(ORGAN, Uint32Array.from([2, 0, 2]))), [0, 2, 3]);
  // Out of range: ignored (a description and a stream of different versions).
  assert.deepEqual(Array.from(organIndexWithout(ORGAN, Uint32Array.from([7]))), Array.from(ORGAN));
});

test('the region draws its triangles on its own vertices, the bad ones left out', () => {
  assert.deepEqual(Array.from(regionIndex(Uint32Array.from(TET_FACES), 4)), TET_FACES);
  // (0, 0, 0) is how the bridge sends a triangle naming a missing vertex; 9 is one.
  assert.deepEqual(Array.from(regionIndex(Uint32Array.from([0, 0, 0, 0, 1, 9, 1, 2, 3]), 4)), [1, 2, 3]);
});
