// The page: loads the WebAssembly core, draws it with wgpu every animation frame, and wires the
// controls. Simulation and drawing share the main thread, so the steps taken per frame adapt to
// keep the frame under its budget (≥ 30 fps), up to the "steps per frame" slider.

import { PARAMS, FIELDS, PRESETS, SIZE, parseUrl, toUrl, toSlider, fromSlider } from './state.js';
import { HoleChart } from './chart.js';

const $ = (id) => document.getElementById(id);
const canvas = $('view');
const message = $('message');

// Milliseconds of stepping allowed per frame: 33 ms per frame at 30 fps, less drawing and the
// browser's own work.
const STEP_BUDGET_MS = 20;
const TIME_UNIT_S = 5; // one simulation time unit ≈ 5 s (paper)

// Everything the tests read lives here too (window.demo).
const demo = { ready: false, error: null, notices: [], firstHole: null, loadedAt: performance.now() };
window.demo = demo;

function showMessage(text, isError = false) {
  message.textContent = text;
  message.classList.toggle('error', isError);
  message.hidden = false;
}

// A fatal error (no GPU, a Rust panic, a lost device): stop and say so on the canvas.
let lastConsoleError = '';
const consoleError = console.error.bind(console);
console.error = (...args) => {
  lastConsoleError = args.map(String).join(' ');
  consoleError(...args);
};
function fatal(what, err) {
  const detail = String(err && err.message ? err.message : err);
  // console_error_panic_hook writes the panic message to console.error before the trap.
  const panic = lastConsoleError.includes('panicked') ? `\n\n${lastConsoleError}` : '';
  demo.error = `${what}: ${detail}${panic}`;
  playing = false;
  showMessage(demo.error, true);
}
window.addEventListener('error', (e) => fatal('Unexpected error', e.error ?? e.message));
window.addEventListener('unhandledrejection', (e) => fatal('Unexpected error', e.reason));

function notify(lines) {
  const n = $('notice');
  if (!lines.length) return;
  demo.notices.push(...lines);
  n.textContent = demo.notices.join(' ');
  n.hidden = false;
}

let wasm; // the module: WebSim, Renderer
let sim; // WebSim
let renderer; // Renderer
let state;
let playing = true;
let tool = 'none';
let dirty = true;
let screenshotRequested = false;
const chart = new HoleChart($('chart'));

// --- stepping, drawing and the frame budget -----------------------------------------------------
// Each frame: some steps, then one draw, on the main thread. The main thread's other work per
// frame (drawing commands, readouts) is measured, and the steps get what is left of 33 ms
// (30 fps), up to the "steps per frame" slider. The GPU renders in its own process: where it is
// the bottleneck (a software GPU such as SwiftShader shades every pixel on the CPU), the canvas
// is drawn at a lower resolution until frames fit 30 fps again, and scaled up by the browser.
const FRAME_MS = 1000 / 30;
let msPerStep = 5; // running estimate of one step's cost
let drawMs = 5; // running estimate of the rest of a frame's main-thread work
let intervalMs = FRAME_MS; // running estimate of the time between frames
let renderScale = 1; // backing pixels per device pixel (≤ 1)
let scaleCooldownUntil = 0; // ms: let the estimates settle between changes
let lastFrameAt = 0;
let stepsThisFrame = 0;
let stepMs = 0;
const rate = { steps: 0, frames: 0, t0: performance.now(), sps: 0, fps: 0 };

// Where the GPU holds frames back anyway (interval > 33 ms with this thread idle), stepping may
// use most of the interval: that does not lower the fps. If stepping itself becomes the
// bottleneck, the interval it causes shrinks this budget back towards 33 ms (0.8 < 1).
function stepsForFrame() {
  const frame = Math.max(FRAME_MS, 0.8 * intervalMs);
  const budget = Math.max(2, frame - drawMs - 4);
  const affordable = Math.max(1, Math.floor(budget / Math.max(msPerStep, 0.01)));
  return Math.min(state.spf, affordable);
}

// Lower the resolution when the GPU, not this thread, holds frames back; raise it again when
// there is room.
function adaptResolution(now) {
  if (lastFrameAt) intervalMs = 0.9 * intervalMs + 0.1 * (now - lastFrameAt);
  lastFrameAt = now;
  if (now < scaleCooldownUntil) return;
  const mainMs = stepMs + drawMs;
  if (intervalMs > 1.15 * FRAME_MS && mainMs < 0.75 * intervalMs && renderScale > 0.3) {
    renderScale = Math.max(0.3, renderScale * 0.85);
    scaleCooldownUntil = now + 400;
  } else if (intervalMs < 0.8 * FRAME_MS && renderScale < 1) {
    renderScale = Math.min(1, renderScale * 1.1);
    scaleCooldownUntil = now + 1000;
  }
}

