// The page: loads the WebAssembly core, and ties the frame loop (loop.js), the controls
// (controls.js) and the readouts (readouts.js) to one simulation and one renderer. Every change
// of state goes through the actions below, which keep the core, the controls and the URL in step.

import init, { WebSim, Renderer, FieldKind } from '../pkg/monolayer.js';
import { PARAMS, MODEL_PARAMS, PRESETS, SIZE, parseUrl, toUrl } from './state.js';
import { FrameLoop } from './loop.js';
import { Controls } from './controls.js';
import { Readouts } from './readouts.js';

const $ = (id) => document.getElementById(id);
const canvas = $('view');
const message = $('message');

// Everything the tests read lives here too (window.demo).
const demo = { ready: false, error: null, notices: [], firstHole: null, loadedAt: performance.now() };
window.demo = demo;

// The page's one simulation and renderer, its state (what the URL carries), and the pending
// screenshot.
const page = { sim: null, renderer: null, state: null, screenshot: false };

function showMessage(text, isError = false) {
  message.textContent = text;
  message.classList.toggle('error', isError);
  message.hidden = false;
}

// console_error_panic_hook writes a Rust panic's message to console.error before the trap: the
// fatal message quotes it.
let lastConsoleError = '';
const consoleError = console.error.bind(console);
console.error = (...args) => {
  lastConsoleError = args.map(String).join(' ');
  consoleError(...args);
};

// A fatal error (no GPU, a Rust panic, a lost device): stop and say so on the canvas.
function fatal(what, err) {
  const detail = String(err && err.message ? err.message : err);
  const panic = lastConsoleError.includes('panicked') ? `\n\n${lastConsoleError}` : '';
  demo.error = `${what}: ${detail}${panic}`;
  loop.stopped = true;
  showMessage(demo.error, true);
}
window.addEventListener('error', (e) => fatal('Unexpected error', e.error ?? e.message));
window.addEventListener('unhandledrejection', (e) => fatal('Unexpected error', e.reason));

function notify(lines) {
  if (!lines.length) return;
  demo.notices.push(...lines);
  $('notice').textContent = demo.notices.join(' ');
  $('notice').hidden = false;
}

const readouts = new Readouts();

const loop = new FrameLoop(canvas, {
  maxSteps: () => page.state.spf,
  step: takeSteps,
  wantsDraw: () => page.screenshot,
  draw,
  readouts: updateReadouts,
  fatal: (e) => fatal('The page stopped', e),
});

// Steps the core; on an error of the model (the core keeps the state before the failing step)
// stops and says why. A Rust panic traps: the module is then unusable, and the loop's catch
// shows it.
function takeSteps(n) {
  try {
    page.sim.step(n);
    return true;
  } catch (e) {
    if (e instanceof WebAssembly.RuntimeError) throw e;
    setPlaying(false);
    const why = String(e.message ?? e);
    const hint = page.sim.active()
      ? 'Activity stretched a cell past the stable range: lower ζ or raise χ, then press Reset.'
      : 'The random start of this seed placed two cells too close to relax them: try another seed and press Reset.';
    showMessage(`The simulation stopped: ${why}\n\n${hint}`, true);
    demo.simError = why;
    return false;
  }
}

function draw(dpr) {
  const { sim, renderer, state } = page;
  const view = sim.view(state.field, dpr);
  try {
    renderer.draw(view, dpr, true);
    if (view.kind() === FieldKind.Tissue) readouts.hideColourBar();
    else readouts.colourBar(state.field, view.range(), renderer.layout(), dpr);
  } finally {
    view.free();
  }
  if (page.screenshot) saveScreenshot();
}

function updateReadouts() {
  const s = readouts.update(page.sim, loop, page.state.spf);
  if (s.active && s.holes > 0 && demo.firstHole === null) {
    demo.firstHole = { seconds: (performance.now() - demo.loadedAt) / 1000, step: s.step };
  }
  const sim = page.sim;
  demo.stats = {
    ...s, fingerprint: sim.fingerprint(), playing: loop.playing, zeta: sim.zeta(), chi: sim.chi(),
    gamma: sim.gamma(), cells: sim.n_cells(), msPerStep: loop.msPerStep, drawMs: loop.drawMs,
    renderScale: loop.renderScale,
  };
}

// Right after drawing, in the same task: the canvas still holds this frame.
function saveScreenshot() {
  page.screenshot = false;
  const url = canvas.toDataURL('image/png');
  const a = document.createElement('a');
  a.href = url;
  a.download = `monolayer-step${page.sim.step_count()}.png`;
  a.click();
  demo.lastScreenshot = url;
}

