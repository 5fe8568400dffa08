// The list of checks every browser engine runs (engines.test.mjs), written once against the
// small page interface of drivers.mjs: evaluate, click, press, setFiles, screenshot. Chromium
// also runs the fuller checks of demo.test.mjs and viewer.test.mjs.
//
// A check that an engine cannot run names the engine and says why (`skip`); one whose Chromium
// run would repeat demo.test.mjs says where it is (`chromium`). No check depends on the
// machine's speed: each waits for a state (under the hang guard) and asserts steps, counts and
// bits; times are reported.

import assert from 'node:assert/strict';
import { readFile } from 'node:fs/promises';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { parseReadouts } from './readouts.mjs';
import { SHIPPED_STATES, DEFAULT_PRESET } from '../../www/js/state.js';
import { TOUR } from '../../www/js/tour.js';

const ROOT = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../..');
export const HANG_MS = Number(process.env.HANG_MS ?? 30 * 60 * 1000);
const DEFAULT_START = SHIPPED_STATES.find((r) => r.preset === DEFAULT_PRESET && r.seed === 1);

// What the running check last waited for, told when a check hangs: whether the page answered
// and its answer stayed false (`polls` grows), or a call to the page never returned.
export const waiting = { what: '', polls: 0 };

// Polls fn(arg) in the page until it is truthy; fails only a page that is stuck ("hung"). While
// not done, fn may return { pending: text } to say what the page is doing: a hang quotes it.
export async function until(p, what, fn, arg) {
  const t0 = Date.now();
  Object.assign(waiting, { what, polls: 0 });
  for (;;) {
    const v = await p.evaluate(fn, arg);
    waiting.polls++;
    if (v && v.pending === undefined) return v;
    if (v) waiting.what = `${what} (last: ${v.pending})`;
    if (Date.now() - t0 > HANG_MS) throw new Error(`hung: waited ${HANG_MS / 1000} s for ${waiting.what}`);
    await new Promise((r) => setTimeout(r, 150));
  }
}

// Opens the page at `query` and waits until it is ready (or failed, which fails the check).
export async function openPage(b, base, query, opts) {
  Object.assign(waiting, { what: `the page ${query} to open`, polls: 0 });
  const p = await b.open(base + query, opts);
  if (!p) return null;
  // While it gets ready, the page names the step of making the tissue it is at (window.demo.stage).
  await until(p, `the page ${query} to load`, () => (window.demo && (window.demo.ready || window.demo.error))
    || { pending: window.demo?.stage ?? 'no script yet' });
  const err = await p.evaluate(() => window.demo.error);
  assert(!err, `page error: ${err}`);
  return p;
}

// Opens the page at `query`, steps it 60 steps and closes it: what its core then says (step,
// fingerprint, threads, coreNote as note, whether the page is cross-origin isolated, the
// threads' start time), with the page's notices and engine label.
async function steppedCore(b, base, query) {
  const p = await openPage(b, base, query);
  const r = await p.evaluate(async () => {
    const call = window.demo.call;
    await call('step', 60);
    const s = await call('stats');
    return { step: s.step, fingerprint: await call('fingerprint'), threads: s.threads, note: s.coreNote,
      isolated: crossOriginIsolated, startMs: window.demo.threadStartMs, notices: window.demo.notices,
      engineText: document.getElementById('engine').textContent };
  });
  await p.close();
  return r;
}

// Runs open(), a page of the threaded core giving { note: its coreNote, … }, once more if that
// core stalled starting its threads (Firefox, now and then) and so steps on the single-thread
// build (main.js replaces the worker), which a check of the threaded core cannot use.
async function twiceIfStalled(engine, open) {
  const r = await open();
  if (!/did not start/.test(r.note)) return r;
  console.log(`       ${engine}: ${r.note}: the page opened again`);
  return open();
}

