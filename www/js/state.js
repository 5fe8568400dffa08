// The page's state: parameters with their allowed ranges, the fields, the presets, and the URL
// that carries them. A bad URL value never breaks the page: it is clamped (or replaced by the
// default) and the page says so.

// Only the FieldKind enum is read here (a plain object of the bindings): the WebAssembly module
// itself is instantiated by main.js.
import { FieldKind } from '../pkg/monolayer.js';

/**
 * The page's state: what the URL carries (parseUrl, toUrl).
 * @typedef {object} PageState
 * @property {PresetName | null} preset the preset whose values these still are, or null
 * @property {number} zeta
 * @property {number} chi
 * @property {number} gamma
 * @property {number} spf the speed limit, steps per 1/30 s
 * @property {number} seed
 * @property {FieldKind} field the field drawn
 * @property {boolean} embed
 * @property {boolean} paused
 * @property {boolean} relax start from random disks, relaxing in the page
 * @property {boolean} tour
 * @property {SizeName} size
 * @property {import('./worker.js').EngineChoice} engine
 * @property {number | null} threads the threaded core's threads (null: every core)
 *
 * @typedef {'zeta' | 'chi' | 'gamma' | 'spf' | 'seed'} ParamName
 * @typedef {'reduced' | 'paper'} SizeName
 * @typedef {'no-holes' | 'short-lived' | 'persistent' | 'paper'} PresetName
 * @typedef {{ label: string, min: number, max: number, def: number, step?: number, log?: boolean,
 *   integer?: boolean, slider?: boolean, model?: boolean }} ParamSpec
 * @typedef {{ label: string, zeta: number, chi: number, gamma: number, size: SizeName }} Preset
 * @typedef {{ file: string, seed: number, size?: SizeName, gamma?: number, preset?: PresetName, step?: number,
 *   firstHole?: number }} ShippedState
 */

// Sizes of the browser's tissue. `reduced`, chosen from measurements (docs/demo.md, "Presets"):
// big enough for a hole to be a hole (several cells around it), small enough that its presets
// open their first hole within a minute of the relaxation on the CPU engine. `paper`: the
// paper's own tissue, 100 cells on 140² after 10,000 relaxation steps (the native defaults).
/** @type {Record<SizeName, import('./worker.js').Size>} */
export const SIZES = {
  reduced: { box: 80, cells: 33, relaxSteps: 1500 },
  paper: { box: 140, cells: 100, relaxSteps: 10000 },
};

// Tissues shipped with the page (`monolayer relaxed-state`, docs/demo.md), so that it opens on a
// confluent tissue: the state at the end of the relaxation for these sizes, seeds and γ, which
// serves every ζ and χ; and, for a preset, a state further on, which serves only exactly its
// parameters. The core checks that a file was made with the page's parameters and seed, and
// refuses it otherwise; any other seed or γ relaxes live, with its progress shown, as does
// `?relax` (to watch the tissue close up). One entry a line (tests/relaxed_state.rs reads them
// and holds each file to what the core computes now).
//
// The paper's preset opens on seed 1 at step 12,000, 2,000 active steps after its relaxation,
// a short time before its first hole (a void region above πR²/4) opens at `firstHole`: the step
// the native core reaches it, one step at a time, with the page's own count.
const asset = (/** @type {string} */ name) => new URL(`../assets/${name}`, import.meta.url).href;
/** @type {ShippedState[]} */
export const SHIPPED_STATES = [
  { size: 'reduced', seed: 1, gamma: 0.06, file: asset('relaxed-seed1.bin') },
  { size: 'paper', seed: 1, gamma: 0.06, file: asset('relaxed-paper-seed1.bin') },
  { preset: 'paper', seed: 1, step: 12000, firstHole: 14255, file: asset('paper-seed1-step12000.bin') },
];
// The shipped state a new tissue of `state` starts from (its URL and step), or null.
/** @param {PageState} state */
export function shippedStateFor(state) {
  if (state.relax) return null;
  const later = SHIPPED_STATES.find((r) => r.preset !== undefined && r.preset === state.preset && r.seed === state.seed);
  const relaxed = SHIPPED_STATES.find((r) => r.size === state.size && r.seed === state.seed && r.gamma === state.gamma);
  return later ?? relaxed ?? null;
}

