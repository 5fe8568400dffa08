// How heavy the page is to load: the bytes sent over the wire, the time to the first frame and
// the time to the first hole, in headless Chromium (WebGL2 on SwiftShader) under the DevTools
// protocol's network throttling, a "Fast 3G" profile (Chrome DevTools' own preset: 562.5 ms of
// latency, 180,000 bytes/s down, 84,375 up). A measurement, reported, not a test: the results
// are recorded in docs/performance.md.
//
//   node tests/browser/load.mjs                   the page as served (gzip on)
//   GZIP=0 node tests/browser/load.mjs            nothing compressed on the wire
//   ISOLATED=0 node tests/browser/load.mjs        no COOP/COEP: the single-thread core only
//   RUNS=3 …                                      repeats (a fresh profile each: a cold cache)

import { chromium } from 'playwright-core';
import { mkdtemp, rm } from 'node:fs/promises';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { serve } from './server.mjs';
import { CHROMIUM } from './drivers.mjs';

export const FAST_3G = { offline: false, latency: 562.5, downloadThroughput: 180000, uploadThroughput: 84375 };

const runs = Number(process.env.RUNS ?? 1);
const files = new Map();
const server = await serve({
  gzip: process.env.GZIP !== '0',
  isolated: process.env.ISOLATED !== '0',
  sent: (file, bytes) => files.set(file, (files.get(file) ?? 0) + bytes),
});
const base = `http://127.0.0.1:${server.address().port}`;
const results = [];
for (let r = 0; r < runs; r++) {
  files.clear();
  const profile = await mkdtemp(path.join(tmpdir(), 'monolayer-load-'));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: CHROMIUM, headless: true, viewport: { width: 1280, height: 900 },
    args: ['--no-sandbox', '--disable-background-networking', '--disable-component-update', '--no-first-run',
      '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
  });
  const page = await context.newPage();
  const cdp = await context.newCDPSession(page);
  await cdp.send('Network.enable');
  await cdp.send('Network.emulateNetworkConditions', FAST_3G);
  await page.goto(`${base}/`);
  await page.waitForFunction(() => window.demo?.firstFrameMs !== undefined || window.demo?.error, null, { timeout: 600000, polling: 50 });
  const firstFrameMs = await page.evaluate(() => window.demo.firstFrameMs);
  await page.waitForFunction(() => window.demo.firstHole !== null, null, { timeout: 1800000, polling: 100 });
  const hole = await page.evaluate(() => ({ ...window.demo.firstHole, backend: window.demo.backend, threads: window.demo.threads, coreNote: window.demo.coreNote }));
  const bytes = [...files.values()].reduce((a, b) => a + b, 0);
  results.push({ bytes, files: Object.fromEntries(files), firstFrameS: firstFrameMs / 1000, firstHoleS: hole.sinceNavigationMs / 1000, hole });
  console.log(JSON.stringify(results.at(-1)));
  await context.close();
  await rm(profile, { recursive: true, force: true });
}
server.close();