// A PNG's distinct colours (every 7th pixel), decoded in a page.
export function pngColours(p, png) {
  return p.evaluate(async (b64) => {
    const img = new Image();
    img.src = `data:image/png;base64,${b64}`;
    await img.decode();
    const c = document.createElement('canvas');
    c.width = img.width;
    c.height = img.height;
    const g = c.getContext('2d');
    g.drawImage(img, 0, 0);
    const d = g.getImageData(0, 0, img.width, img.height).data;
    const colours = new Set();
    for (let i = 0; i < d.length; i += 4 * 7) colours.add((d[i] << 16) | (d[i + 1] << 8) | d[i + 2]);
    return { colours: colours.size, width: img.width, height: img.height };
  }, png.toString('base64'));
}

const workerStats = (p) => p.evaluate(() => window.demo.call('stats'));
const drawn = (p) => p.evaluate(() => window.demo.drawn ?? 0);

// Each check: { name, core (run in every engine), long (plays the paper's tissue to its first
// hole), skip: { engine: why }, chromium: where
// demo.test.mjs covers it, run(browser, ctx) }. ctx: { base (the page, cross-origin isolated),
// plainBase (the page without COOP/COEP), stallBase (the page whose threaded core never starts
// its threads), engine, nativeRun (a native run's directory and frames), metrics (reported),
// launch(opts) (another browser of this engine) }.
export const CHECKS = [
  {
    name: 'the page loads, draws its tissue and steps',
    core: true,
    chromium: 'demo.test.mjs checks it on WebGPU and on WebGL2',
    async run(b, ctx) {
      const p = await openPage(b, ctx.base, '/?preset=persistent&seed=1');
      const backend = await p.evaluate(() => window.demo.backend);
      ctx.metrics.backend = backend;
      assert.match(await p.evaluate(() => document.getElementById('backend').textContent), /^Drawing with /);
      await until(p, 'a frame drawn', () => window.demo.drawn > 0 && window.demo.stats);
      const a = (await workerStats(p)).step;
      await until(p, `a step after ${a}`, (a) => window.demo.stats.step > a, a);
      const shot = await pngColours(p, await p.screenshot('#view'));
      assert(shot.colours > 20, `the canvas has only ${shot.colours} colours: blank?`);
      assert.deepEqual(p.errors, [], p.errors.join('\n'));
      await p.close();
    },
  },
  {
    name: 'a preset and a field change the core, the view and the URL',
    core: true,
    chromium: "demo.test.mjs checks every field and the presets' values",
    async run(b, ctx) {
      const p = await openPage(b, ctx.base, '/?preset=persistent&seed=1');
      await until(p, 'a frame drawn', () => window.demo.drawn > 0);
      await p.evaluate(() => {
        const s = document.getElementById('preset');
        s.value = 'no-holes';
        s.dispatchEvent(new Event('change'));
      });
      await until(p, 'the preset in the core', () => window.demo.call('stats').then((s) => s.chi === 0.1 && s.zeta === 2));
      const before = await drawn(p);
      await p.press('3');
      await until(p, 'a frame of the speed', (d) => window.demo.drawn > d + 1 && location.search.includes('field=speed'), before);
      const url = await p.evaluate(() => location.search);
      assert.match(url, /preset=no-holes/);
      // The bar is shown with the frame that draws the field, which may come after the one counted.
      await until(p, 'the colour bar with the speed', () => !document.getElementById('colorbar-labels').hidden);
      await p.close();
    },
  },
  {
    name: 'Download gives the readouts and the state',
    core: true,
    chromium: 'viewer.test.mjs checks the download against monolayer analyze',
    async run(b, ctx) {
      const p = await openPage(b, ctx.base, '/?preset=persistent&seed=1');
      await until(p, 'three rows of readouts', () => window.demo.call('readout_rows').then((n) => n >= 3));
      await p.click('#play');
      await p.click('#download');
      await until(p, 'the download', () => window.demo.lastDownload);
      const info = await p.evaluate(() => window.demo.lastDownload);
      const stats = await workerStats(p);
      assert.equal(info.step, stats.step, 'the download is of the paused state');
      assert(info.npzBytes > 1000, `frame of ${info.npzBytes} bytes`);
      const csv = await p.evaluate(() => window.demo.call('download').then((d) => d.csv));
      const { rows, rowEvery } = parseReadouts(csv);
      assert.equal(rowEvery, 10);
      assert(rows.length >= 3, `${rows.length} rows`);
      assert.equal(rows.at(-1).step, stats.step);
      assert.equal(rows.at(-1).holes, stats.holes);
      await p.close();
    },
  },
  {
    name: "a native run's frames open and play",
    core: true,
    chromium: "viewer.test.mjs checks them against monolayer analyze, a damaged frame among them",
    async run(b, ctx) {
      const p = await openPage(b, ctx.base, '/?preset=persistent&seed=1&field=director');
      const frames = ctx.nativeRun.frames.map((n) => path.join(ctx.nativeRun.dir, 'frames', n));
      await p.setFiles('#open-files', [path.join(ctx.nativeRun.dir, 'run.json'), ...frames]);
      await until(p, 'the run opened', () => window.demo.playback.opened === 1);
      const pb = await p.evaluate(() => window.demo.playback);
      assert.deepEqual(pb.frames.map((f) => f.step), ctx.nativeRun.steps);
      assert.deepEqual(pb.errors, []);
      const d = await drawn(p);
      await p.click('#player-play');
      await until(p, 'the frames playing', (d) => window.demo.drawn > d + 2 && window.demo.stats.step > 300, d);
      await p.close();
    },
  },
  {
    name: "the shipped tissue's first hole opens at its native step",
    long: true,
    core: true,
    chromium: 'demo.test.mjs asserts it on WebGPU and on WebGL2',
    async run(b, ctx) {
      const p = await openPage(b, ctx.base, '/');
      await until(p, 'the first hole', () => window.demo.firstHole !== null);
      const hole = await p.evaluate(() => window.demo.firstHole);
      const { rows, rowEvery } = parseReadouts(await p.evaluate(() => window.demo.call('download').then((d) => d.csv)));
      const first = rows.find((r) => r.holes > 0);
      ctx.metrics.firstHole = { ...hole, row: first?.step };
      console.log(`       ${ctx.engine}: first hole ${hole.seconds.toFixed(1)} s after loading (row at step ${first?.step}; ${ctx.metrics.backend})`);
      assert(first, 'no row of readouts has a hole');
      assert(first.step >= DEFAULT_START.firstHole && first.step < DEFAULT_START.firstHole + rowEvery,
        `first row with a hole at step ${first.step}; it opens at ${DEFAULT_START.firstHole}`);
      await p.close();
    },
  },
  {
    // "What if?": the shipped paper tissue played to its first hole, then rewound to the state
    // the page saved before it and replayed with activity off. The replay starts from that
    // state's bits (the fingerprint the core gives right after the rewind is the one recorded
    // when the state was saved), with ζ = 0 read back from the core, in the slider and in the
    // URL; the caption names the step, then the replay's verdict; Back returns to the live
    // tissue and its ζ. Chromium only: it plays the paper's tissue to its first hole once more
    // and replays it (its time: docs/performance.md), and the replay is the same core code in
    // every engine, whose bits the other engines' checks already compare.
    name: 'What if? replays the first hole from the state saved before it, with activity off',
    long: true,
    core: false,
    async run(b, ctx) {
      const p = await openPage(b, ctx.base, '/');
      await until(p, 'the first hole, with a state saved before it', () => window.demo.stats?.rewind);
      await until(p, 'the What if? control', () => !document.getElementById('whatif').hidden);
      const { rewind } = await workerStats(p);
      assert(rewind.holeStep >= DEFAULT_START.firstHole && rewind.holeStep < DEFAULT_START.firstHole + 10,
        `the hole's first row at step ${rewind.holeStep}; it opens at ${DEFAULT_START.firstHole}`);
      assert(rewind.from + 1000 <= rewind.holeStep && rewind.from + 1500 > rewind.holeStep,
        `rewinds to step ${rewind.from} for a hole at ${rewind.holeStep}`);
      const saved = await p.evaluate(() => window.demo.call('saved_states'));
      const at = saved.find((s) => s.step === rewind.from);
      assert(at, `no saved state at step ${rewind.from} among ${saved.map((s) => s.step)}`);
      await p.click('#whatif-off');
      await until(p, 'the replay', () => window.demo.whatIf);
      const r = await p.evaluate(() => window.demo.whatIf);
      ctx.metrics.whatIf = { rewind, saved: saved.length, bytes: saved.map((s) => s.bytes), replay: r };
      assert.equal(r.step, rewind.from, 'the replay does not start at the saved step');
      assert.equal(r.fingerprint, at.fingerprint, 'the replay does not start from the saved bits');
      assert.equal(r.zeta, 0, `ζ read back from the core after the rewind: ${r.zeta}`);
      const replaying = await workerStats(p);
      assert.equal(replaying.zeta, 0);
      assert.equal(replaying.replay?.from, rewind.from);
      assert.equal(await p.evaluate(() => document.getElementById('zeta-out').textContent), '0');
      assert.match(await p.evaluate(() => location.search), /[?&]zeta=0(&|$)/);
      const from = rewind.from.toLocaleString('en-US');
      await until(p, 'the caption with the step rewound to',
        (from) => document.getElementById('whatif-caption').textContent.startsWith(`Rewound to step ${from}`), from);
      // The replay watched to its verdict, which the caption states (reported: whether this tear
      // needs the motion is the experiment's question, not the page's to assert).
      const done = await until(p, "the replay's verdict", async () => {
        const s = await window.demo.call('stats');
        return s.replay && s.replay.verdict !== 'watching' ? s.replay : null;
      });
      // The caption is written by the page when the verdict's stats reach it, a moment after the
      // worker has it.
      const said = done.verdict === 'tore' ? 'the hole opened again, at step' : 'no hole opened within R';
      const caption = await until(p, "the caption with the replay's verdict", (said) => {
        const text = document.getElementById('whatif-caption').textContent;
        return text.includes(said) && text;
      }, said);
      assert.match(caption, /docs\/figures\.md, section "Intervention"/);
      ctx.metrics.whatIf.verdict = { verdict: done.verdict, tearStep: done.tearStep, until: done.until };
      console.log(`       ${ctx.engine}: What if? from step ${rewind.from} with ζ = 0: ${done.verdict}`
        + `${done.tearStep === null ? '' : ` at step ${done.tearStep}`} (the original at ${rewind.holeStep})`);
      await p.click('#whatif-back');
      await until(p, 'the live tissue again', () => window.demo.whatIfBack);
      const live = await workerStats(p);
      assert.equal(live.replay, null);
      assert.equal(live.zeta, 0.5);
      assert(live.step >= rewind.holeStep, `back at step ${live.step}, before the hole (${rewind.holeStep})`);
      assert.match(await p.evaluate(() => location.search), /[?&]preset=paper(&|$)/);
      assert.deepEqual(p.errors, [], p.errors.join('\n'));
      await p.close();
    },
  },
  {
    name: 'with neither WebGPU nor WebGL2 the page draws the cells with Canvas 2D',
    core: true,
    async run(b, ctx) {
      const nogpu = await ctx.launch({ gpu: false });
      try {
        const p = await openPage(nogpu, ctx.base, '/?preset=persistent&seed=1&paused');
        await until(p, 'a frame drawn', () => window.demo.drawn > 0);
        assert.equal(await p.evaluate(() => window.demo.backend), 'Canvas 2D');
        assert.match(await p.evaluate(() => document.getElementById('backend').textContent),
          /^Drawing with Canvas 2D \(this browser offers neither WebGPU nor WebGL2/);
        // The pixels: the canvas as shown, against the image of the sites the core made for it.
        // A site deep inside each cell (φ > 0.9) is shown, where the layout puts it, in the
        // cell's own colour.
        const png = await p.screenshot('#view');
        const check = await p.evaluate(async (b64) => {
          const img = new Image();
          img.src = `data:image/png;base64,${b64}`;
          await img.decode();
          const c = document.createElement('canvas');
          c.width = img.width;
          c.height = img.height;
          const g = c.getContext('2d');
          g.drawImage(img, 0, 0);
          const shown = g.getImageData(0, 0, c.width, c.height).data;
          const view = document.getElementById('view');
          const k = img.width / view.width; // screenshot pixels per backing pixel
          const { x: x0, y: y0, side } = window.demo.renderer.layout();
          const l = await window.demo.call('box_size');
          // The core's colours of this frame, as the renderer drew them.
          const { rgba, tissue } = window.demo.renderer.last;
          let cells = 0;
          let matched = 0;
          const seen = new Set();
          // Away from the lattice's edges: WebKit's element screenshots leave the top rows of
          // some canvases black.
          for (let y = 7; y < l - 5; y += 5) {
            for (let x = 7; x < l - 5; x += 5) {
              const t = 4 * (y * l + x);
              if (tissue[t + 1] < 0.9 || seen.has(tissue[t])) continue; // deep inside a cell
              seen.add(tissue[t]);
              cells++;
              // The pixels of the site's square, its edges left out: most have its colour (a
              // line of the overlay, such as the cell's axis, may cross some).
              const [ax, bx] = [x, x + 1].map((v) => (x0 + (v * side) / l) * k);
              const [ay, by] = [y, y + 1].map((v) => (y0 + (v * side) / l) * k);
              let same = 0;
              let all = 0;
              for (let py = Math.ceil(ay) + 1; py < Math.floor(by) - 1; py++) {
                for (let px = Math.ceil(ax) + 1; px < Math.floor(bx) - 1; px++) {
                  const i = 4 * (py * img.width + px);
                  all++;
                  if (Math.max(...[0, 1, 2].map((j) => Math.abs(shown[i + j] - rgba[t + j]))) <= 3) same++;
                }
              }
              if (all > 0 && same >= all / 2) matched++;

            }
          }
          return { cells, matched };
        }, png.toString('base64'));
        ctx.metrics.canvas2d = check;
        assert(check.cells >= 10, `only ${check.cells} cells sampled`);
        assert.equal(check.matched, check.cells, `${check.matched} of ${check.cells} cells show their own colour`);
        const look = await pngColours(p, png);
        assert(look.colours > 20, `only ${look.colours} colours`);
        // The fields draw too, with their colour bar.
        const before = await drawn(p);
        await p.press('5');
        await until(p, 'a frame of the strain rate', (d) => window.demo.drawn > d, before);
        await until(p, 'the colour bar', () => !document.getElementById('colorbar-labels').hidden);
        assert.deepEqual(p.errors, [], p.errors.join('\n'));
        await p.close();
      } finally {
        await nogpu.close();
      }
    },
  },
  {
    name: "the renderer survives its device's loss, and falls back after repeated losses",
    core: true,
    async run(b, ctx) {
      const p = await openPage(b, ctx.base, '/?preset=persistent&seed=1');
      await until(p, 'a frame drawn', () => window.demo.drawn > 0);
      const first = await p.evaluate(() => window.demo.backend);
      const losses = [];
      // One loss: a new renderer of the same kind; the tissue steps and is drawn on, no error.
      for (let n = 1; n <= 3; n++) {
        const at = await p.evaluate(() => ({ step: window.demo.stats.step, drawn: window.demo.drawn }));
        await p.evaluate(() => window.demo.loseRenderer());
        await until(p, `loss ${n} answered`, (n) => window.demo.rendererLosses.length >= n, n);
        await until(p, `drawing and stepping after loss ${n}`,
          (at) => window.demo.drawn > at.drawn + 2 && window.demo.stats.step > at.step, at);
        const st = await p.evaluate(() => ({ error: window.demo.error, backend: window.demo.backend, losses: window.demo.rendererLosses }));
        assert(!st.error, `error shown after loss ${n}: ${st.error}`);
        losses.push(st.losses.at(-1));
        if (n < 3) assert.equal(st.backend, first, `loss ${n}: the same kind of renderer again`);
      }
      // The third within a minute: the next kind, and the page says why.
      const last = await p.evaluate(() => ({ backend: window.demo.backend, notices: window.demo.notices }));
      ctx.metrics.deviceLoss = { first, after: last.backend, losses };
      // The next kind this browser offers (headless Firefox has no WebGL2: Canvas 2D).
      const order = ['WebGPU', 'WebGL2', 'Canvas 2D'];
      const kind = (backend) => order.find((k) => backend.startsWith(k));
      const next = kind(last.backend);
      assert(order.indexOf(next) > order.indexOf(kind(first)), `after three losses: ${last.backend}, after ${first}`);
      assert(last.notices.some((t) => t.includes(`Drawing with ${next} now`) && t.includes('3 times within a minute')), `notices: ${last.notices}`);
      assert.match(await p.evaluate(() => document.getElementById('backend').textContent), /lost its device 3 times/);
      assert.deepEqual(p.errors, [], p.errors.join('\n'));
      await p.close();
    },
  },
  {
    name: 'the guided tour shows each caption at its event, in an embedded page',
    long: true,
    core: true,
    async run(b, ctx) {
      const p = await openPage(b, ctx.base, '/?tour&embed&spf=20');
      const caption = () => p.evaluate(() => ({
        id: window.demo.tour.log.at(-1)?.id, text: document.getElementById('tour-caption').textContent,
        visible: !document.getElementById('tour').hidden,
      }));
      const first = await caption();
      assert(first.visible, 'the tour is not shown in the embedded page');
      assert.equal(first.id, 'cells');
      // Walk it: wait for the hole's caption (the tissue plays, captions come at their events).
      await until(p, "the hole's caption", () => window.demo.tour.log.some((c) => c.id === 'hole'));
      const paused = await workerStats(p);
      await new Promise((r) => setTimeout(r, 500));
      assert.equal((await workerStats(p)).step, paused.step, 'the tour did not pause on the hole');
      await p.click('#tour-next');
      await until(p, 'the last caption', () => window.demo.tour.log.at(-1)?.id === 'verdict');
      const log = await p.evaluate(() => window.demo.tour.log);
      ctx.metrics.tour = log;
      assert.deepEqual(log.map((c) => c.id), TOUR.map((c) => c.id), `captions ${log.map((c) => c.id)}`);
      const start = log[0].step;
      assert.equal(start, DEFAULT_START.step, 'the tour starts on the shipped tissue');
      for (let i = 1; i < log.length; i++) {
        const c = TOUR[i];
        if (c.after !== undefined) assert(log[i].step - log[i - 1].step >= c.after, `${c.id} at step ${log[i].step}, ${c.after} after ${log[i - 1].step}`);
        if (c.cores) assert(log[i].cores > 0 || log[i].coresSeen, `${c.id} without a spiral core seen`);
        if (c.hole) assert(log[i].holes > 0 && log[i].step >= DEFAULT_START.firstHole, `${c.id} at step ${log[i].step} with ${log[i].holes} holes`);
      }
      // The last caption's verdict is docs/figures.md's "the argument" row, word for word (less its
      // bold and its links into the docs, which the page is served without).
      const figures = await readFile(path.join(ROOT, 'docs', 'figures.md'), 'utf8');
      const row = figures.split('\n').find((l) => l.startsWith('| the argument |')).split('|').map((c) => c.trim());
      const verdict = row[3].replace(/\*\*/g, '').replace(/ \(\[[^\]]*\]\([^)]*\)\)/g, '');
      const said = (await caption()).text;
      assert(said.includes(verdict), `the last caption does not carry the verdict "${verdict}": ${said}`);
      // Keyboard: Escape closes it.
      await p.evaluate(() => document.getElementById('tour-next').focus());
      await p.press('Escape');
      await until(p, 'the tour closed', () => document.getElementById('tour').hidden);
      await p.close();
    },
  },
  {
    name: 'with prefers-reduced-motion the guided tour waits for its Play button',
    core: true,
    async run(b, ctx) {
      const q = await openPage(b, ctx.base, '/?tour&spf=20', { reducedMotion: true });
      assert(q, `${ctx.engine}: no way to ask for reduced motion`);
      const a = (await workerStats(q)).step;
      await new Promise((r) => setTimeout(r, 800));
      assert.equal((await workerStats(q)).step, a, 'the tour played with reduced motion');
      assert(await q.evaluate(() => !document.getElementById('tour-play').hidden && document.activeElement.id === 'tour-play'), 'no focused Play button');
      await q.click('#tour-play');
      await until(q, 'the tissue playing', (a) => window.demo.stats.step > a, a);
      await q.close();
    },
  },
  {
    name: 'the threaded core gives the bits of one thread, on one and two threads',
    core: true,
    async run(b, ctx) {
      const run = (query, base = ctx.base) => steppedCore(b, base, `/?preset=persistent&seed=1&paused${query}`);
      const one = await twiceIfStalled(ctx.engine, () => run('&threads=1'));
      const two = await twiceIfStalled(ctx.engine, () => run('&threads=2'));
      // A host that sends no COOP/COEP headers: the single-thread build.
      const single = await run('', ctx.plainBase);
      ctx.metrics.threads = { one, two, single };
      assert(two.isolated, 'the test server isolates the page (COOP/COEP)');
      assert.match(two.note, /^threaded build/, `two threads: ${two.note}`);
      assert.equal(two.threads, 2);
      assert.equal(one.threads, 1);
      assert(!single.isolated && /^single-thread build: the page is not cross-origin isolated/.test(single.note), `without the headers: ${JSON.stringify(single)}`);
      assert.equal(one.step, two.step);
      assert.equal(one.fingerprint, two.fingerprint, 'one thread and two part');
      assert.equal(single.step, two.step);
      assert.equal(single.fingerprint, two.fingerprint, 'the threaded build and the single-thread one part');
    },
  },
  {
    name: "a threaded core whose threads never start is replaced by the single-thread build, with the same bits",
    core: true,
    async run(b, ctx) {
      // ctx.stallBase's server never answers the fetch() by which each of the threaded core's
      // thread Workers gets its script, so the pool never starts: the stall Firefox shows now
      // and then, there with the worker blocked, here waiting.
      const query = '/?preset=persistent&seed=1&paused&threads=2';
      const r = await steppedCore(b, ctx.stallBase, query);
      const normal = await twiceIfStalled(ctx.engine, () => steppedCore(b, ctx.base, query));
      ctx.metrics.threadStart = { stalled: r, normalStartMs: normal.startMs };
      console.log(`       ${ctx.engine}: the threaded core's threads started in ${normal.startMs?.toFixed(0)} ms; stalled: ${r.note}`);
      assert.match(r.note, /^single-thread build: the threaded core's threads did not start within \d+ s$/, r.note);
      assert.equal(r.threads, 1);
      assert(r.notices.some((n) => n.includes('did not start')), `no notice: ${JSON.stringify(r.notices)}`);
      assert(r.engineText.includes('did not start'), r.engineText);
      assert.equal(normal.threads, 2);
      assert.equal(r.step, normal.step);
      assert.equal(r.fingerprint, normal.fingerprint, 'the replacement steps other bits than the threaded core');
    },
  },
  {
    name: "the threaded core's speed on the paper's tissue, one thread against two (reported, not asserted)",
    core: false,
    async run(b, ctx) {
      // Two pages of the paper's tissue, paused, on one and on two threads; blocks of steps on
      // a copy of each tissue, taken in turn (the other page idle), so that both see the same
      // machine.
      const one = await openPage(b, ctx.base, '/?preset=paper&paused&threads=1');
      const two = await openPage(b, ctx.base, '/?preset=paper&paused&threads=2');
      const block = (p) => p.evaluate(() => window.demo.call('core_ms_per_step', 20, 1));
      const pairs = [];
      for (let i = 0; i < 4; i++) pairs.push({ one: await block(one), two: await block(two) });
      const ratios = pairs.map((r) => r.one / r.two).sort((a, c) => a - c);
      const median = (ratios[1] + ratios[2]) / 2;
      ctx.metrics.threadsSpeed = { pairs, median, threads: [await one.evaluate(() => window.demo.threads), await two.evaluate(() => window.demo.threads)] };
      console.log(`       the paper's tissue: ${pairs.map((r) => `${(1000 / r.one).toFixed(0)}/${(1000 / r.two).toFixed(0)}`).join(', ')} steps/s on 1/2 threads; median speed-up ${median.toFixed(2)}`);
      assert(pairs.every((r) => r.one > 0 && r.two > 0));
      await one.close();
      await two.close();
    },
  },
];
