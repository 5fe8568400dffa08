// The controls: sliders made from the parameter table, the preset and field choosers, the seed,
// the buttons, the keyboard shortcuts and the brushes on the canvas. They only call `actions`
// (main.js), which change the core, the state and the URL.

import { PARAMS, SLIDERS, FIELDS, PRESETS, ENGINES, fieldName, toSlider, fromSlider } from './state.js';

const $ = (id) => document.getElementById(id);

// Substrate brushes: ξs multiplier painted on a disc of BRUSH_RADIUS sites.
const BRUSHES = { soft: 0.1, stiff: 10, erase: 1 };
const BRUSH_RADIUS = 6;

export class Controls {
  // actions: setParam(name, v), applyPreset(name), setField(kind), setSeed(v), togglePlay(),
  // stepOnce(), reset(), screenshot(), record(), download(), brush(x, y, multiplier), ablate(x, y), latticeAt(event).
  constructor(actions) {
    this.actions = actions;
    this.tool = 'none';
    this.buildSliders();
    this.buildChoosers();
    this.wireButtons();
    // On the canvas's wrapper: a new renderer brings a new canvas.
    this.installBrush($('view').parentElement);
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
      const input = document.createElement('input');
      Object.assign(input, { id: name, type: 'range', min: 0, max: 1000 });
      input.setAttribute('aria-labelledby', label.id);
      input.addEventListener('input', () => this.actions.setParam(name, fromSlider(name, Number(input.value))));
      div.append(label, out, input);
      box.append(div);
    }
  }

  buildChoosers() {
    const preset = $('preset');
    for (const [key, p] of Object.entries(PRESETS)) preset.add(new Option(p.label, key));
    preset.add(new Option('Custom', 'custom'));
    preset.addEventListener('change', (e) => {
      if (e.target.value in PRESETS) this.actions.applyPreset(e.target.value);
    });
    const engine = $('engine-choice');
    for (const [key, label] of Object.entries(ENGINES)) engine.add(new Option(label, key));
    engine.addEventListener('change', (e) => this.actions.setEngine(e.target.value));
    const fields = $('fields');
    for (const [kind, f] of FIELDS) {
      const l = document.createElement('label');
      const input = document.createElement('input');
      Object.assign(input, { type: 'radio', name: 'field', value: fieldName(kind) });
      input.addEventListener('change', () => this.actions.setField(kind));
      l.append(input, ` ${f.label}`);
      fields.append(l);
    }
    $('seed').addEventListener('change', (e) => this.actions.setSeed(e.target.value));
  }

  wireButtons() {
    $('play').addEventListener('click', () => this.actions.togglePlay());
    $('step').addEventListener('click', () => this.actions.stepOnce());
    $('reset').addEventListener('click', () => this.actions.reset());
    $('shot').addEventListener('click', () => this.actions.screenshot());
    $('record').addEventListener('click', () => this.actions.record());
    $('download').addEventListener('click', () => this.actions.download());
    for (const r of document.querySelectorAll('input[name=tool]')) {
      r.addEventListener('change', () => {
        this.tool = r.value;
        $('view').classList.toggle('tool', this.tool !== 'none');
      });
    }
  }

  // Shows `state` in every control.
  refresh(state, playing) {
    for (const name of SLIDERS) {
      $(name).value = toSlider(name, state[name]);
      $(name).setAttribute('aria-valuetext', String(state[name]));
      $(`${name}-out`).textContent = String(state[name]);
    }
    $('seed').value = String(state.seed);
    $('preset').value = state.preset ?? 'custom';
    $('engine-choice').value = state.engine;
    for (const input of document.querySelectorAll('input[name=field]')) {
      input.checked = input.value === fieldName(state.field);
    }
    $('play').textContent = playing ? 'Pause' : 'Play';
    $('play').setAttribute('aria-pressed', String(!playing));
  }

  showRecording(on) {
    $('record').textContent = on ? 'Stop' : 'Record';
    $('record').setAttribute('aria-pressed', String(on));
    $('record').classList.toggle('recording', on);
  }

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
    else if (k === 'b') {
      const tools = [...document.querySelectorAll('input[name=tool]')];
      const i = tools.findIndex((t) => t.checked);
      tools[(i + 1) % tools.length].click();
    } else if (k >= '1' && k <= String(kinds.length)) this.actions.setField(kinds[Number(k) - 1]);
    else return;
    e.preventDefault();
  }

  applyTool(ev) {
    const at = this.actions.latticeAt(ev);
    if (!at || this.tool === 'none') return;
    if (this.tool in BRUSHES) this.actions.brush(at[0], at[1], BRUSH_RADIUS, BRUSHES[this.tool]);
    else if (this.tool === 'ablate') this.actions.ablate(at[0], at[1]);
  }

  // Brushes paint while the pointer is down on the canvas; the laser removes one cell per press.
  installBrush(wrap) {
    let down = false;
    wrap.addEventListener('pointerdown', (e) => {
      if (e.target.id !== 'view') return;
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
