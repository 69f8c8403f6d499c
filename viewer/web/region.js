// The served cut region (the hybrid model, docs/viewer.md "The cut region"):
// read from the end of a surface frame, and the index buffers it changes:
// the organ's triangles without those the region covers, the region's own
// triangles. No three.js here, so that node can test it (viewer/test/region.test.mjs).

/** No region: a model without one, or a bridge older than the fields. */
export const NO_REGION = Object.freeze({
  version: 0, positions: new Float32Array(0), triangles: new Uint32Array(0), hidden: new Uint32Array(0),
});

/**
 * The region's part of a surface frame (DataView `data`), from byte `o`
 * (where the contact points end): `u32 version_lo, version_hi, nrv, nrt, nh`,
 * `f32 positions[3·nrv]` (m, deformed), `u32 triangles[3·nrt]` (region
 * vertices), `u32 hidden[nh]` (the model's triangles it covers). NO_REGION
 * when the frame ends before it or does not hold what it announces.
 */
export function readRegion(data, o) {
  if (o === undefined || o + 20 > data.byteLength) return NO_REGION;
  const version = data.getUint32(o, true) + 2 ** 32 * data.getUint32(o + 4, true);
  const nrv = data.getUint32(o + 8, true), nrt = data.getUint32(o + 12, true), nh = data.getUint32(o + 16, true);
  o += 20;
  if (version === 0 || o + 4 * (3 * nrv + 3 * nrt + nh) > data.byteLength) return NO_REGION;
  const buffer = data.buffer, base = data.byteOffset + o;
  return {
    version,
    positions: new Float32Array(buffer, base, 3 * nrv),
    triangles: new Uint32Array(buffer, base + 12 * nrv, 3 * nrt),
    hidden: new Uint32Array(buffer, base + 12 * nrv + 12 * nrt, nh),
  };
}

/**
 * The organ's index buffer without the triangles in `hidden` (indices of
 * triangles, i.e. positions in `triangles` / 3; those out of range are
 * ignored): a new Uint32Array, the triangles in their order.
 */
export function organIndexWithout(triangles, hidden) {
  const nt = triangles.length / 3;
  if (hidden.length === 0) return triangles.slice();
  const drop = new Uint8Array(nt);
  for (const t of hidden) if (t < nt) drop[t] = 1;
  let kept = 0;
  for (let t = 0; t < nt; ++t) kept += 1 - drop[t];
  const out = new Uint32Array(3 * kept);
  let k = 0;
  for (let t = 0; t < nt; ++t) {
    if (drop[t]) continue;
    out[k++] = triangles[3 * t]; out[k++] = triangles[3 * t + 1]; out[k++] = triangles[3 * t + 2];
  }
  return out;
}

/**
 * The region's index buffer: its triangles whose corners are all region
 * vertices (nv of them) and not all the same (the bridge sends a bad one as
 * 0, 0, 0), copied: the frame's buffer is not kept.
 */
export function regionIndex(triangles, nv) {
  const keep = [];
  for (let t = 0; t < triangles.length / 3; ++t) {
    const a = triangles[3 * t], b = triangles[3 * t + 1], c = triangles[3 * t + 2];
    if (a < nv && b < nv && c < nv && !(a === b && b === c)) keep.push(a, b, c);
  }
  return Uint32Array.from(keep);
}
