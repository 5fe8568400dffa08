// The guided tour (`?tour`, or the Tour button): the paper's tissue from its shipped state, with
// a caption for each thing worth seeing, shown when it happens in the simulation, not after a
// time: the tissue stepping on, a spiral core in the flow, the first hole (where the tour
// pauses). Every caption's words are here, in TOUR, and nowhere else.
//
// The tour plays at a lowered speed limit (TOUR_SPF, unless the link sets `spf`), so that a
// caption stays long enough to read at any machine's speed. With prefers-reduced-motion it does
// not start on its own: the tissue waits, paused, for the Play button. The captions are in a
// live region (read out by screen readers as they change); Next, Play and Close are buttons,
// and Escape closes the tour.

// A caption's `after`: the active steps since the last caption shown before it may show;
// `cores`: also a spiral core drawn in the flow; `hole`: the first hole open. `field`: the view
// it switches to; `pause`: the tour stops the tissue on it; `next`: it comes when the visitor
// presses Next on the caption before.
/**
 * @typedef {{ id: string, title: string, field: string, text: string, after?: number, cores?: boolean,
 *   hole?: boolean, pause?: boolean, next?: boolean }} Caption
 * @typedef {import('./worker.js').Stats} Stats
 */
/** @type {Caption[]} */
export const TOUR = [
  {
    id: 'cells', title: 'The cells', field: 'tissue', after: 0,
    text: 'This is a sheet of 100 cells, as in a lab dish, seen from above. Each colour is one cell; the white line '
      + 'through a cell is its long axis, longer the more the cell is stretched.',
  },
  {
    id: 'activity', title: 'Activity and friction', field: 'tissue', after: 400,
    text: 'Every cell pulls along its long axis: that is its activity (ζ = 0.5 here). The cells slide on a substrate '
      + 'with very little friction (χ = 0.001), so a push travels far through the sheet.',
  },
  {
    id: 'flows', title: 'The flows', field: 'speed', after: 400,
    text: 'Now the colours show how fast the tissue moves, and the arrows where. Whole groups of cells swirl together, '
      + 'over distances of many cells.',
  },
  {
    id: 'strain', title: 'The strain rate', field: 'strainrate', after: 400, cores: true,
    text: 'A green ringed cross marks a spiral core, where the flow swirls outwards. The colours now show the strain '
      + 'rate: red where the tissue is being pulled apart, blue where it is squeezed.',
  },
  {
    id: 'forecast', title: 'Where the tear will come', field: 'forecast', after: 400,
    text: 'The shading is a forecast, made from the flow and the thinning of the tissue: the brighter a place, the '
      + 'likelier a hole opens there within the next 3,000 steps. Watch the brightest place.',
  },
  {
    id: 'hole', title: 'A hole opens', field: 'tissue', hole: true, pause: true,
    text: 'The sheet has torn: the black region is a hole, where no cell covers the substrate. The tour has paused on '
      + 'it. Press Next to continue.',
  },
  {
    id: 'verdict', title: 'What the paper claims, and what this model found', field: 'tissue', next: true,
    // The verdict is docs/figures.md's "the argument" row (a browser test holds them together).
    text: 'The paper argues that holes open from the collective motion of the cells, not from a tissue that thins '
      + 'first. What this model found — by correlation not shown: a forecast from the motion beats thinning alone on '
      + 'held-out seeds only one frame ahead (AUC +0.022 ± 0.012), not 3–5 frames ahead nor on covered sites; by '
      + 'intervention supported: activity switched off 1–5 frames before prevents every tear the replicas make, and '
      + 'the thinned site refills. "What if?" asks it of the hole you just watched: it replays it with the motion '
      + 'switched off.',
  },
];

// The speed limit while touring (steps per 1/30 s: at most 60 steps/s), unless the link sets one.
export const TOUR_SPF = 2;

const $ = (/** @type {string} */ id) => /** @type {HTMLElement} */ (document.getElementById(id));

