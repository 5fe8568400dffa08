// What the page reads out under the canvas: steps, time, holes, void area, packing, speed, the
// colour bar's labels and the void-area chart. Times are in the core's units, shown in seconds
// with the core's seconds per time unit.

import { FIELDS } from './state.js';
import { HoleChart } from './chart.js';

const $ = (id) => document.getElementById(id);

export function formatSeconds(s) {
  if (s < 120) return `${s.toFixed(0)} s`;
  if (s < 7200) return `${(s / 60).toFixed(1)} min`;
  return `${(s / 3600).toFixed(2)} h`;
}

export class Readouts {
  constructor() {
    this.chart = new HoleChart($('chart'));
    this.frames = 0;
  }

  // A new tissue: the chart starts over.
  reset(secondsPerUnit) {
    this.chart.secondsPerUnit = secondsPerUnit;
    this.chart.clear();
    $('time-unit').textContent = `one time unit ≈ ${secondsPerUnit} s`;
  }

  // The latest stats of the simulation (worker.js) and the loop's rates.
  update(stats, loop, spf, playing) {
    const { step, holes, area, time: t, active, packing } = stats;
    const { sps, fps } = loop.rate;
    $('r-step').textContent = step.toLocaleString('en');
    $('r-time').textContent = active
      ? `${t.toFixed(0)} (${formatSeconds(t * stats.timeUnitSeconds)})`
      : `relaxing ${Math.round((100 * step) / stats.relaxSteps)} %`;
    // Before activity the tissue is still closing up: gaps then are not holes.
    $('r-holes').textContent = active ? String(holes) : `(${holes} gaps)`;
    $('r-area').textContent = `${area} µm²`;
    $('r-packing').textContent = `${(100 * packing).toFixed(1)} %`;
    $('r-sps').textContent = sps.toFixed(0);
    $('r-spf').textContent = playing && fps > 0 ? `${Math.round(sps / fps)} / ${spf}` : `– / ${spf}`;
    $('r-fps').textContent = fps.toFixed(0);
    $('r-fps').title = `drawn at ${Math.round(loop.renderScale * 100)} % resolution`;
    if (active) this.chart.push(t, area);
    if (++this.frames % 10 === 0) this.chart.draw();
  }

  // The colour bar's labels, under the bar the renderer drew (its layout, in device pixels).
  colourBar(field, range, layout, dpr) {
    const labels = $('colorbar-labels');
    const [x, , side] = layout;
    const [lo, hi] = range;
    labels.hidden = false;
    labels.style.width = `${side / dpr}px`;
    labels.style.marginLeft = `${x / dpr}px`;
    const f = FIELDS.get(field);
    $('cb-min').textContent = Math.abs(lo) < 0.01 && lo !== 0 ? lo.toExponential(1) : lo.toFixed(2);
    $('cb-max').textContent = hi.toPrecision(2) + f.units;
    $('cb-name').textContent = f.label;
  }

  hideColourBar() {
    $('colorbar-labels').hidden = true;
  }
}
