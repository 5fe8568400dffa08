// What the page reads out under the canvas: steps, time, holes, void area, packing, speed, the
// colour bar's labels and the void-area chart. Times are in the core's units, shown in seconds
// with the core's seconds per time unit.

import { FIELDS } from './state.js';
import { HoleChart } from './chart.js';

const $ = (/** @type {string} */ id) => /** @type {HTMLElement} */ (document.getElementById(id));

// Writes only a changed text: every write makes the browser lay out and paint the page again,
// work that a software GPU does on the CPU the simulation's worker needs.
/** @param {string} id @param {string} text @param {string} [title] */
function put(id, text, title) {
  const e = $(id);
  if (e.textContent !== text) e.textContent = text;
  if (title !== undefined && e.title !== title) e.title = title;
}

/** @param {number} s */
export function formatSeconds(s) {
  if (s < 120) return `${s.toFixed(0)} s`;
  if (s < 7200) return `${(s / 60).toFixed(1)} min`;
  return `${(s / 3600).toFixed(2)} h`;
}

export class Readouts {
  constructor() {
    this.chart = new HoleChart(/** @type {HTMLCanvasElement} */ ($('chart')));
    this.frames = 0; // points added to the chart (it is redrawn every tenth)
  }

  // A new tissue: the chart starts over.
  /** @param {number} secondsPerUnit */
  reset(secondsPerUnit) {
    this.chart.secondsPerUnit = secondsPerUnit;
    this.chart.clear();
    $('time-unit').textContent = `one time unit ≈ ${secondsPerUnit} s`;
  }

  // The latest stats of the simulation (worker.js) and the loop's rates.
  /**
   * @param {import('./worker.js').Stats} stats
   * @param {import('./loop.js').FrameLoop} loop
   * @param {number} spf
   * @param {boolean} playing
   */
  update(stats, loop, spf, playing) {
    const { step, holes, area, time: t, active, packing } = stats;
    const { sps, fps } = loop.rate;
    put('r-step', step.toLocaleString('en'));
    put('r-time', active
      ? `${t.toFixed(0)} (${formatSeconds(t * stats.timeUnitSeconds)})`
      : `relaxing ${Math.round((100 * step) / stats.relaxSteps)} %`);
    // Before activity the tissue is still closing up: gaps then are not holes.
    put('r-holes', active ? String(holes) : `(${holes} gaps)`);
    put('r-area', `${area} µm²`);
    put('r-packing', `${(100 * packing).toFixed(1)} %`);
    put('r-sps', sps.toFixed(0));
    put('r-spf', playing && fps > 0 ? `${Math.round(sps / fps)} / ${spf}` : `– / ${spf}`);
    put('r-fps', fps.toFixed(0), `drawn at ${Math.round(loop.renderScale * 100)} % resolution`);
    if (active && this.chart.push(t, area) && ++this.frames % 10 === 0) this.chart.draw();
  }

  // The colour bar's labels, under the bar the renderer drew (its layout, in device pixels).
  /**
   * @param {import('../pkg/monolayer.js').FieldKind} field
   * @param {ArrayLike<number>} range
   * @param {{ x: number, side: number }} layout
   * @param {number} dpr
   */
  colourBar(field, range, layout, dpr) {
    const labels = $('colorbar-labels');
    const { x, side } = layout;
    const [lo, hi] = [range[0], range[1]];
    labels.hidden = false;
    labels.style.width = `${side / dpr}px`;
    labels.style.marginLeft = `${x / dpr}px`;
    const f = /** @type {{ label: string, units: string }} */ (FIELDS.get(field));
    $('cb-min').textContent = Math.abs(lo) < 0.01 && lo !== 0 ? lo.toExponential(1) : lo.toFixed(2);
    $('cb-max').textContent = hi.toPrecision(2) + f.units;
    $('cb-name').textContent = f.label;
  }

  hideColourBar() {
    $('colorbar-labels').hidden = true;
  }
}