export class Tour {
  /**
   * @param {{ begin(playing: boolean): Promise<Stats>, setField(name: string): void, setPlaying(on: boolean): void,
   *   end(): void }} actions begin(playing): the paper's tissue from its shipped state at the tour's speed limit,
   *   a Promise of its first stats
   */
  constructor(actions) {
    this.actions = actions;
    this.active = false;
    this.waiting = false; // with reduced motion, for the Play button
    this.index = -1;
    this.since = 0; // the step the last caption was shown at
    this.coresSeen = false;
    /** @type {(Stats & { cores: number }) | undefined} */
    this.last = undefined;
    /** @type {{ id: string, step: number | null, holes: number | null, cores: number | null, coresSeen: boolean }[]} */
    this.log = []; // each caption shown
    $('tour-next').addEventListener('click', () => this.next());
    $('tour-play').addEventListener('click', () => this.play());
    $('tour-close').addEventListener('click', () => this.close());
    $('tour').addEventListener('keydown', (e) => {
      if (e.key === 'Escape') this.close();
    });
  }

  static reducedMotion() {
    return window.matchMedia?.('(prefers-reduced-motion: reduce)').matches ?? false;
  }

  async start() {
    this.active = true;
    this.index = -1;
    this.log = [];
    this.waiting = Tour.reducedMotion();
    $('tour').hidden = false;
    const first = await this.actions.begin(!this.waiting);
    this.coresSeen = false;
    this.show(0, { ...first, cores: 0 });
    (this.waiting ? $('tour-play') : $('tour-caption')).focus();
  }

  // The visitor's Play: the tissue runs (with reduced motion, the tour's start).
  play() {
    this.waiting = false;
    $('tour-play').hidden = true;
    this.actions.setPlaying(true);
  }

  // The visitor's Next, shown on the hole's caption (on to the last, the tissue running again)
  // and on the last (the tour's end).
  next() {
    if (this.index === TOUR.length - 1) return this.close();
    if (TOUR[this.index]?.pause) {
      this.show(this.index + 1, this.last);
      this.actions.setPlaying(true);
    }
  }

  close() {
    if (!this.active) return;
    this.active = false;
    $('tour').hidden = true;
    this.actions.end();
  }

  // Each frame's stats (and the spiral cores it drew): shows the next caption whose event came.
  /** @param {Stats} stats @param {number} cores */
  update(stats, cores) {
    if (!this.active || this.index < 0 || !stats) return;
    this.last = { ...stats, cores };
    if (cores > 0 && TOUR[this.index].field === 'speed') this.coresSeen = true;
    // The first hole overrides whatever is still to come before it.
    const hole = TOUR.findIndex((c) => c.hole);
    if (this.index < hole && stats.active && stats.holes > 0) return this.show(hole, this.last);
    const c = TOUR[this.index + 1];
    if (!c || c.hole || c.next) return;
    if (stats.step - this.since >= (c.after ?? 0) && (!c.cores || this.coresSeen || cores > 0)) this.show(this.index + 1, this.last);
  }

  /** @param {number} index @param {{ step: number, holes: number, cores: number } | undefined} at */
  show(index, at) {
    const c = TOUR[index];
    this.index = index;
    this.since = at?.step ?? 0;
    this.log.push({ id: c.id, step: at?.step ?? null, holes: at?.holes ?? null, cores: at?.cores ?? null, coresSeen: this.coresSeen });
    $('tour-count').textContent = `${index + 1} of ${TOUR.length}`;
    $('tour-title').textContent = c.title;
    $('tour-caption').textContent = c.text;
    $('tour-next').hidden = !(c.pause || index === TOUR.length - 1);
    $('tour-next').textContent = index === TOUR.length - 1 ? 'End the tour' : 'Next';
    $('tour-play').hidden = !this.waiting;
    this.actions.setField(c.field);
    if (c.pause) {
      this.actions.setPlaying(false);
      $('tour-next').focus();
    }
  }
}
