// Browser tests of the page as an instrument (issue 27), in Debian's headless Chromium on the
// WebGL2 fallback (the drawing is not what is tested here; demo.test.mjs covers both backends):
// the Download button's CSV and frame (which `monolayer analyze` reads), the code version in
// share links, and a native run's frames opened in the page. Needs www/pkg (scripts/serve.sh
// --build-only) and the native binary (cargo build --release --bin monolayer).
//
//   node --test --test-reporter=spec tests/browser/viewer.test.mjs
//
// Nothing here depends on the machine's speed: the tests wait for steps, rows and frames, and
// assert counts and values.

import { describe, before, after, it } from 'node:test';
import assert from 'node:assert/strict';
import { chromium } from 'playwright-core';
import { createServer } from 'node:http';
import { readFile, mkdir, mkdtemp, rm, writeFile, copyFile, readdir } from 'node:fs/promises';
import { execFileSync } from 'node:child_process';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

import { parseUrl, toUrl } from '../../www/js/state.js';

const ROOT = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../..');
const WWW = path.join(ROOT, 'www');
const OUT = path.join(ROOT, 'test-output', 'browser');
const NATIVE = process.env.MONOLAYER_BIN
  ?? path.join(process.env.CARGO_TARGET_DIR ?? path.join(ROOT, 'target'), 'release', 'monolayer');
const CHROMIUM = process.env.CHROMIUM ?? '/usr/bin/chromium';
const FLAGS = [
  '--no-sandbox', '--disable-background-networking', '--disable-component-update', '--disable-sync',
  '--no-first-run', '--disable-quic', '--window-size=1280,900', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
];

const TYPES = { '.html': 'text/html', '.js': 'text/javascript', '.css': 'text/css', '.wasm': 'application/wasm', '.png': 'image/png' };
function serve() {
  const server = createServer(async (req, res) => {
    const url = new URL(req.url, 'http://x');
    const rel = decodeURIComponent(url.pathname === '/' ? '/index.html' : url.pathname);
    const file = path.join(WWW, path.normalize(rel));
    if (!file.startsWith(WWW)) return res.writeHead(403).end();
    try {
      const body = await readFile(file);
      res.writeHead(200, { 'content-type': TYPES[path.extname(file)] ?? 'application/octet-stream' });
      res.end(body);
    } catch {
      res.writeHead(404).end();
    }
  });
  return new Promise((ok) => server.listen(0, '127.0.0.1', () => ok(server)));
}

const native = (args) => execFileSync(NATIVE, args, { encoding: 'utf8', env: { ...process.env, RAYON_NUM_THREADS: '1' } });

// --- share links carry the code version (in Node: www/js/state.js) ---------------------------
describe('share links', () => {
  it('carry the code version, and a link from another version says so', () => {
    const mine = '0.1.0+0123456789ab';
    const { state, notices } = parseUrl('?seed=4', mine);
    assert.deepEqual(notices, [], 'a link without a version is not from another one');
    const url = toUrl(state, mine);
    assert.equal(new URLSearchParams(url).get('v'), mine, url);
    assert.deepEqual(parseUrl(url, mine).notices, [], `its own link: ${url}`);
    const other = parseUrl(url, '0.2.0+ba9876543210');
    assert.equal(other.notices.length, 1, String(other.notices));
    assert.match(other.notices[0], /0\.1\.0\+0123456789ab.*0\.2\.0\+ba9876543210/);
    assert.equal(other.state.seed, 4, 'the link still opens its state');
  });
});