function runSteps(n) {
  const t0 = performance.now();
  try {
    sim.step(n);
  } catch (e) {
    // A Rust panic traps: the module is unusable, the page shows the panic (fatal, via frame).
    if (e instanceof WebAssembly.RuntimeError) throw e;
    // An error of the model: the core keeps the state before the failing step; say why, stop.
    playing = false;
    updatePlayButton();
    const why = String(e.message ?? e);
    const hint = sim.active()
      ? 'Activity stretched a cell past the stable range: lower ζ or raise χ, then press Reset.'
      : 'The random start of this seed placed two cells too close to relax them: try another seed and press Reset.';
    showMessage(`The simulation stopped: ${why}\n\n${hint}`, true);
    demo.simError = why;
    return;
  }
  const dt = performance.now() - t0;
  msPerStep = 0.8 * msPerStep + 0.2 * (dt / n);
  stepMs = dt;
  stepsThisFrame = n;
  rate.steps += n;
  dirty = true;
}

// --- the frame ----------------------------------------------------------------------------------
function resizeCanvas() {
  const dpr = (window.devicePixelRatio || 1) * renderScale;
  const w = Math.max(1, Math.round(canvas.clientWidth * dpr));
  const h = Math.max(1, Math.round(canvas.clientHeight * dpr));
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
    dirty = true;
  }
  return dpr;
}

function frame(now) {
  if (demo.error) return;
  requestAnimationFrame(frame);
  try {
    adaptResolution(now);
    stepsThisFrame = 0;
    stepMs = 0;
    if (playing) runSteps(stepsForFrame());
    const t0 = performance.now();
    const dpr = resizeCanvas();
    if (dirty || screenshotRequested) {
      renderer.draw(sim, state.field, dpr, true);
      dirty = false;
      if (screenshotRequested) saveScreenshot();
      updateColorbar(dpr);
    }
    rate.frames++;
    updateReadouts();
    drawMs = 0.9 * drawMs + 0.1 * (performance.now() - t0);
  } catch (e) {
    fatal('The page stopped', e);
  }
}

function updateReadouts() {
  const now = performance.now();
  if (now - rate.t0 >= 500) {
    const s = (now - rate.t0) / 1000;
    rate.sps = rate.steps / s;
    rate.fps = rate.frames / s;
    rate.steps = 0;
    rate.frames = 0;
    rate.t0 = now;
  }
  const step = sim.step_count();
  const holes = sim.holes();
  const area = sim.hole_area();
  const t = sim.active_time();
  $('r-step').textContent = step.toLocaleString('en');
  $('r-time').textContent = sim.active()
    ? `${t.toFixed(0)} (${formatSeconds(t * TIME_UNIT_S)})`
    : `relaxing ${Math.round((100 * step) / sim.relax_steps())} %`;
  $('r-holes').textContent = sim.active() ? String(holes) : `(${holes} gaps)`;
  $('r-area').textContent = `${area} µm²`;
  $('r-packing').textContent = `${(100 * sim.packing_fraction()).toFixed(1)} %`;
  $('r-sps').textContent = rate.sps.toFixed(0);
  $('r-spf').textContent = playing ? `${stepsThisFrame} / ${state.spf}` : `– / ${state.spf}`;
  $('r-fps').textContent = rate.fps.toFixed(0);
  $('r-fps').title = `drawn at ${Math.round(renderScale * 100)} % resolution`;
  if (sim.active()) chart.push(t, area);
  // Before activity the tissue is still closing up: gaps then are not holes.
  if (sim.active() && holes > 0 && demo.firstHole === null) {
    demo.firstHole = { seconds: (now - demo.loadedAt) / 1000, step };
  }
  if (rate.frames % 10 === 0) chart.draw();
  demo.stats = {
    step, holes, area, time: t, packing: sim.packing_fraction(), sps: rate.sps, fps: rate.fps,
    fingerprint: sim.fingerprint(), playing, zeta: sim.zeta(), chi: sim.chi(), gamma: sim.gamma(),
    cells: sim.n_cells(), msPerStep, drawMs, renderScale,
  };
}

