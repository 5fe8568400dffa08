// The simulation's own thread. The WebAssembly core is instantiated here and steps while the
// page plays, whatever the drawing costs; whenever the main thread is ready to draw, it asks
// for a frame and gets the latest state's view, its arrays transferred (not copied).
//
// Messages in: { type: 'new', size, params, seed, relaxed (a relaxed state's URL, or null) }, { type: 'play', on }, { type: 'spf', n },
// { type: 'frame', field, dpr }, { type: 'call', id, method, args }.
// Messages out: { type: 'ready', info }, { type: 'frame', parts, stats }, { type: 'stopped', why,
// active }, { type: 'result', id, value | error }, { type: 'fatal', message }.

import init, { WebSim, WebPlayback } from '../pkg/monolayer.js';

let sim = null;
// A run's frames opened in the page instead of the live simulation (null while live):
// { p: WebPlayback, frames: [{ name, step, file }], index }.
let playback = null;
// How the current tissue started: 'snapshot' (a shipped relaxed state) or 'disks' (relaxing here).
let startedFrom = null;
let playing = false;
// The "steps per frame" slider caps the speed at `spf` steps per 1/30 s: a budget that refills
// with time, not with frames drawn, so that drawing never holds stepping back.
let spf = 20;
let budget = 0;
let refilledAt = performance.now();
// The page's pending request for a frame, and whether the state changed since the last frame.
let frameRequest = null;
let changed = true;
let lastSent = { field: null, dpr: null };
let scheduled = false;
// A batch of steps is sized to take about this long, so that messages are answered promptly.
const BATCH_MS = 12;
let msPerStep = 5;

// console_error_panic_hook writes a Rust panic's message to console.error before the trap.
let lastConsoleError = '';
const consoleError = console.error.bind(console);
console.error = (...args) => {
  lastConsoleError = args.map(String).join(' ');
  consoleError(...args);
};

function fatal(e) {
  const panic = lastConsoleError.includes('panicked') ? `\n\n${lastConsoleError}` : '';
  postMessage({ type: 'fatal', message: `${e.message ?? e}${panic}` });
  sim = null;
}

// A zero-delay task (setTimeout would be clamped to 4 ms once nested).
const tick = new MessageChannel();
tick.port1.onmessage = () => pump();
function schedule() {
  if (!scheduled) {
    scheduled = true;
    tick.port2.postMessage(null);
  }
}

// Steps the core; on an error of the model (the core keeps the state before the failing step)
// stops and tells the page why.
function takeSteps(n) {
  try {
    sim.step(n);
    return true;
  } catch (e) {
    if (e instanceof WebAssembly.RuntimeError) throw e;
    playing = false;
    postMessage({ type: 'stopped', why: String(e.message ?? e), active: sim.active() });
    return false;
  }
}

function refill() {
  const now = performance.now();
  budget = Math.min(spf, budget + ((now - refilledAt) * spf * 30) / 1000);
  refilledAt = now;
}

function pump() {
  scheduled = false;
  if (!sim && !playback) return;
  try {
    if (playing && sim) {
      refill();
      const n = Math.min(Math.floor(budget), Math.max(1, Math.floor(BATCH_MS / msPerStep)));
      if (n >= 1) {
        const t0 = performance.now();
        if (takeSteps(n)) {
          msPerStep = 0.8 * msPerStep + 0.2 * ((performance.now() - t0) / n);
          budget -= n;
          changed = true;
        }
      }
    }
    if (frameRequest) sendFrame();
    if (playing) {
      if (budget >= 1) schedule();
      else setTimeout(schedule, 1000 / (30 * spf));
    }
  } catch (e) {
    fatal(e);
  }
}

