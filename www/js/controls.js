// The controls: sliders made from the parameter table, the preset and field choosers, the seed,
// the buttons, the keyboard shortcuts and the brushes on the canvas. They only call `actions`
// (main.js), which change the core, the state and the URL.

import { PARAMS, SLIDERS, FIELDS, PRESETS, ENGINES, fieldName, toSlider, fromSlider } from './state.js';

const $ = (/** @type {string} */ id) => /** @type {HTMLElement} */ (document.getElementById(id));
const input = (/** @type {string} */ id) => /** @type {HTMLInputElement} */ (document.getElementById(id));
const select = (/** @type {string} */ id) => /** @type {HTMLSelectElement} */ (document.getElementById(id));

/**
 * What the controls do (main.js): setParam(name, v), applyPreset(name), setField(kind),
 * setSeed(v), setEngine(engine), togglePlay(), stepOnce(), reset(), screenshot(), record(),
 * download(), brush(x, y, radius, multiplier), ablate(x, y), latticeAt(event).
 * @typedef {object} ControlActions
 * @property {(name: import('./state.js').ParamName, v: number) => void} setParam
 * @property {(name: import('./state.js').PresetName) => void} applyPreset
 * @property {(kind: import('../pkg/monolayer.js').FieldKind) => void} setField
 * @property {(raw: string) => void} setSeed
 * @property {(engine: import('./worker.js').EngineChoice) => unknown} setEngine
 * @property {() => void} togglePlay
 * @property {() => void} stepOnce
 * @property {() => void} reset
 * @property {() => void} screenshot
 * @property {() => unknown} record
 * @property {() => unknown} download
 * @property {(x: number, y: number, radius: number, multiplier: number) => unknown} brush
 * @property {(x: number, y: number) => unknown} ablate
 * @property {(ev: PointerEvent) => [number, number] | null} latticeAt
 */

// Substrate brushes: ξs multiplier painted on a disc of BRUSH_RADIUS sites.
/** @type {Record<string, number>} */
const BRUSHES = { soft: 0.1, stiff: 10, erase: 1 };
const BRUSH_RADIUS = 6;

export class Controls {
  /** @param {ControlActions} actions */
  constructor(actions) {
    this.actions = actions;
    this.tool = 'none';
    this.buildSliders();
    this.buildChoosers();
    this.wireButtons();
    // On the canvas's wrapper: a new renderer brings a new canvas.
    this.installBrush(/** @type {HTMLElement} */ ($('view').parentElement));
    window.addEventListener('keydown', (e) => this.onKey(e));
  }

  buildSliders() {
    const box = $('sliders');
    for (const name of SLIDERS) {
      const div = document.createElement('div');
      div.className = 'slider';
      const label = document.createElement('label');
      label.htmlFor = name;
      label.id = `${name}-label`;
      label.textContent = PARAMS[name].label;
      const out = document.createElement('output');
      out.id = `${name}-out`;
      out.htmlFor = name;
      const range = document.createElement('input');
      Object.assign(range, { id: name, type: 'range', min: 0, max: 1000 });
      range.setAttribute('aria-labelledby', label.id);
      range.addEventListener('input', () => this.actions.setParam(name, fromSlider(name, Number(range.value))));
      div.append(label, out, range);
      box.append(div);
    }
  }

  buildChoosers() {
    const preset = select('preset');
    for (const [key, p] of Object.entries(PRESETS)) preset.add(new Option(p.label, key));
    preset.add(new Option('Custom', 'custom'));
    preset.addEventListener('change', () => {
      if (preset.value in PRESETS) this.actions.applyPreset(/** @type {import('./state.js').PresetName} */ (preset.value));
    });
    const engine = select('engine-choice');
    for (const [key, label] of Object.entries(ENGINES)) engine.add(new Option(label, key));
    engine.addEventListener('change', () => this.actions.setEngine(/** @type {import('./worker.js').EngineChoice} */ (engine.value)));
    const fields = $('fields');
    for (const [kind, f] of FIELDS) {
      const l = document.createElement('label');
      const radio = document.createElement('input');
      Object.assign(radio, { type: 'radio', name: 'field', value: fieldName(kind) });
      radio.addEventListener('change', () => this.actions.setField(kind));
      l.append(radio, ` ${f.label}`);
      fields.append(l);
    }
    const seed = input('seed');
    seed.addEventListener('change', () => this.actions.setSeed(seed.value));
  }

