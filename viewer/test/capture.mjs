// Screenshots of the live viewer from headless Chromium, for the demo
// (scripts/demo.sh) on machines without a display: opens the page, prints
// "capture: ready" once the organ is drawn, then takes a screenshot every
// --interval seconds for --seconds seconds, and copies the one with the
// most going on (largest displacement, most contacts; on a served cut
// region, among those of its latest topology version: after the last cut)
// to DIR/viewer.png.
//
//   node capture.mjs --url URL --out DIR [--seconds 8] [--interval 0.5] [--model ID]
//
// With --interval 0 it takes no screenshot: it watches the page for
// --seconds and prints what the page drew, as JSON (bench/viewer_impact.sh).

import { copyFileSync, mkdirSync } from 'node:fs';
import { join } from 'node:path';
import { parseArgs } from 'node:util';
import { chromium } from 'playwright-core';

const { values: args } = parseArgs({
  options: {
    url: { type: 'string' }, out: { type: 'string' }, model: { type: 'string', default: '' },
    seconds: { type: 'string', default: '8' }, interval: { type: 'string', default: '0.5' },
    width: { type: 'string', default: '1280' }, height: { type: 'string', default: '800' },
    chromium: { type: 'string', default: process.env.PALPATE_CHROMIUM || '/usr/bin/chromium' },
  },
});
if (!args.url || !args.out) { console.error('capture: --url and --out are required'); process.exit(2); }
mkdirSync(args.out, { recursive: true });

const browser = await chromium.launch({
  executablePath: args.chromium,
  args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
         '--disable-background-networking', '--disable-component-update', '--disable-sync',
         '--no-first-run', '--disable-quic'],
});
let status = 0;
try {
  const page = await browser.newPage({ viewport: { width: Number(args.width), height: Number(args.height) } });
  const query = args.model ? `?model=${encodeURIComponent(args.model)}&fps=20` : '?fps=20';
  await page.goto(args.url + query);
  await page.waitForFunction(() => window.palpateViewer?.vertexCount > 0 && window.palpateViewer.framesRendered > 0,
                             null, { timeout: 30000 });
  console.log('capture: ready');
  if (Number(args.interval) === 0) {
    const count = () => page.evaluate(() => ({ frames: window.palpateViewer.framesRendered,
                                               surfaces: window.palpateViewer.surfacesReceived }));
    const before = await count(), t0 = Date.now();
    await page.waitForTimeout(1000 * Number(args.seconds));
    const after = await count(), seconds = (Date.now() - t0) / 1000;
    console.log(JSON.stringify({ seconds, frames_per_s: (after.frames - before.frames) / seconds,
                                 surfaces_per_s: (after.surfaces - before.surfaces) / seconds }));
    process.exitCode = 0;
    await browser.close();
    process.exit(0);
  }
  const shots = Math.max(1, Math.round(Number(args.seconds) / Number(args.interval)));
  // A served cut region that was cut is what to show: a frame of a later
  // topology version (more cut) beats any earlier one, then the liveliest.
  let best = { version: -1, score: -1, file: '' };
  for (let i = 1; i <= shots; ++i) {
    await page.waitForTimeout(1000 * Number(args.interval));
    const v = await page.evaluate(() => ({ d: window.palpateViewer.maxDisplacement_m, c: window.palpateViewer.contacts,
                                           t: window.palpateViewer.topologyVersion }));
    const file = join(args.out, `viewer-${String(i).padStart(2, '0')}.png`);
    await page.screenshot({ path: file });
    const score = v.d * (1 + v.c);
    if (v.t > best.version || (v.t === best.version && score > best.score)) best = { version: v.t, score, file };
  }
  copyFileSync(best.file, join(args.out, 'viewer.png'));
  console.log(`capture: ${shots} screenshots in ${args.out}; the liveliest is viewer.png`);
} catch (e) {
  console.error(`capture: ${e.message.split('\n')[0]}`);
  status = 1;
} finally {
  await browser.close();
}
process.exit(status);