function formatSeconds(s) {
  if (s < 120) return `${s.toFixed(0)} s`;
  if (s < 7200) return `${(s / 60).toFixed(1)} min`;
  return `${(s / 3600).toFixed(2)} h`;
}

function updateColorbar(dpr) {
  const labels = $('colorbar-labels');
  if (state.field === 'tissue') {
    labels.hidden = true;
    return;
  }
  const [x, , side] = renderer.layout();
  const [lo, hi] = renderer.range(sim);
  labels.hidden = false;
  labels.style.width = `${side / dpr}px`;
  labels.style.marginLeft = `${x / dpr}px`;
  const units = { phi: '', speed: ' µm per time unit', director: '', strain: ' per time unit', activediv: '' }[state.field];
  $('cb-min').textContent = Math.abs(lo) < 0.01 && lo !== 0 ? lo.toExponential(1) : lo.toFixed(2);
  $('cb-max').textContent = hi.toPrecision(2) + units;
  $('cb-name').textContent = FIELDS[state.field];
}

function saveScreenshot() {
  screenshotRequested = false;
  // Right after drawing, in the same task: the canvas still holds this frame.
  const url = canvas.toDataURL('image/png');
  const a = document.createElement('a');
  a.href = url;
  a.download = `monolayer-step${sim.step_count()}.png`;
  a.click();
  demo.lastScreenshot = url;
}

// --- state and controls -------------------------------------------------------------------------
function syncUrl() {
  history.replaceState(null, '', toUrl(state));
}

function newSim() {
  if (sim) sim.free();
  sim = new wasm.WebSim(SIZE.box, SIZE.cells, SIZE.relaxSteps, state.zeta, state.chi, state.gamma, state.seed);
  chart.clear();
  demo.firstHole = null;
  demo.loadedAt = performance.now();
  demo.simError = null;
  message.hidden = true;
  dirty = true;
}

function setParam(name, value, fromPreset = false) {
  state[name] = value;
  if (!fromPreset && ['zeta', 'chi', 'gamma'].includes(name)) state.preset = null;
  try {
    if (name === 'zeta') sim.set_zeta(value);
    if (name === 'chi') sim.set_chi(value);
    if (name === 'gamma') sim.set_gamma(value);
  } catch (e) {
    notify([`${name} = ${value}: ${e.message ?? e}`]);
  }
  refreshControls();
  syncUrl();
}

function applyPreset(name) {
  const p = PRESETS[name];
  for (const k of ['zeta', 'chi', 'gamma']) setParam(k, p[k], true);
  state.preset = name;
  refreshControls();
  syncUrl();
}

function refreshControls() {
  for (const name of ['zeta', 'chi', 'gamma', 'spf']) {
    $(name).value = toSlider(name, state[name]);
    $(name).setAttribute('aria-valuetext', String(state[name]));
    $(`${name}-out`).textContent = String(state[name]);
  }
  $('seed').value = String(state.seed);
  $('preset').value = state.preset ?? 'custom';
  for (const input of document.querySelectorAll('input[name=field]')) input.checked = input.value === state.field;
}

function updatePlayButton() {
  $('play').textContent = playing ? 'Pause' : 'Play';
  $('play').setAttribute('aria-pressed', String(!playing));
  state.paused = !playing;
  syncUrl();
}

function setField(f) {
  state.field = f;
  dirty = true;
  refreshControls();
  syncUrl();
}

function buildControls() {
  for (const name of ['zeta', 'chi', 'gamma', 'spf']) {
    $(`${name}-label`).textContent = PARAMS[name].label;
    $(name).addEventListener('input', (e) => {
      const v = fromSlider(name, Number(e.target.value));
      if (name === 'spf') {
        state.spf = v;
        refreshControls();
        syncUrl();
      } else setParam(name, v);
    });
  }
  const presetSelect = $('preset');
  for (const [key, p] of Object.entries(PRESETS)) presetSelect.add(new Option(p.label, key));
  presetSelect.add(new Option('Custom', 'custom'));
  presetSelect.addEventListener('change', (e) => {
    if (e.target.value in PRESETS) applyPreset(e.target.value);
  });
  const fields = $('fields');
  for (const [key, label] of Object.entries(FIELDS)) {
    const l = document.createElement('label');
    l.innerHTML = `<input type="radio" name="field" value="${key}"> `;
    l.append(label);
    l.querySelector('input').addEventListener('change', () => setField(key));
    fields.append(l);
  }
  $('seed').addEventListener('change', (e) => {
    const p = PARAMS.seed;
    let v = Math.round(Number(e.target.value));
    if (!Number.isFinite(v) || v < p.min || v > p.max) {
      v = Math.min(p.max, Math.max(p.min, Number.isFinite(v) ? v : p.def));
      notify([`Seed must be an integer in [0, ${p.max}]: using ${v}.`]);
    }
    state.seed = v;
    refreshControls();
    syncUrl();
  });
  $('play').addEventListener('click', () => {
    playing = !playing;
    updatePlayButton();
  });
  $('step').addEventListener('click', () => {
    playing = false;
    updatePlayButton();
    runSteps(state.spf);
  });
  $('reset').addEventListener('click', () => newSim());
  $('shot').addEventListener('click', () => {
    screenshotRequested = true;
  });
  for (const r of document.querySelectorAll('input[name=tool]')) {
    r.addEventListener('change', () => {
      tool = r.value;
      canvas.classList.toggle('tool', tool !== 'none');
    });
  }
  window.addEventListener('keydown', onKey);
  installBrush();
}