// --- the page in Chromium -----------------------------------------------------------------------
describe('the page as an instrument (Chromium, WebGL2)', () => {
  let server;
  let base;
  let context;
  let profile;
  let work;
  const errors = [];

  before(async () => {
    await mkdir(OUT, { recursive: true });
    work = await mkdtemp(path.join(tmpdir(), 'monolayer-viewer-'));
    server = await serve();
    base = `http://127.0.0.1:${server.address().port}`;
    profile = await mkdtemp(path.join(tmpdir(), 'monolayer-chromium-'));
    context = await chromium.launchPersistentContext(profile, {
      executablePath: CHROMIUM, headless: true, args: FLAGS, viewport: { width: 1280, height: 900 }, acceptDownloads: true,
    });
  });
  after(async () => {
    await context?.close();
    server?.close();
    if (profile) await rm(profile, { recursive: true, force: true });
    if (work) await rm(work, { recursive: true, force: true });
  });

  async function open(query) {
    const page = await context.newPage();
    page.on('console', (m) => {
      if (m.type() === 'error') errors.push(`console: ${m.text()}`);
    });
    page.on('pageerror', (e) => errors.push(`pageerror: ${e.message}`));
    await page.goto(base + query);
    await page.waitForFunction(() => window.demo && (window.demo.ready || window.demo.error), null, { timeout: 60000 });
    const err = await page.evaluate(() => window.demo.error);
    assert(!err, `page error: ${err}`);
    return page;
  }

  it('a link from another version opens with a notice, and the page writes its own version into the URL', { timeout: 120000 }, async () => {
    const page = await open('/?seed=1&paused&v=0.0.1%2Bdeadbeef0000');
    const version = await page.evaluate(() => window.demo.version);
    assert.match(version, /^\d+\.\d+\.\d+\+([0-9a-f]{12}|unknown)$/, version);
    const notices = await page.evaluate(() => window.demo.notices);
    assert(notices.some((n) => n.includes('0.0.1+deadbeef0000') && n.includes(version)), `notices: ${notices}`);
    assert.equal(new URL(page.url()).searchParams.get('v'), version, page.url());
    assert(await page.locator('#notice').isVisible(), 'the notice is shown');
    await page.close();
  });

  it('Download gives the readouts as CSV and the state as a frame that monolayer analyze reads', { timeout: 180000 }, async () => {
    const page = await open('/?seed=1');
    // Rows fall every 10 active steps from the start of activity (the shipped relaxed state).
    await page.waitForFunction(() => window.demo.call('readout_rows').then((n) => n >= 4), null, { timeout: 90000, polling: 500 });
    await page.click('#play'); // pause: the readouts and the downloaded state are of one step
    const version = await page.evaluate(() => window.demo.version);
    const downloads = [];
    page.on('download', (d) => downloads.push(d));
    await page.click('#download');
    await page.waitForFunction(() => window.demo.lastDownload !== undefined, null, { timeout: 30000 });
    const stats = await page.evaluate(() => window.demo.call('stats'));
    const info = await page.evaluate(() => window.demo.lastDownload);
    assert.equal(info.step, stats.step, 'the download is of the paused state');
    for (let i = 0; i < 100 && downloads.length < 3; i++) await page.waitForTimeout(100);
    const names = downloads.map((d) => d.suggestedFilename()).sort();
    assert.deepEqual(names, [`frame_${String(stats.step).padStart(7, '0')}.npz`, `monolayer-seed1-step${stats.step}.csv`, 'run.json'].sort());
    const saved = {};
    for (const d of downloads) {
      saved[d.suggestedFilename()] = path.join(work, d.suggestedFilename());
      await d.saveAs(saved[d.suggestedFilename()]);
    }

    // The CSV: a header naming the code version, the seed and the parameters; rows that parse.
    const csv = await readFile(saved[info.csvName], 'utf8');
    await writeFile(path.join(OUT, 'viewer-download.csv'), csv);
    const header = csv.split('\n').filter((l) => l.startsWith('#')).join('\n');
    assert(header.includes(`code version ${version}`), header);
    assert(header.includes('# seed 1'), header);
    const params = JSON.parse(header.match(/parameters at download[^:]*: (\{.*\})/)[1]);
    assert.equal(params.box_size, stats.l);
    assert.equal(params.zeta, stats.zeta);
    const lines = csv.trim().split('\n').filter((l) => !l.startsWith('#'));
    const columns = lines[0].split(',');
    for (const c of ['step', 'time', 'time_s', 'holes', 'void_area', 'packing', 'mean_speed', 'plus_half_defects', 'minus_half_defects']) {
      assert(columns.includes(c), `no column ${c}: ${columns}`);
    }
    const rows = lines.slice(1).map((l) => Object.fromEntries(l.split(',').map((v, i) => [columns[i], Number(v)])));
    assert(rows.length >= 4, `${rows.length} rows`);
    for (const r of rows) for (const [k, v] of Object.entries(r)) assert(Number.isFinite(v), `${k} = ${v}`);
    for (const r of rows.slice(0, -1)) assert.equal((r.step - params.relax_steps) % 10, 0, `row at step ${r.step}`);
    assert.equal(rows[0].step, params.relax_steps, 'rows start with activity');
    assert.equal(rows[0].time, 0);
    // Its last row is the state the page shows: the same readouts.
    const last = rows.at(-1);
    assert.equal(last.step, stats.step);
    assert.equal(last.holes, stats.holes);
    assert.equal(last.void_area, stats.area);
    assert.equal(last.packing, stats.packing);
    assert.equal(last.time, stats.time);
    assert(Math.abs(last.time_s - stats.time * stats.timeUnitSeconds) < 1e-9);

    // The frame with its run.json is a run `monolayer analyze` reads.
    const run = path.join(work, 'run');
    await mkdir(path.join(run, 'frames'), { recursive: true });
    await copyFile(saved['run.json'], path.join(run, 'run.json'));
    await copyFile(saved[info.frameName], path.join(run, 'frames', info.frameName));
    native(['analyze', run, '--out', path.join(work, 'analysis')]);
    assert((await readdir(path.join(work, 'analysis'))).length > 0, 'analyze wrote nothing');
    assert(errors.length === 0, errors.join('\n'));
    await page.close();
  });
});