  wireButtons() {
    $('play').addEventListener('click', () => this.actions.togglePlay());
    $('step').addEventListener('click', () => this.actions.stepOnce());
    $('reset').addEventListener('click', () => this.actions.reset());
    $('shot').addEventListener('click', () => this.actions.screenshot());
    $('record').addEventListener('click', () => this.actions.record());
    $('download').addEventListener('click', () => this.actions.download());
    for (const r of document.querySelectorAll('input[name=tool]')) {
      if (!(r instanceof HTMLInputElement)) continue;
      r.addEventListener('change', () => {
        this.tool = r.value;
        $('view').classList.toggle('tool', this.tool !== 'none');
      });
    }
  }

  // Shows `state` in every control.
  /** @param {import('./state.js').PageState} state @param {boolean} playing */
  refresh(state, playing) {
    for (const name of SLIDERS) {
      input(name).value = String(toSlider(name, state[name]));
      $(name).setAttribute('aria-valuetext', String(state[name]));
      $(`${name}-out`).textContent = String(state[name]);
    }
    input('seed').value = String(state.seed);
    select('preset').value = state.preset ?? 'custom';
    select('engine-choice').value = state.engine;
    for (const radio of document.querySelectorAll('input[name=field]')) {
      if (radio instanceof HTMLInputElement) radio.checked = radio.value === fieldName(state.field);
    }
    $('play').textContent = playing ? 'Pause' : 'Play';
    $('play').setAttribute('aria-pressed', String(!playing));
  }

  /** @param {boolean} on */
  showRecording(on) {
    $('record').textContent = on ? 'Stop' : 'Record';
    $('record').setAttribute('aria-pressed', String(on));
    $('record').classList.toggle('recording', on);
  }

  /** @param {KeyboardEvent} e */
  onKey(e) {
    if (e.target instanceof HTMLInputElement && e.target.type !== 'range' && e.target.type !== 'radio') return;
    if (e.target instanceof HTMLSelectElement || e.ctrlKey || e.metaKey || e.altKey) return;
    const k = e.key.toLowerCase();
    const kinds = [...FIELDS.keys()];
    if (k === ' ') $('play').click();
    else if (k === 's') $('step').click();
    else if (k === 'r') $('reset').click();
    else if (k === 'p') $('shot').click();
    else if (k === 'v') $('record').click();
    else if (k === 'd') $('download').click();
    // "What if?" (whatif.js), once it is offered.
    else if (k === 'w' && !$('whatif').hidden) $('whatif-off').click();
    else if (k === 'b') {
      const tools = /** @type {HTMLInputElement[]} */ ([...document.querySelectorAll('input[name=tool]')]);
      const i = tools.findIndex((t) => t.checked);
      tools[(i + 1) % tools.length].click();
    } else if (k >= '1' && k <= String(kinds.length)) this.actions.setField(kinds[Number(k) - 1]);
    else return;
    e.preventDefault();
  }

  /** @param {PointerEvent} ev */
  applyTool(ev) {
    const at = this.actions.latticeAt(ev);
    if (!at || this.tool === 'none') return;
    if (this.tool in BRUSHES) this.actions.brush(at[0], at[1], BRUSH_RADIUS, BRUSHES[this.tool]);
    else if (this.tool === 'ablate') this.actions.ablate(at[0], at[1]);
  }

  // Brushes paint while the pointer is down on the canvas; the laser removes one cell per press.
  /** @param {HTMLElement} wrap */
  installBrush(wrap) {
    let down = false;
    wrap.addEventListener('pointerdown', (e) => {
      if (!(e.target instanceof HTMLCanvasElement) || e.target.id !== 'view') return;
      down = true;
      e.target.setPointerCapture(e.pointerId);
      this.applyTool(e);
    });
    wrap.addEventListener('pointermove', (e) => {
      if (down && this.tool !== 'ablate') this.applyTool(e);
    });
    wrap.addEventListener('pointerup', () => {
      down = false;
    });
  }
}