function onKey(e) {
  if (e.target instanceof HTMLInputElement && e.target.type !== 'range' && e.target.type !== 'radio') return;
  if (e.target instanceof HTMLSelectElement || e.ctrlKey || e.metaKey || e.altKey) return;
  const k = e.key.toLowerCase();
  if (k === ' ') $('play').click();
  else if (k === 's') $('step').click();
  else if (k === 'r') $('reset').click();
  else if (k === 'p') $('shot').click();
  else if (k === 'b') {
    const tools = [...document.querySelectorAll('input[name=tool]')];
    const i = tools.findIndex((t) => t.checked);
    tools[(i + 1) % tools.length].click();
  } else if (k >= '1' && k <= String(Object.keys(FIELDS).length)) setField(Object.keys(FIELDS)[Number(k) - 1]);
  else return;
  e.preventDefault();
}

// Pointer → lattice site, through the layout the renderer drew.
function latticeAt(ev) {
  const rect = canvas.getBoundingClientRect();
  const scale = canvas.width / rect.width; // backing pixels per CSS pixel
  const [x0, y0, side] = renderer.layout();
  const px = (ev.clientX - rect.left) * scale;
  const py = (ev.clientY - rect.top) * scale;
  const l = sim.box_size();
  const x = ((px - x0) / side) * l;
  const y = ((py - y0) / side) * l;
  return x >= 0 && y >= 0 && x < l && y < l ? [x, y] : null;
}

function applyTool(ev) {
  const at = latticeAt(ev);
  if (!at || tool === 'none') return;
  const brush = { soft: 0.1, stiff: 10, erase: 1 };
  try {
    if (tool in brush) sim.paint_substrate(at[0], at[1], 6, brush[tool]);
    else if (tool === 'ablate') sim.remove_cell_at(at[0], at[1]);
  } catch (e) {
    notify([String(e.message ?? e)]);
  }
  dirty = true;
}

function installBrush() {
  let down = false;
  canvas.addEventListener('pointerdown', (e) => {
    down = true;
    canvas.setPointerCapture(e.pointerId);
    applyTool(e);
  });
  canvas.addEventListener('pointermove', (e) => {
    if (down && tool !== 'ablate') applyTool(e);
  });
  canvas.addEventListener('pointerup', () => {
    down = false;
  });
}

// --- start --------------------------------------------------------------------------------------
async function boot() {
  const parsed = parseUrl(location.search);
  state = parsed.state;
  notify(parsed.notices);
  document.body.classList.toggle('embed', state.embed);
  playing = !state.paused;
  buildControls();
  refreshControls();
  updatePlayButton();
  try {
    wasm = await import('../pkg/monolayer.js');
    await wasm.default();
  } catch (e) {
    fatal('Could not load the WebAssembly core (build it with `bash scripts/serve.sh`)', e);
    return;
  }
  showMessage('Looking for WebGPU or WebGL2…');
  resizeCanvas();
  try {
    renderer = await wasm.Renderer.create(canvas);
  } catch (e) {
    fatal('This page needs WebGPU or WebGL2 to draw the tissue', e);
    return;
  }
  $('backend').textContent = `Drawing with ${renderer.backend()}.`;
  demo.backend = renderer.backend();
  try {
    newSim();
  } catch (e) {
    fatal('Could not start the simulation', e);
    return;
  }
  Object.defineProperty(demo, 'sim', { get: () => sim });
  demo.renderer = renderer;
  demo.size = SIZE;
  demo.ready = true;
  requestAnimationFrame(frame);
}

boot();