// Which engine steps the tissue (worker.js): 'auto' is the GPU engine on a hardware adapter
// with WebGPU compute and the CPU engine elsewhere (on a software adapter such as SwiftShader
// the CPU engine is the faster); 'cpu' and 'gpu' choose one ('gpu' falls back to the CPU
// where WebGPU compute is missing, and the page says why).
// The most threads a link may ask of the threaded core.
export const MAX_THREADS = 64;

export const ENGINES = {
  auto: 'Auto (GPU on a hardware GPU)',
  cpu: 'CPU (WebAssembly, bit-identical to native)',
  gpu: 'GPU (WebGPU compute, f32)',
};

// Each parameter: label, range, default, and whether its slider is logarithmic. The page makes
// one slider for each entry with `slider` (in this order); `model` ones are the core's.
/** @type {Record<ParamName, ParamSpec>} */
export const PARAMS = {
  zeta: { label: 'Activity ζ', min: 0, max: 3, def: 2.5, step: 0.01, slider: true, model: true },
  chi: { label: 'Friction ratio χ = ξs/ξcell', min: 0.001, max: 1, def: 0.001, log: true, slider: true, model: true },
  gamma: { label: 'Surface tension γ', min: 0.02, max: 0.2, def: 0.06, step: 0.005, slider: true, model: true },
  spf: { label: 'Speed limit: steps per 1/30 s', min: 1, max: 50, def: 20, step: 1, integer: true, slider: true },
  seed: { label: 'Seed', min: 0, max: 4294967295, def: 1, step: 1, integer: true },
};
const PARAM_NAMES = /** @type {ParamName[]} */ (Object.keys(PARAMS));
export const SLIDERS = PARAM_NAMES.filter((k) => PARAMS[k].slider);
/** @typedef {'zeta' | 'chi' | 'gamma'} ModelParamName the core's parameters (`model` in PARAMS) */
export const MODEL_PARAMS = /** @type {ModelParamName[]} */ (PARAM_NAMES.filter((k) => PARAMS[k].model));

// The fields the core can draw (src/web/view.rs, `FieldKind`), in the order of keys 1–7, with
// the colour bar's units. In the URL a field is its FieldKind name in lower case.
export const FIELDS = new Map([
  [FieldKind.Tissue, { label: 'Cells (outline at φ = ½, axis ∝ elongation)', units: '' }],
  [FieldKind.PhiSum, { label: 'Σφ (void where < 0.01)', units: '' }],
  [FieldKind.Speed, { label: 'Speed |Σφv| with velocity arrows and spiral cores', units: ' µm per time unit' }],
  [FieldKind.Director, { label: 'Nematic order |Σφ Q̂| with director and ±½ defects', units: '' }],
  [FieldKind.StrainRate, { label: 'Strain rate ε̇ = ∇·v/2 with ±½ defects and spiral cores', units: ' per time unit' }],
  [FieldKind.ForceDivergence, { label: 'Active-force divergence ∇·fᵃ with ±½ defects', units: '' }],
  // The recorded forecast (src/analysis/forecast.rs, SHIPPED_MODEL); its score on runs it never
  // saw is in docs/figures.md, "Forecast".
  [FieldKind.Forecast, { label: 'Forecast of the next hole within 3,000 steps (held-out AUC 0.95)', units: '' }],
]);
export const fieldName = (/** @type {FieldKind} */ kind) => FieldKind[kind].toLowerCase();
const fieldByName = (/** @type {string} */ name) => [...FIELDS.keys()].find((k) => fieldName(k) === name);

