// Browser tests of the page as an instrument, in Debian's headless Chromium on the
// WebGL2 fallback (VIEWER_BACKEND=webgpu for WebGPU; demo.test.mjs covers both backends):
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
import { readFile, mkdir, mkdtemp, rm, writeFile, copyFile, readdir } from 'node:fs/promises';
import { execFileSync } from 'node:child_process';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { parseReadouts } from './readouts.mjs';
import { serve } from './server.mjs';

import { parseUrl, toUrl } from '../../www/js/state.js';

const ROOT = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../..');
const OUT = path.join(ROOT, 'test-output', 'browser');
const NATIVE = process.env.MONOLAYER_BIN
  ?? path.join(process.env.CARGO_TARGET_DIR ?? path.join(ROOT, 'target'), 'release', 'monolayer');
const CHROMIUM = process.env.CHROMIUM ?? '/usr/bin/chromium';
// WebGL2 by default; VIEWER_BACKEND=webgpu runs the same tests on WebGPU (SwiftShader).
const WEBGPU = process.env.VIEWER_BACKEND === 'webgpu';
const FLAGS = [
  '--no-sandbox', '--disable-background-networking', '--disable-component-update', '--disable-sync',
  '--no-first-run', '--disable-quic', '--window-size=1280,900', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
  ...(WEBGPU ? ['--enable-unsafe-webgpu', '--enable-features=Vulkan', '--use-vulkan=swiftshader'] : []),
];

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
describe(`the page as an instrument (Chromium, ${WEBGPU ? 'WebGPU' : 'WebGL2'})`, () => {
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
    const page = await open('/?preset=persistent&seed=1&paused&v=0.0.1%2Bdeadbeef0000');
    const backend = await page.evaluate(() => window.demo.backend);
    assert(backend.startsWith(WEBGPU ? 'WebGPU' : 'WebGL2'), `drawing with ${backend}`);
    const version = await page.evaluate(() => window.demo.version);
    assert.match(version, /^\d+\.\d+\.\d+\+([0-9a-f]{12}|unknown)$/, version);
    const notices = await page.evaluate(() => window.demo.notices);
    assert(notices.some((n) => n.includes('0.0.1+deadbeef0000') && n.includes(version)), `notices: ${notices}`);
    assert.equal(new URL(page.url()).searchParams.get('v'), version, page.url());
    assert(await page.locator('#notice').isVisible(), 'the notice is shown');
    await page.close();
  });

  it('Download gives the readouts as CSV and the state as a frame that monolayer analyze reads', { timeout: 180000 }, async () => {
    const page = await open('/?preset=persistent&seed=1');
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
    const { header, rowEvery, columns, rows } = parseReadouts(csv);
    assert(header.includes(`code version ${version}`), header);
    assert(header.includes('# seed 1'), header);
    const params = JSON.parse(header.match(/parameters at download[^:]*: (\{.*\})/)[1]);
    assert.equal(params.box_size, stats.l);
    assert.equal(params.zeta, stats.zeta);
    for (const c of ['step', 'time', 'time_s', 'holes', 'void_area', 'packing', 'mean_speed', 'plus_half_defects', 'minus_half_defects']) {
      assert(columns.includes(c), `no column ${c}: ${columns}`);
    }
    assert(rows.length >= 4, `${rows.length} rows`);
    for (const r of rows) for (const [k, v] of Object.entries(r)) assert(Number.isFinite(v), `${k} = ${v}`);
    assert.equal(rowEvery, 10, 'the header states a row every 10 active steps');
    for (const r of rows.slice(0, -1)) assert.equal((r.step - params.relax_steps) % rowEvery, 0, `row at step ${r.step}`);
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

  it("a native run's frames open in the page, play, and show the analysis of `monolayer analyze`; a damaged frame is reported and skipped", { timeout: 240000 }, async () => {
    // A small run: frames at the end of relaxation (step 300) and every 10 steps to 340; 14
    // cells cover about 80 % of the box, so that the frames hold holes.
    const run = path.join(work, 'native-run');
    native(['run', '--quiet', '--set', 'box_size=60', '--set', 'n_cells=14', '--relax-steps', '300', '--steps', '40',
      '--frame-interval', '10', '--threads', '1', '--out', run]);
    native(['analyze', run, '--out', path.join(work, 'native-analysis')]);
    const table = (await readFile(path.join(work, 'native-analysis', 'frames.csv'), 'utf8')).trim().split('\n');
    const cols = table[0].split(',');
    const byStep = new Map(table.slice(1).map((l) => {
      const r = Object.fromEntries(l.split(',').map((v, i) => [cols[i], Number(v)]));
      return [r.step, r];
    }));
    const frameDir = path.join(run, 'frames');
    const names = (await readdir(frameDir)).filter((n) => n.endsWith('.npz')).sort();
    assert.deepEqual(names, [300, 310, 320, 330, 340].map((s) => `frame_${String(s).padStart(7, '0')}.npz`));
    // Damage one frame (cut in half), and add a file that is no part of a run.
    const damaged = path.join(frameDir, 'frame_0000320.npz');
    const bytes = await readFile(damaged);
    await writeFile(damaged, bytes.subarray(0, bytes.length >> 1));
    await writeFile(path.join(work, 'state.npz'), 'not a frame');

    const page = await open('/?preset=persistent&seed=1&field=director');
    await page.setInputFiles('#open-files', [path.join(run, 'run.json'), ...names.map((n) => path.join(frameDir, n)), path.join(work, 'state.npz')]);
    await page.waitForFunction(() => window.demo.playback.opened === 1, null, { timeout: 60000 });
    const pb = await page.evaluate(() => window.demo.playback);
    assert.deepEqual(pb.frames.map((f) => f.step), [300, 310, 330, 340], 'the good frames, in step order');
    assert(pb.errors.some((e) => e.startsWith('frame_0000320.npz: not a readable .npz')), `errors: ${pb.errors}`);
    assert(pb.errors.some((e) => e.startsWith('state.npz: not a frame')), `errors: ${pb.errors}`);
    assert.match(await page.textContent('#player-errors'), /frame_0000320\.npz/);
    assert(await page.locator('#player').isVisible(), 'the player is shown');

    // Each frame through the slider: drawn with its defects and its holes as analyze measures them.
    let holesSeen = 0;
    for (const [i, f] of pb.frames.entries()) {
      await page.evaluate((i) => {
        const s = document.getElementById('player-slider');
        s.value = String(i);
        s.dispatchEvent(new Event('input'));
      }, i);
      await page.waitForFunction((step) => window.demo.stats?.step === step && window.demo.stats.startedFrom === 'frames', f.step, { timeout: 30000 });
      const st = await page.evaluate(() => window.demo.stats);
      const row = byStep.get(f.step);
      assert.equal(st.l, 60);
      assert.equal(st.cells, 14);
      holesSeen += st.holes;
      assert(Math.abs(st.area / 3600 - row.void_fraction) < 1e-6, `step ${f.step}: void ${st.area} sites, analyze ${row.void_fraction}`);
      assert(Math.abs(st.packing - row.packing_fraction) < 1e-6, `step ${f.step}: packing ${st.packing}, analyze ${row.packing_fraction}`);
      const d = await page.evaluate(() => window.demo.call('defects'));
      const plus = d.filter((x) => x.twiceCharge > 0).length;
      const minus = d.filter((x) => x.twiceCharge < 0).length;
      assert.deepEqual([plus, minus], [row.plus_half_defects, row.minus_half_defects], `step ${f.step}: ±½ defects`);
    }
    assert(holesSeen > 0, 'no holes in the frames: the test proves little');
    await page.locator('#view').screenshot({ path: path.join(OUT, `viewer-frame-${WEBGPU ? 'webgpu' : 'webgl2'}.png`) });

    // Play: every frame is shown, in turn.
    await page.click('#player-play');
    const from = (await page.evaluate(() => window.demo.playback.shown.length));
    await page.waitForFunction(({ from, steps }) => {
      const seen = new Set(window.demo.playback.shown.slice(from));
      return steps.every((s) => seen.has(s));
    }, { from, steps: pb.frames.map((f) => f.step) }, { timeout: 60000 });
    // Recording works on the frames as on the live tissue: a WebM of four more frames shown.
    await page.click('#record');
    const recFrom = await page.evaluate(() => window.demo.playback.shown.length);
    await page.waitForFunction((n) => window.demo.playback.shown.length >= n + 4, recFrom, { timeout: 60000 });
    await page.click('#record');
    await page.waitForFunction(() => window.demo.lastRecording, null, { timeout: 30000 });
    const rec = await page.evaluate(() => window.demo.lastRecording);
    assert(rec.type === 'video/webm' && rec.size > 1000 && rec.head === '1a45dfa3', `recording ${JSON.stringify(rec)}`);
    await page.click('#player-play');

    // Step shows the next frame; Download, which takes data out of the live simulation, says so.
    const shownBefore = await page.evaluate(() => window.demo.playback.shown.length);
    await page.click('#step');
    await page.waitForFunction((n) => window.demo.playback.shown.length > n, shownBefore, { timeout: 30000 });
    await page.click('#download');
    await page.waitForFunction(() => window.demo.notices.some((n) => n.startsWith('Download: ')), null, { timeout: 30000 });
    assert.equal(await page.evaluate(() => window.demo.error), null);

    // The run directory itself, picked: its frames, the damaged one named, its other files
    // (checkpoint, lock) skipped without a word.
    await page.setInputFiles('#open-dir', run);
    await page.waitForFunction(() => window.demo.playback.opened === 2, null, { timeout: 60000 });
    const dir = await page.evaluate(() => window.demo.playback);
    assert.deepEqual(dir.frames.map((f) => f.step), [300, 310, 330, 340]);
    assert.equal(dir.errors.length, 1, `errors: ${dir.errors}`);
    assert.match(dir.errors[0], /^frame_0000320\.npz: /);

    // A drop (DataTransfer) of run.json and two frames opens them in turn.
    const dropped = await Promise.all(['run.json', 'frames/frame_0000310.npz', 'frames/frame_0000340.npz']
      .map(async (n) => [path.basename(n), (await readFile(path.join(run, n))).toString('base64')]));
    const dt = await page.evaluateHandle((files) => {
      const dt = new DataTransfer();
      for (const [name, b64] of files) dt.items.add(new File([Uint8Array.from(atob(b64), (c) => c.charCodeAt(0))], name));
      return dt;
    }, dropped);
    await page.dispatchEvent('#view', 'drop', { dataTransfer: dt });
    await page.waitForFunction(() => window.demo.playback.opened === 3, null, { timeout: 60000 });
    assert.deepEqual(await page.evaluate(() => window.demo.playback.frames.map((f) => f.step)), [310, 340]);
    assert.deepEqual(await page.evaluate(() => window.demo.playback.errors), []);

    // Reset returns to the live tissue.
    await page.click('#reset');
    await page.waitForFunction(() => window.demo.stats?.startedFrom !== 'frames' && window.demo.stats.l === 80, null, { timeout: 60000 });
    assert(!(await page.locator('#player').isVisible()), 'the player is hidden again');
    assert(errors.length === 0, errors.join('\n'));
    await page.close();
  });
});
