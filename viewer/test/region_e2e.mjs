// End-to-end test of the viewer drawing a served cut region (docs/viewer.md,
// "The cut region"), in headless Chromium (Debian's package, driven by
// playwright-core): the page of a model whose region palpated simulates
// draws the region as its own mesh and the organ without the triangles the
// region covers; the page of a model without one draws every triangle of
// its description, as before the region's fields. Screenshots go to --out.
//
// Started by tests/viewer/region_e2e.sh inside a private network namespace,
// with palpated and palpate-viewer already running.
//
//   node region_e2e.mjs --url URL --model ID --plain ID --out DIR
//
// --model: a model served with its cut region; --plain: one without.

import { mkdirSync } from 'node:fs';
import { join } from 'node:path';
import { parseArgs } from 'node:util';
import { chromium } from 'playwright-core';

const { values: args } = parseArgs({
  options: {
    url: { type: 'string' }, model: { type: 'string' }, plain: { type: 'string' }, out: { type: 'string' },
    chromium: { type: 'string', default: process.env.PALPATE_CHROMIUM || '/usr/bin/chromium' },
  },
});
for (const key of ['url', 'model', 'plain', 'out'])
  if (!args[key]) { console.error(`region_e2e: --${key} is required`); process.exit(2); }
mkdirSync(args.out, { recursive: true });

const TIMEOUT_MS = 20000;
// Positions travel as float32: a coordinate of a 0.2 m organ keeps ~1e-8 m;
// at rest the region's vertices lie on the organ's box up to that.
const FLOAT32_M = 1e-6;

let failures = 0;
function check(condition, what, detail) {
  console.log(`${condition ? 'ok  ' : 'FAIL'} ${what}${detail === undefined ? '' : `: ${detail}`}`);
  if (!condition) failures += 1;
}

const browser = await chromium.launch({
  executablePath: args.chromium,
  args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
         '--disable-background-networking', '--disable-component-update', '--disable-sync',
         '--no-first-run', '--disable-quic'],
});
const errors = [];
async function openPage(model) {
  const page = await browser.newPage({ viewport: { width: 1000, height: 640 } });
  page.on('pageerror', (e) => errors.push(e.message));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  await page.goto(`${args.url}?model=${encodeURIComponent(model)}&fps=30&follow=0`);
  await page.waitForFunction(() => {
    const v = window.palpateViewer;
    return v && v.connected && v.surfacesReceived > 0 && v.framesRendered > 1;
  }, null, { timeout: TIMEOUT_MS });
  return page;
}
const state = (page) => page.evaluate(() => {
  const v = window.palpateViewer;
  return { modelId: v.modelId, triangleCount: v.triangleCount, topologyVersion: v.topologyVersion,
           organTriangles: v.organTriangles, regionTriangles: v.regionTriangles, regionVertices: v.regionVertices,
           hidden: v.hiddenTriangles(), organIndex: v.drawnOrganTriangles(), regionIndex: v.drawnRegionTriangles(),
           regionPositions: v.drawnRegionPositions(), rest: v.restPositions(), model: document.querySelector('#model').textContent };
});

try {
  // 1. The model with its region: two meshes, the covered triangles left out.
  const page = await openPage(args.model);
  await page.waitForFunction(() => window.palpateViewer.topologyVersion > 0, null, { timeout: TIMEOUT_MS }).catch(() => {});
  const cut = await state(page);
  check(cut.modelId === args.model, 'the page shows the model with the region', cut.modelId);
  check(cut.topologyVersion >= 1, 'its surface samples carry the region', `topology version ${cut.topologyVersion}`);
  check(/cut region /.test(cut.model), 'the panel names the cut region', cut.model);
  const hidden = new Set(cut.hidden);
  check(cut.hidden.length > 0 && hidden.size === cut.hidden.length && cut.hidden.every((t) => t < cut.triangleCount),
    'the region covers some of the description\'s triangles, each once', `${cut.hidden.length} of ${cut.triangleCount}`);
  check(cut.organTriangles === cut.triangleCount - cut.hidden.length && cut.organIndex.length === 3 * cut.organTriangles,
    'the organ draws every triangle but those', `${cut.organTriangles} drawn`);
  check(cut.regionTriangles > 0 && cut.regionIndex.length === 3 * cut.regionTriangles &&
        cut.regionIndex.every((v) => v < cut.regionVertices),
    'the region draws its own triangles on its own vertices', `${cut.regionTriangles} triangles, ${cut.regionVertices} vertices`);
  // At rest the region sits inside the organ's rest bounding box (it is a part of the organ).
  const lo = [0, 1, 2].map((c) => Math.min(...cut.rest.filter((_, i) => i % 3 === c)));
  const hi = [0, 1, 2].map((c) => Math.max(...cut.rest.filter((_, i) => i % 3 === c)));
  const outside = cut.regionPositions.filter((x, i) => x < lo[i % 3] - FLOAT32_M || x > hi[i % 3] + FLOAT32_M).length;
  check(cut.regionPositions.length === 3 * cut.regionVertices && cut.regionPositions.every(Number.isFinite) && outside === 0,
    'the region\'s vertices are drawn inside the organ\'s box at rest', `${outside} coordinates outside`);
  await page.screenshot({ path: join(args.out, 'region.png') });

  // 2. The model without a region: drawn exactly as before the fields.
  const plainPage = await openPage(args.plain);
  const plain = await state(plainPage);
  check(plain.modelId === args.plain && plain.topologyVersion === 0 && plain.regionTriangles === 0 &&
        plain.regionIndex.length === 0 && plain.hidden.length === 0,
    'a model without a region draws no region', `version ${plain.topologyVersion}`);
  check(plain.organTriangles === plain.triangleCount && plain.organIndex.length === 3 * plain.triangleCount,
    'and every triangle of its description', `${plain.organTriangles} of ${plain.triangleCount}`);
  check(!/cut region/.test(plain.model), 'its panel names no cut region', plain.model);
  await plainPage.screenshot({ path: join(args.out, 'plain.png') });

  check(errors.length === 0, 'no errors in the pages', errors.join(' | '));
} catch (e) {
  console.log(`FAIL ${e.message}`);
  failures += 1;
} finally {
  await browser.close();
}
console.log(failures === 0 ? 'region_e2e: all checks passed' : `region_e2e: ${failures} check(s) failed`);
process.exit(failures === 0 ? 0 : 1);