function stats() {
  if (playback) {
    const a = playback.p.stats();
    return {
      step: a[0], time: a[1], holes: a[2], area: a[3], packing: a[4], active: a[0] >= a[10], zeta: a[5], chi: a[6],
      gamma: a[7], cells: a[8], l: a[9], relaxSteps: a[10], timeUnitSeconds: a[11], msPerStep, startedFrom: 'frames',
      frame: playback.index, frames: playback.frames.length,
    };
  }
  return {
    step: sim.step_count(),
    holes: sim.holes(),
    area: sim.hole_area(),
    time: sim.active_time(),
    active: sim.active(),
    packing: sim.packing_fraction(),
    zeta: sim.zeta(),
    chi: sim.chi(),
    gamma: sim.gamma(),
    cells: sim.n_cells(),
    l: sim.box_size(),
    relaxSteps: sim.relax_steps(),
    timeUnitSeconds: sim.time_unit_seconds(),
    msPerStep,
    startedFrom,
    // The only engine so far: the core compiled to WebAssembly (see main.js, showEngine).
    engine: 'cpu',
  };
}

function sendFrame() {
  const { field, dpr } = frameRequest;
  if (!changed && field === lastSent.field && dpr === lastSent.dpr) return;
  frameRequest = null;
  changed = false;
  lastSent = { field, dpr };
  const view = (playback ? playback.p : sim).view(field, dpr);
  const parts = {
    l: view.l(),
    kind: view.kind(),
    tissue: view.tissue(),
    field: view.field(),
    segments: view.segments(),
    range: view.range(),
  };
  view.free();
  postMessage({ type: 'frame', parts, stats: stats() }, [parts.tissue.buffer, parts.field.buffer, parts.segments.buffer]);
}

// What the page and the tests may ask of the simulation, beyond stepping.
const CALLS = {
  // Steps n now and returns the milliseconds it took.
  step: (n) => {
    const t0 = performance.now();
    if (!takeSteps(n)) return null;
    return performance.now() - t0;
  },
  set: (name, value) => sim[`set_${name}`](value),
  paint_substrate: (...a) => sim.paint_substrate(...a),
  remove_cell_at: (...a) => sim.remove_cell_at(...a),
  substrate_at: (...a) => sim.substrate_at(...a),
  cell_at: (...a) => sim.cell_at(...a),
  n_cells: () => sim.n_cells(),
  box_size: () => sim.box_size(),
  fingerprint: () => sim.fingerprint(),
  defects: () => (playback ? playback.p : sim).defects(),
  spiral_cores: () => (playback ? playback.p : sim).spiral_cores(),
  stats: () => stats(),
  // The Download button: the readouts since the tissue was made (CSV), the current state as a
  // native frame file and a run.json that makes a run of it for `monolayer analyze`.
  download: () => {
    if (!sim) throw new Error("this takes data out of the live simulation, and a run's frames are shown (Reset returns to it)");
    return downloadParts();
  },
  readout_rows: () => sim.readout_rows(),
  // A run's frames: `files` (File objects the page was given) replace the live simulation.
  open: (files) => openRun(files),
  show: (index) => showFrame(index),
};

function downloadParts() {
  return {
    csv: sim.readouts_csv(),
    npz: sim.frame_npz(),
    frameName: sim.frame_name(),
    runJson: sim.run_json(),
    step: sim.step_count(),
  };
}

const FRAME_NAME = /^frame_\d+\.npz$/;
// A run directory's other files (its checkpoints, lock, and the tables and plots of `analyze`):
// skipped without a word when a whole directory is opened.
const RUN_FILES = /^(checkpoint\.npz|last_good_state\.npz|\..*|.*\.(csv|png|svg|md|txt|webm))$/;

