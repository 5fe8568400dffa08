// The simulation's own thread. The WebAssembly core is instantiated here and steps while the
// page plays, whatever the drawing costs; whenever the main thread is ready to draw, it asks
// for a frame and gets the latest state's view, its arrays transferred (not copied).
//
// Two engines step the tissue: the CPU core compiled to WebAssembly (`WebSim`, bit-identical to
// native), and where WebGPU compute works the GPU engine (`WebGpuEngine`, the same model in
// f32 on WebGPU compute, src/gpu/), which steps without reading back and hands its state to
// the `WebSim` only when the page draws, measures or edits: everything drawn and read out is
// measured by the same code either way.
//
// The core comes in two builds (scripts/serve.sh): the single-thread one (www/pkg, with the GPU
// engine) and a threaded one (www/pkg-threads: the core's parallel loops on a pool of Web
// Workers sharing its memory, wasm-bindgen-rayon), which needs a cross-origin isolated page
// (COOP/COEP headers) for its shared memory. The first tissue loads one of them (loadCore):
// the threaded one where the page is isolated and the CPU engine is to step, else the other.
// Both give the same bits: the parallel loops do not depend on the thread count (par.rs).
//
// Messages in: { type: 'new', size, params, seed, shipped (a shipped state's URL, or null),
// engine ('auto' | 'cpu' | 'gpu'), threads (null: every core) }, { type: 'engine', engine },
// { type: 'play', on }, { type: 'spf', n },
// { type: 'frame', field, dpr }, { type: 'call', id, method, args }.
// Messages out: { type: 'ready', info }, { type: 'progress', text }, { type: 'engine', stats }, { type: 'frame', parts, stats, cores }, { type: 'stopped', why,
// active }, { type: 'result', id, value | error }, { type: 'fatal', message }.

// The core's module (its exports: WebSim, WebPlayback, and WebGpuEngine in the single-thread
// build), once loaded; which build it is, on how many threads, and why.
let core = null;
let coreNote = '';

// Loads the core for the first tissue `m` (the build stays for the worker's life).
async function loadCore(m) {
  if (core) return;
  let why;
  if (!self.crossOriginIsolated) why = 'the page is not cross-origin isolated';
  else if (typeof SharedArrayBuffer === 'undefined') why = 'this browser has no SharedArrayBuffer';
  else if (m.engine === 'gpu') why = 'the GPU engine is in the single-thread build';
  else if (m.engine === 'auto' && !(await gpuAdapterOnce()).software && !(await gpuAdapterOnce()).error) {
    why = 'the GPU engine may step here, and it is in the single-thread build';
  }
  if (!why) {
    try {
      const threaded = await import('../pkg-threads/monolayer.js');
      await threaded.default();
      await threaded.initThreadPool(Math.max(1, m.threads ?? navigator.hardwareConcurrency ?? 1));
      core = threaded;
      coreNote = 'threaded build, cross-origin isolated';
      return;
    } catch (e) {
      why = `the threaded build did not load (${e.message ?? e})`;
    }
  }
  const single = await import('../pkg/monolayer.js');
  await single.default();
  core = single;
  coreNote = `single-thread build: ${why}`;
}

let sim = null;
// The GPU engine, or null while the CPU engine steps: { engine: WebGpuEngine, adapter,
// software }; `gpuNote` says why the engine is the one it is (shown by the page).
let gpu = null;
let gpuNote = '';
// The device, asked for once per worker (a promise of { engine } or { error }).
let gpuDevice = null;
// The GPU's state is ahead of `sim` (download before drawing or measuring); `sim` was edited
// since the last upload (upload before stepping).
let gpuAhead = false;
let gpuEdited = false;
// The GPU submissions under way, oldest first (the engine keeps up to `in_flight_max`, so that
// it steps the next while the last is checked): { k (steps), down (a Promise of the state they
// end at, queued behind them where it is due a row of readouts or a frame, else null) }.
let flight = [];
const queued = () => flight.reduce((n, f) => n + f.k, 0);
// Everything that may touch the GPU engine or replace `sim` runs in turn, one after the other
// (a submission must be checked before the next, a download must not meet a submission):
// `exclusive(fn)` queues fn behind the last one. `turnQueued`: a GPU turn is in the queue.
let queue = Promise.resolve();
const exclusive = (fn) => (queue = queue.then(fn, fn));
let turnQueued = false;
// A run's frames opened in the page instead of the live simulation (null while live):
// { p: WebPlayback, frames: [{ name, step, file }], index }.
let playback = null;
// How the current tissue started: 'snapshot' (a shipped state) or 'disks' (relaxing here), and
// the step it started at.
let startedFrom = null;
let startedAt = 0;
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
// Steps taken and their milliseconds since the engine was last chosen (hand-offs and checks
// included): the speed the page reports as measured here.
let speed = { steps: 0, ms: 0 };