// The paper's three regimes at this size, from native runs of the same core with the calibrated
// conventions (subdomain friction weights, −∇μ; `monolayer sweep`, seeds 1 and 2, 1,500
// relaxation steps, 8,000 active steps; docs/demo.md, "Presets"). An 80-site box truncates the
// long-range flows that tear the full-size tissue at the paper's ζ ≤ 0.5, so the presets drive
// 3–5× harder:
//   χ = 0.1,   ζ = 2:   no void site in 8,000 active steps (both seeds);
//   χ = 0.001, ζ = 1.5: a hole after ≈ 2,000 active steps that closes by 6,500 (seed 1), a
//                       small one after ≈ 5,250 that closes by 7,000 (seed 2);
//   χ = 0.001, ζ = 2.5: a hole that grows to 34–40 % of the box and stays open, after ≈ 1,200
//                       active steps for seed 1 (the default) and ≈ 4,000 for seed 2.
//
// The `paper` preset is the paper's own tissue at its parameters (Fig. 1a: χ = 0.001, ζ = 0.5,
// γ = 0.06), 100 cells on 140²; natively its first hole opens 4,000–12,000 active steps after
// the relaxation (docs/calibration.md), which the CPU engine takes minutes to reach.
/** @type {Record<PresetName, Preset>} */
export const PRESETS = {
  'no-holes': { label: 'No holes (high friction, χ = 0.1)', zeta: 2, chi: 0.1, gamma: 0.06, size: 'reduced' },
  'short-lived': { label: 'Short-lived holes (χ = 0.001, ζ = 1.5)', zeta: 1.5, chi: 0.001, gamma: 0.06, size: 'reduced' },
  persistent: { label: 'Persistent holes (low friction, χ = 0.001)', zeta: 2.5, chi: 0.001, gamma: 0.06, size: 'reduced' },
  paper: { label: "The paper's tissue (100 cells on 140², χ = 0.001, ζ = 0.5)", zeta: 0.5, chi: 0.001, gamma: 0.06, size: 'paper' },
};
// Whether the state is still exactly the preset (its model parameters and its size).
/** @param {PageState} state @param {PresetName} name */
const isPreset = (state, name) => MODEL_PARAMS.every((k) => state[k] === PRESETS[name][k]) && state.size === PRESETS[name].size;
// The page opens on the paper's own tissue, from its shipped state a short time before a hole.
/** @type {PresetName} */
export const DEFAULT_PRESET = 'paper';
// The size a URL without `size` or `preset` means.
export const DEFAULT_SIZE = PRESETS[DEFAULT_PRESET].size;

// `fallback` is what the state holds without this value (the preset's, or the default).
/** @param {ParamName} name @param {string | null} raw @param {string[]} notices @param {number} fallback */
function clampParam(name, raw, notices, fallback) {
  const p = PARAMS[name];
  let v = Number(raw);
  if (raw === null || raw === '' || !Number.isFinite(v)) {
    notices.push(`${name}=${raw} is not a number: using ${fallback}.`);
    return fallback;
  }
  if (p.integer) v = Math.round(v);
  // −0 would print as "0" in the URL and come back as +0: keep one zero.
  if (v === 0) v = 0;
  if (v < p.min || v > p.max) {
    const c = Math.min(p.max, Math.max(p.min, v));
    notices.push(`${name}=${raw} is outside [${p.min}, ${p.max}]: using ${c}.`);
    return c;
  }
  return v;
}