// --- actions: the only writers of the state -------------------------------------------------------
function changed() {
  controls.refresh(page.state, loop.playing);
  history.replaceState(null, '', toUrl(page.state));
}

function newSim() {
  const s = page.state;
  if (page.sim) page.sim.free();
  page.sim = new WebSim(SIZE.box, SIZE.cells, SIZE.relaxSteps, s.zeta, s.chi, s.gamma, s.seed);
  readouts.reset(page.sim.time_unit_seconds());
  demo.firstHole = null;
  demo.loadedAt = performance.now();
  demo.simError = null;
  message.hidden = true;
  loop.dirty = true;
}

function setPlaying(on) {
  loop.playing = on;
  page.state.paused = !on;
  changed();
}

// Sets a parameter in the state and, for the model's, in the core (a preset sets them together).
function setParam(name, value, fromPreset = false) {
  const state = page.state;
  state[name] = value;
  if (MODEL_PARAMS.includes(name)) {
    if (!fromPreset) state.preset = null;
    try {
      page.sim[`set_${name}`](value);
    } catch (e) {
      notify([`${name} = ${value}: ${e.message ?? e}`]);
    }
  }
  changed();
}

// Pointer → lattice site, through the layout the renderer drew.
function latticeAt(ev) {
  const rect = canvas.getBoundingClientRect();
  const scale = canvas.width / rect.width; // backing pixels per CSS pixel
  const [x0, y0, side] = page.renderer.layout();
  const l = page.sim.box_size();
  const x = (((ev.clientX - rect.left) * scale - x0) / side) * l;
  const y = (((ev.clientY - rect.top) * scale - y0) / side) * l;
  return x >= 0 && y >= 0 && x < l && y < l ? [x, y] : null;
}

// A brush or the laser: an invalid stroke is reported, not fatal.
function edit(f) {
  try {
    f();
  } catch (e) {
    notify([String(e.message ?? e)]);
  }
  loop.dirty = true;
}

const controls = new Controls({
  setParam,
  applyPreset(name) {
    for (const k of MODEL_PARAMS) setParam(k, PRESETS[name][k], true);
    page.state.preset = name;
    changed();
  },
  setField(kind) {
    page.state.field = kind;
    loop.dirty = true;
    changed();
  },
  setSeed(raw) {
    const p = PARAMS.seed;
    let v = Math.round(Number(raw));
    if (!Number.isFinite(v) || v < p.min || v > p.max) {
      v = Math.min(p.max, Math.max(p.min, Number.isFinite(v) ? v : p.def));
      notify([`Seed must be an integer in [0, ${p.max}]: using ${v}.`]);
    }
    page.state.seed = v;
    changed();
  },
  togglePlay: () => setPlaying(!loop.playing),
  stepOnce() {
    setPlaying(false);
    loop.runSteps(page.state.spf);
  },
  reset: () => newSim(),
  screenshot() {
    page.screenshot = true;
  },
  brush: (x, y, radius, multiplier) => edit(() => page.sim.paint_substrate(x, y, radius, multiplier)),
  ablate: (x, y) => edit(() => page.sim.remove_cell_at(x, y)),
  latticeAt,
});

// --- start ----------------------------------------------------------------------------------------
async function boot() {
  const parsed = parseUrl(location.search);
  page.state = parsed.state;
  notify(parsed.notices);
  document.body.classList.toggle('embed', page.state.embed);
  loop.playing = !page.state.paused;
  changed();
  try {
    await init();
  } catch (e) {
    fatal('Could not load the WebAssembly core (build it with `bash scripts/serve.sh`)', e);
    return;
  }
  showMessage('Looking for WebGPU or WebGL2…');
  loop.resizeCanvas();
  try {
    page.renderer = await Renderer.create(canvas);
  } catch (e) {
    fatal('This page needs WebGPU or WebGL2 to draw the tissue', e);
    return;
  }
  $('backend').textContent = `Drawing with ${page.renderer.backend()}.`;
  demo.backend = page.renderer.backend();
  try {
    newSim();
  } catch (e) {
    fatal('Could not start the simulation', e);
    return;
  }
  Object.defineProperty(demo, 'sim', { get: () => page.sim });
  demo.renderer = page.renderer;
  demo.size = SIZE;
  demo.ready = true;
  loop.start();
}

boot();
