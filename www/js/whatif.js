// "What if?": the question of `monolayer intervene` asked of the hole a visitor has just watched
// open. Do holes come from the collective motion of the cells, or from a tissue that thins
// first? Once a hole has opened, the page rewinds to a state it saved before it (worker.js and
// src/web/history.rs keep the live tissue's last states) and replays from there with activity
// off (ζ = 0) or halved; the caption says where it rewound to, whether the hole opened again
// within a cell's radius of where it did, and what the command-line experiment found over all
// nucleations (WHAT_IF_FINDING: where to read it). "Back to the live tissue" returns to the
// state the visitor left, with its ζ.

/** @typedef {import('./worker.js').Stats} Stats */
/** @typedef {import('./worker.js').Replay} Replay */

// Where the command-line experiment's finding over all nucleations of the paper's runs is read.
// Its numbers are not repeated here: they live in one place, docs/figures.md, and change as its
// runs do (tests/browser/whatif.test.mjs checks that the section exists). The page is served
// without the docs, so the caption names the file and its section rather than linking it.
export const FINDINGS_SECTION = 'Intervention';
export const WHAT_IF_FINDING = 'What the command-line experiment (monolayer intervene) found over all the nucleations '
  + `of the paper's runs: docs/figures.md, section "${FINDINGS_SECTION}".`;

// The replays offered: activity off (as the experiment's `activity-off` arm) and halved (its
// `activity-halved` arm): ζ of the saved state × factor.
export const CHOICES = {
  off: { factor: 0, button: 'whatif-off', says: 'activity off' },
  half: { factor: 0.5, button: 'whatif-half', says: 'activity halved' },
};

const n = (/** @type {number} */ v) => v.toLocaleString('en-US');

/**
 * What the caption says of a replay, given its watch and the ζ it runs at.
 * @param {Replay} r
 * @param {number} zeta
 * @param {number} factor
 */
export function whatIfCaption(r, zeta, factor) {
  const how = `${factor === 0 ? CHOICES.off.says : CHOICES.half.says} (ζ = ${zeta})`;
  const where = `within R = ${r.radius} sites of where it opened`;
  const watched = r.until - r.from;
  let said;
  if (r.verdict === 'tore') {
    said = `Rewound to step ${n(r.from)} and replayed with ${how}: the hole opened again, at step `
      + `${n(r.tearStep ?? 0)}, ${where} at step ${n(r.holeStep)}.`;
  } else if (r.verdict === 'held') {
    said = `Rewound to step ${n(r.from)} and replayed with ${how}: no hole opened ${where} (at step `
      + `${n(r.holeStep)}) in the ${n(watched)} steps watched, to step ${n(r.until)}.`;
  } else {
    said = `Rewound to step ${n(r.from)}, ${n(r.holeStep - r.from)} steps before the hole was first counted at step `
      + `${n(r.holeStep)}, and replaying with ${how}: watching for a hole ${where}, to step ${n(r.until)}.`;
  }
  return `${said} ${WHAT_IF_FINDING}`;
}

const $ = (/** @type {string} */ id) => /** @type {HTMLElement} */ (document.getElementById(id));

export class WhatIf {
  /**
   * @param {{ rewind(factor: number): Promise<unknown>, back(): Promise<unknown> }} actions
   *   rewind: the replay of the last hole with activity × factor; back: the live tissue again.
   */
  constructor(actions) {
    this.actions = actions;
    this.busy = false;
    /** The factor of the replay shown (null: the live tissue). */
    /** @type {number | null} */
    this.factor = null;
    for (const c of Object.values(CHOICES)) $(c.button).addEventListener('click', () => this.run(() => this.actions.rewind(c.factor)));
    $('whatif-back').addEventListener('click', () => this.run(() => this.actions.back()));
  }

  /** @param {() => Promise<unknown>} action */
  async run(action) {
    if (this.busy) return;
    this.busy = true;
    try {
      await action();
    } finally {
      this.busy = false;
    }
  }

  // Each frame's stats: the control shows once the live tissue has a hole to rewind before (or
  // while a replay runs), with its caption.
  /** @param {Stats} s */
  update(s) {
    const box = $('whatif');
    const shown = s.rewind !== null || s.replay !== null;
    if (box.hidden === shown) box.hidden = !shown;
    if (!shown) return;
    $('whatif-back').hidden = s.replay === null;
    let text;
    if (s.replay) text = whatIfCaption(s.replay, s.zeta, this.factor ?? 0);
    else if (s.rewind) {
      text = `A hole opened at step ${n(s.rewind.holeStep)}. What if the cells had stopped pulling? Rewind to step `
        + `${n(s.rewind.from)} and replay it with activity off or halved.`;
    } else text = '';
    const caption = $('whatif-caption');
    if (caption.textContent !== text) caption.textContent = text;
  }
}