function timed(steps, ms) {
  speed.steps += steps;
  speed.ms += ms;
}

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
  if (gpu && sim) {
    if (!turnQueued) {
      turnQueued = true;
      exclusive(gpuTurn).finally(() => {
        turnQueued = false;
        if (playing || frameRequest) schedule();
      });
    }
    return;
  }
  try {
    if (playing && sim) {
      refill();
      const n = Math.min(Math.floor(budget), Math.max(1, Math.floor(BATCH_MS / msPerStep)));
      if (n >= 1) {
        const t0 = performance.now();
        if (takeSteps(n)) {
          const ms = performance.now() - t0;
          msPerStep = 0.8 * msPerStep + 0.2 * (ms / n);
          timed(n, ms);
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

// --- the GPU engine --------------------------------------------------------------------------
// A GPU submission is sized to take about this long, so that frames and calls are answered
// between submissions.
const GPU_BATCH_MS = 40;

// Whether an adapter is a software one (SwiftShader, lavapipe): there the CPU engine is faster.
function isSoftware(info) {
  const text = [info?.vendor, info?.architecture, info?.description, info?.device].join(' ');
  return Boolean(info?.isFallbackAdapter) || /swiftshader|llvmpipe|lavapipe|software/i.test(text);
}

// What WebGPU offers here, asked once: { adapter (its name), software } or { error }.
let gpuAdapter = null;
function gpuAdapterOnce() {
  gpuAdapter ??= (async () => {
    if (!self.navigator?.gpu) return { error: 'this browser has no WebGPU' };
    // The adapter the engine asks for (src/gpu/context.rs: high performance), so that the
    // name shown and the software test are of the one that steps.
    const adapter = await navigator.gpu.requestAdapter({ powerPreference: 'high-performance' }).catch(() => null);
    if (!adapter) return { error: 'WebGPU found no adapter' };
    const info = adapter.info ?? {};
    const name = [info.vendor, info.architecture, info.description].filter(Boolean).join(' ') || 'unnamed adapter';
    return { adapter: name, software: isSoftware(info) };
  })();
  return gpuAdapter;
}

// The GPU engine's device, made once and only when it is to step: { engine, adapter,
// software } or { error }.
function gpuDeviceOnce(found) {
  gpuDevice ??= (async () => {
    try {
      const engine = await core.WebGpuEngine.create();
      return { engine, adapter: found.adapter, software: found.software || engine.runs_on_cpu() };
    } catch (e) {
      return { error: `WebGPU refused a device for compute (${e.message ?? e})` };
    }
  })();
  return gpuDevice;
}

// The GPU engine's kernels, compiled one at a time (once per device), the page told the
// progress before each: the browser compiles them in its GPU process before their first use,
// which would otherwise hold the first step (about 7 s on SwiftShader) with nothing shown.
async function compileKernels(engine) {
  const total = engine.kernels();
  for (let left = engine.kernels_left(); left > 0; ) {
    postMessage({ type: 'progress', text: `compiling the GPU engine's kernels: ${total - left} of ${total}` });
    left = await engine.compile_next();
  }
}

// Chooses the engine for a new tissue: 'gpu' wherever WebGPU compute works, 'cpu' always, and
// 'auto' the GPU on a hardware adapter and the CPU on a software one, where it is faster.
async function chooseEngine(wanted) {
  gpu = null;
  flight = [];
  gpuAhead = gpuEdited = false;
  if (wanted === 'cpu') {
    gpuNote = 'chosen';
    return;
  }
  const found = await gpuAdapterOnce();
  if (found.error) {
    gpuNote = `${found.error}: stepping on the CPU engine`;
    return;
  }
  if (wanted === 'auto' && found.software) {
    gpuNote = `WebGPU runs in software here (${found.adapter}), where the CPU engine is faster`;
    return;
  }
  if (!core.WebGpuEngine) {
    gpuNote = 'the threaded core has no GPU engine (?engine=gpu opens the page on the single-thread core, which has)';
    return;
  }
  const d = await gpuDeviceOnce(found);
  if (d.error) {
    gpuNote = `${d.error}: stepping on the CPU engine`;
    return;
  }
  try {
    await compileKernels(d.engine);
  } catch (e) {
    gpuNote = `the GPU engine's kernels did not compile (${e.message ?? e}): stepping on the CPU engine`;
    return;
  }
  try {
    d.engine.upload(sim);
  } catch (e) {
    gpuNote = `the GPU could not take this tissue (${e.message ?? e}): stepping on the CPU engine`;
    return;
  }
  if (wanted === 'auto') {
    // A hardware adapter: the faster engine for this tissue, by a short trial.
    let t;
    try {
      t = await engineTrial(d, TRIAL_STEPS);
    } catch (e) {
      gpuNote = `the GPU engine failed its trial (${e.message ?? e}): stepping on the CPU engine`;
      return;
    }
    const ms = `${t.gpu.toFixed(2)} ms per step against ${t.cpu.toFixed(2)} on the CPU engine in a short trial`;
    if (!(t.gpu < t.cpu)) {
      gpuNote = `${d.adapter} took ${ms}: stepping on the CPU engine`;
      return;
    }
    gpu = d;
    gpuNote = `${d.adapter}, ${ms}`;
    return;
  }
  gpu = d;
  gpuNote = d.software ? `on a software adapter (${d.adapter}), chosen` : d.adapter;
}

// Steps per engine in `auto`'s trial: enough to time past the first submission's set-up,
// few enough to stay under a second on any engine worth choosing.
const TRIAL_STEPS = 5;

// Milliseconds per step of each engine on the tissue as it is, which the trial leaves as it was:
// the CPU core on a copy, the GPU engine from an upload of `sim` after one warm-up step (its
// first submission compiles and sets up), then uploaded again.
async function engineTrial(d, steps) {
  const copy = sim.core_copy();
  let cpu;
  try {
    const t0 = performance.now();
    copy.step(steps);
    cpu = (performance.now() - t0) / steps;
  } finally {
    copy.free();
  }
  d.engine.upload(sim);
  d.engine.submit(1);
  await d.engine.check();
  const t1 = performance.now();
  const k = d.engine.submit(steps);
  await d.engine.check();
  const gpuMs = (performance.now() - t1) / Math.max(k, 1);
  d.engine.upload(sim);
  return { cpu, gpu: gpuMs };
}

// Brings `sim` level with the GPU (the submissions under way settled, then one readback), so
// that it can be drawn, measured or edited.
async function gpuDown() {
  while (gpu && flight.length) {
    if ((await gpuSettle()) === null) return;
  }
  if (!gpu || !gpuAhead) return;
  try {
    sim.adopt(await gpu.engine.download());
  } catch (e) {
    if (gpuFailed()) return;
    throw e;
  }
  gpuAhead = false;
  changed = true;
}

// Whether the GPU device failed (lost, a GPU error, a readback that did not map), as opposed to
// the model (φ out of range, a cell lost); if it did, the engine is dropped (gpuLost).
function gpuFailed() {
  const why = gpu?.engine.device_fault();
  if (!why) return false;
  gpuLost(why);
  return true;
}

// The GPU engine is gone: the tissue goes on on the CPU engine from the last state `sim` holds
// (the last hand-off, at most a row of readouts behind the device), and the page says why. A
// later choice of the GPU engine asks for a new adapter and device.
function gpuLost(why) {
  const lost = gpu;
  gpu = null;
  gpuAdapter = null;
  gpuDevice = null;
  flight = [];
  gpuAhead = gpuEdited = false;
  try {
    lost.engine.free();
  } catch {
    // Already freed: nothing to release.
  }
  gpuNote = `the GPU device failed (${why}); the tissue goes on on the CPU engine from step ${sim.step_count()}`;
  speed = { steps: 0, ms: 0 };
  changed = true;
  postMessage({ type: 'engine', stats: stats(), lost: gpuNote });
}

// Submits GPU steps while fewer than the engine's limit are under way, up to `limit` steps
// under way in all, `batch` at most in one (each ends at the next row of readouts at the
// latest; one that ends on a row, or follows a request for a frame, queues the download of the
// state it ends at), then settles the oldest. Returns its steps, 0 if they were put back to be
// taken again (with more solve iterations or storage, and the submissions after it with them),
// or null if the model failed (the state before the submission, in `sim` too; the page told).
async function gpuAdvance(limit, batch) {
  if (gpuEdited) {
    await gpuDown();
    if (!gpu) return 0;
    gpu.engine.upload(sim);
    gpuEdited = false;
  }
  while (flight.length < gpu.engine.in_flight_max()) {
    const want = Math.min(limit - queued(), batch);
    if (want < 1) break;
    const toRow = sim.steps_to_next_row(gpu.engine.submitted_to());
    const k = gpu.engine.submit(Math.min(want, toRow));
    if (k === 0) break;
    const down = k === toRow || frameRequest ? gpu.engine.download() : null;
    // A download dropped with its submission (put back, or the device lost) is never awaited.
    down?.catch(() => {});
    flight.push({ k, down });
  }
  return gpuSettle();
}

// Settles the oldest GPU submission under way (gpuAdvance); a download queued behind it is
// taken by `sim` (a row of readouts, a frame sent if one is asked for).
async function gpuSettle() {
  const f = flight.shift();
  if (!f) return 0;
  let taken;
  try {
    taken = await gpu.engine.check();
  } catch (e) {
    flight = [];
    if (gpuFailed()) return 0;
    playing = false;
    gpuAhead = true;
    await gpuDown();
    postMessage({ type: 'stopped', why: String(e.message ?? e), active: sim.active() });
    return null;
  }
  if (!taken) {
    flight = [];
    return 0;
  }
  gpuAhead = true;
  if (f.down) {
    try {
      sim.adopt(await f.down);
    } catch (e) {
      if (gpuFailed()) return 0;
      throw e;
    }
    gpuAhead = flight.length > 0;
    changed = true;
    if (frameRequest) sendFrame();
  }
  return f.k;
}

// One turn of the GPU engine: a submission while playing, then a frame if one is asked for.
async function gpuTurn() {
  if (!gpu || !sim) return;
  try {
    if (playing) {
      refill();
      if (budget >= 1 || flight.length) {
        const t0 = performance.now();
        const k = await gpuAdvance(Math.floor(budget), Math.max(1, Math.floor(GPU_BATCH_MS / msPerStep)));
        if (k === null || !gpu) return;
        if (k) {
          const ms = performance.now() - t0;
          msPerStep = 0.8 * msPerStep + 0.2 * (ms / k);
          timed(k, ms);
          budget -= k;
          changed = true;
        }
      } else {
        await new Promise((r) => setTimeout(r, 1000 / (30 * spf)));
      }
    }
    // Paused, or a frame asked for with nothing under way: level with the GPU, then draw
    // (while playing, a frame comes with the next download).
    if (!playing || (frameRequest && !flight.length)) await gpuDown();
    if (frameRequest && !gpuAhead) sendFrame();
  } catch (e) {
    if (!gpuFailed()) fatal(e);
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
    startedAt,
    // Which engine steps, and why (main.js, showEngine).
    engine: gpu ? 'gpu' : 'cpu',
    engineNote: gpuNote,
    stepsPerSecond: speed.steps > 0 && speed.ms > 0 ? (1000 * speed.steps) / speed.ms : null,
    solveIterations: gpu ? gpu.engine.solve_iterations() : null,
    // The core's build and threads (loadCore).
    threads: core.coreThreads(),
    coreNote,
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
  // The spiral cores this view marks (the guided tour waits for one in the flow).
  const cores = (playback ? playback.p : sim).spiral_cores().length / 3;
  postMessage({ type: 'frame', parts, stats: stats(), cores }, [parts.tissue.buffer, parts.field.buffer, parts.segments.buffer]);
}

// What the page and the tests may ask of the simulation, beyond stepping.
const CALLS = {
  // Steps n now and returns the milliseconds it took.
  // On the GPU engine, if the device fails part way, the rest are taken on the CPU engine
  // from the last state handed over.
  step: async (n) => {
    const t0 = performance.now();
    let left = n;
    while (gpu && left > 0) {
      const k = await gpuAdvance(left, left);
      if (k === null) return null;
      left -= k;
    }
    if (gpu) await gpuDown();
    if (left > 0 && !takeSteps(left)) return null;
    const ms = performance.now() - t0;
    timed(n, ms);
    return ms;
  },
  // `auto`'s timed trial on the GPU engine in use (the tests drive it on a software adapter,
  // where `auto` does not try): ms per step of each engine; the tissue does not move.
  engine_trial: async (steps) => {
    if (!gpu) return null;
    await gpuDown();
    return engineTrial(gpu, steps);
  },
  // Destroys the GPU engine's device, as a driver reset would (the browser tests' forced loss).
  gpu_destroy: () => gpu?.engine.destroy_device(),
  // The CPU core's own milliseconds per step, without the readouts: the fastest of `batches`
  // batches of n steps of a copy of the tissue (the tests' wasm/native report). The tissue shown
  // does not move.
  core_ms_per_step: (n, batches) => {
    const copy = sim.core_copy();
    try {
      let best = Infinity;
      for (let b = 0; b < batches; b++) {
        const t0 = performance.now();
        copy.step(n);
        best = Math.min(best, (performance.now() - t0) / n);
      }
      return best;
    } finally {
      copy.free();
    }
  },
  set: (name, value) => edited(sim[`set_${name}`](value)),
  paint_substrate: (...a) => edited(sim.paint_substrate(...a)),
  remove_cell_at: (...a) => edited(sim.remove_cell_at(...a)),
  substrate_at: (...a) => sim.substrate_at(...a),
  cell_at: (...a) => sim.cell_at(...a),
  n_cells: () => sim.n_cells(),
  box_size: () => sim.box_size(),
  fingerprint: () => sim.fingerprint(),
  phi_sum: () => sim.phi_sum(),
  field_values: (kind) => sim.field_values(kind),
  evaluate: () => sim.evaluate(),
  // The ±½ defects and spiral cores that the view of `kind` marks (counts), built now.
  marks: (kind) => {
    sim.field_values(kind);
    return { defects: sim.defects().length / 4, spiralCores: sim.spiral_cores().length / 3 };
  },
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

// An edit of `sim` reaches the GPU before its next step.
function edited(value) {
  gpuEdited = gpu !== null;
  return value;
}

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
    p = records.length ? new core.WebPlayback('run.json', await records[0].text()) : new core.WebPlayback('', '');
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
  gpu = null;
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

// A new tissue (the 'new' message): from a shipped state where one fits, else from
// random disks; then the engine that steps it.
async function newTissue(m) {
  await loadCore(m);
  gpu = null;
  if (sim) sim.free();
  sim = null;
  if (playback) playback.p.free();
  playback = null;
  const { size, params: p, seed } = m;
  const args = [size.box, size.cells, size.relaxSteps, p.zeta, p.chi, p.gamma, seed];
  if (m.shipped) {
    try {
      const res = await fetch(m.shipped);
      if (!res.ok) throw new Error(`HTTP ${res.status}`);
      sim = core.WebSim.from_snapshot(new Uint8Array(await res.arrayBuffer()), ...args);
      startedFrom = 'snapshot';
    } catch (err) {
      // Not fatal: the same tissue comes from relaxing here, only later.
      console.warn(`relaxing live: the shipped state ${m.shipped} was not usable (${err.message ?? err})`);
    }
  }
  try {
    if (!sim) {
      sim = new core.WebSim(...args);
      startedFrom = 'disks';
    }
    startedAt = sim.step_count();
  } catch (err) {
    postMessage({ type: 'fatal', message: `Could not start the simulation: ${err.message ?? err}` });
    return;
  }
  await chooseEngine(m.engine ?? 'auto');
  changed = true;
  postMessage({ type: 'ready', stats: stats() });
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
      await exclusive(() => newTissue(m));
    } else if (m.type === 'engine') {
      // Another engine for the same tissue: it goes on from the state it has now.
      await exclusive(async () => {
        if (!sim) return;
        if (gpu) await gpuDown();
        await chooseEngine(m.engine);
        speed = { steps: 0, ms: 0 };
        changed = true;
        postMessage({ type: 'engine', stats: stats() });
      });
    } else if (m.type === 'play') {
      playing = m.on;
    } else if (m.type === 'spf') {
      spf = m.n;
    } else if (m.type === 'frame') {
      frameRequest = m;
    } else if (m.type === 'call') {
      try {
        // Level with the GPU first: a call reads or edits the tissue as it is now.
        const value = await exclusive(async () => {
          if (gpu && sim) await gpuDown();
          return CALLS[m.method](...(m.args ?? []));
        });
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