// Reads the state from a query string. Returns { state, notices }. `version` is the page's code
// version (crate version + git commit, `codeVersion()` of the core): a link made by another
// version (its `v`) says so, since the same parameters and seed may then show another tissue.
/** @param {string} search @param {string} [version] @returns {{ state: PageState, notices: string[] }} */
export function parseUrl(search, version) {
  const q = new URLSearchParams(search);
  const notices = [];
  const linkVersion = q.get('v');
  if (version !== undefined && linkVersion !== null && linkVersion !== version) {
    notices.push(`This link was made by version ${linkVersion || '(none)'} of the page; this is ${version}: the same parameters and seed may show another tissue.`);
  }
  const asked = q.get('preset');
  if (asked !== null && !(asked in PRESETS)) notices.push(`preset=${asked} is unknown: using ${DEFAULT_PRESET}.`);
  const preset = asked !== null && asked in PRESETS ? /** @type {PresetName} */ (asked) : null;
  const base = PRESETS[preset ?? DEFAULT_PRESET];
  /** @type {PageState} */
  const state = {
    preset: preset ?? (MODEL_PARAMS.some((k) => q.has(k)) ? null : DEFAULT_PRESET),
    zeta: base.zeta,
    chi: base.chi,
    gamma: base.gamma,
    spf: PARAMS.spf.def,
    seed: PARAMS.seed.def,
    field: FieldKind.Tissue,
    embed: q.has('embed'),
    paused: q.has('paused'),
    relax: q.has('relax'),
    tour: q.has('tour'),
    size: base.size,
    engine: 'auto',
    threads: null,
  };
  const engine = q.get('engine');
  if (engine !== null) {
    if (engine in ENGINES) state.engine = /** @type {import('./worker.js').EngineChoice} */ (engine);
    else notices.push(`engine=${engine} is unknown (${Object.keys(ENGINES).join(', ')}): using auto.`);
  }
  // The threaded core's pool (worker.js): every core unless the link asks for fewer.
  const threads = q.get('threads');
  if (threads !== null) {
    const n = Number(threads);
    if (Number.isInteger(n) && n >= 1 && n <= MAX_THREADS) state.threads = n;
    else notices.push(`threads=${threads} is not a whole number from 1 to ${MAX_THREADS}: using every core.`);
  }
  const size = q.get('size');
  if (size !== null) {
    if (size in SIZES) state.size = /** @type {SizeName} */ (size);
    else notices.push(`size=${size} is unknown (${Object.keys(SIZES).join(' or ')}): using ${state.size}.`);
  }
  for (const name of PARAM_NAMES) {
    if (q.has(name)) state[name] = clampParam(name, q.get(name), notices, state[name]);
  }
  // A preset with a model parameter changed is no longer that preset: the URL written back
  // must carry the values, or a shared link would show another tissue.
  if (state.preset !== null && !isPreset(state, state.preset)) {
    state.preset = null;
  }
  const field = q.get('field');
  if (field !== null) {
    const kind = fieldByName(field);
    if (kind !== undefined) state.field = kind;
    else notices.push(`field=${field} is unknown: showing the cells.`);
  }
  return { state, notices };
}

// The query string that reproduces the view (only what differs from the defaults, plus the
// seed so that a shared link shows the same tissue, and the code version `v` when given).
/** @param {PageState} state @param {string} [version] */
export function toUrl(state, version) {
  const q = new URLSearchParams();
  if (state.preset) q.set('preset', state.preset);
  else {
    for (const k of MODEL_PARAMS) q.set(k, String(state[k]));
    if (state.size !== DEFAULT_SIZE) q.set('size', state.size);
  }
  q.set('seed', String(state.seed));
  if (state.spf !== PARAMS.spf.def) q.set('spf', String(state.spf));
  if (state.field !== FieldKind.Tissue) q.set('field', fieldName(state.field));
  if (state.embed) q.set('embed', '');
  if (state.paused) q.set('paused', '');
  if (state.relax) q.set('relax', '');
  if (state.tour) q.set('tour', '');
  if (state.engine !== 'auto') q.set('engine', state.engine);
  if (state.threads !== null) q.set('threads', String(state.threads));
  if (version !== undefined) q.set('v', version);
  return '?' + q.toString().replace(/=(&|$)/g, '$1');
}

// Slider position (0–1000) ↔ value, logarithmic where the parameter spans decades.
/** @param {ParamName} name @param {number} v */
export function toSlider(name, v) {
  const p = PARAMS[name];
  const t = p.log ? Math.log(v / p.min) / Math.log(p.max / p.min) : (v - p.min) / (p.max - p.min);
  return Math.round(1000 * t);
}

/** @param {ParamName} name @param {number} s */
export function fromSlider(name, s) {
  const p = PARAMS[name];
  const t = s / 1000;
  let v = p.log ? p.min * Math.pow(p.max / p.min, t) : p.min + t * (p.max - p.min);
  if (p.log) v = Number(v.toPrecision(2));
  else if (p.integer) v = Math.round(v);
  else v = Math.round(v / (p.step ?? 1)) * (p.step ?? 1);
  return Number(v.toFixed(6));
}