// Opens the files of a run (its run.json and frame_*.npz; a directory's other files are
// ignored): every frame is read and checked on its own, so that a bad one is reported, naming
// the file, and skipped. Returns { frames: [{ name, step }], errors, seed, runVersion, hasRecord }
// or { error, errors } when nothing can be shown (the live simulation then carries on).
async function openRun(files) {
  const errors = [];
  const records = files.filter((f) => f.name === 'run.json');
  const frames = files.filter((f) => FRAME_NAME.test(f.name)).sort((a, b) => (a.name < b.name ? -1 : 1));
  for (const f of files) {
    if (!records.includes(f) && !frames.includes(f) && !RUN_FILES.test(f.name)) {
      errors.push(`${f.name}: not a frame (frame_<step>.npz) or run.json: ignored`);
    }
  }
  if (records.length > 1) errors.push(`${records.length} files named run.json: using the first`);
  let p;
  try {
    p = records.length ? new WebPlayback('run.json', await records[0].text()) : new WebPlayback('', '');
  } catch (e) {
    return { error: String(e.message ?? e), errors };
  }
  if (!records.length) errors.push('no run.json: the frames are shown with the default parameters (R, ζ, Δt) at their own size');
  const good = [];
  for (const file of frames) {
    try {
      const step = p.check(file.name, new Uint8Array(await file.arrayBuffer()));
      if (good.some((g) => g.step === step)) errors.push(`${file.name}: step ${step} again: skipped`);
      else good.push({ name: file.name, step, file });
    } catch (e) {
      errors.push(String(e.message ?? e));
    }
  }
  if (!good.length) {
    p.free();
    return { error: frames.length ? 'none of the frames could be read' : 'no frame_<step>.npz among the files', errors };
  }
  good.sort((a, b) => a.step - b.step);
  playing = false;
  if (sim) sim.free();
  sim = null;
  if (playback) playback.p.free();
  playback = { p, frames: good, index: -1 };
  const first = await showFrame(0);
  return {
    frames: good.map(({ name, step }) => ({ name, step })), errors: first.error ? [...errors, first.error] : errors,
    seed: p.seed(), runVersion: p.run_version(), hasRecord: p.has_record(),
  };
}

// Shows frame `index` of the run opened: { step } or { error } (naming the file).
async function showFrame(index) {
  const f = playback.frames[index];
  try {
    playback.p.show(f.name, new Uint8Array(await f.file.arrayBuffer()));
  } catch (e) {
    return { index, step: f.step, error: String(e.message ?? e) };
  }
  playback.index = index;
  changed = true;
  return { index, step: f.step };
}

// Messages are handled one after the other, each after the last one's awaits (the core's
// instantiation, a relaxed state's download): a call or a second 'new' never meets a
// half-made simulation.
let inbox = Promise.resolve();
onmessage = (e) => {
  inbox = inbox.then(() => handle(e.data));
};

async function handle(m) {
  try {
    if (m.type === 'new') {
      if (!sim) await init();
      if (sim) sim.free();
      sim = null;
      if (playback) playback.p.free();
      playback = null;
      const { size, params: p, seed } = m;
      const args = [size.box, size.cells, size.relaxSteps, p.zeta, p.chi, p.gamma, seed];
      if (m.relaxed) {
        try {
          const res = await fetch(m.relaxed);
          if (!res.ok) throw new Error(`HTTP ${res.status}`);
          sim = WebSim.from_relaxed(new Uint8Array(await res.arrayBuffer()), ...args);
          startedFrom = 'snapshot';
        } catch (err) {
          // Not fatal: the same tissue comes from relaxing here, only later.
          console.warn(`relaxing live: the relaxed state ${m.relaxed} was not usable (${err.message ?? err})`);
        }
      }
      try {
        if (!sim) {
          sim = new WebSim(...args);
          startedFrom = 'disks';
        }
      } catch (err) {
        postMessage({ type: 'fatal', message: `Could not start the simulation: ${err.message ?? err}` });
        return;
      }
      changed = true;
      postMessage({ type: 'ready', stats: stats() });
    } else if (m.type === 'play') {
      playing = m.on;
    } else if (m.type === 'spf') {
      spf = m.n;
    } else if (m.type === 'frame') {
      frameRequest = m;
    } else if (m.type === 'call') {
      try {
        const value = await CALLS[m.method](...(m.args ?? []));
        changed = true; // cheap to assume: a call may have edited the tissue
        postMessage({ type: 'result', id: m.id, value });
      } catch (err) {
        if (err instanceof WebAssembly.RuntimeError) throw err;
        postMessage({ type: 'result', id: m.id, error: String(err.message ?? err) });
      }
    }
    schedule();
  } catch (err) {
    fatal(err);
  }
}
