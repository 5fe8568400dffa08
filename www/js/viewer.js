// A run's frames in the page: a run directory or its run.json and frame_*.npz, dropped on the
// page or picked with the file dialogs, are read here and in the worker (nothing is uploaded),
// then played as a movie with the same fields and overlays as the live tissue. The worker checks
// each frame on its own: a bad one is listed, naming the file and what is wrong, and skipped.

const $ = (/** @type {string} */ id) => /** @type {HTMLElement} */ (document.getElementById(id));
const sleep = (/** @type {number} */ ms) => new Promise((r) => setTimeout(r, ms));

/**
 * What opening a run answers (worker.js, openRun).
 * @typedef {{ frames: { name: string, step: number }[], errors: string[], seed: number, runVersion: string,
 *   hasRecord: boolean }} Opened
 */

// Every file of a drop, directories walked (webkitGetAsEntry), else the plain file list.
/** @param {DataTransfer} dt */
async function droppedFiles(dt) {
  const entries = /** @type {FileSystemEntry[]} */ ([...(dt.items ?? [])].map((i) => i.webkitGetAsEntry?.()).filter(Boolean));
  if (!entries.length) return [...dt.files];
  /** @type {File[]} */
  const files = [];
  /** @param {FileSystemEntry} entry */
  const walk = async (entry) => {
    if (entry instanceof FileSystemFileEntry || entry.isFile) {
      const f = /** @type {FileSystemFileEntry} */ (entry);
      files.push(await new Promise((ok, no) => f.file(ok, no)));
    } else if (entry.isDirectory) {
      const reader = /** @type {FileSystemDirectoryEntry} */ (entry).createReader();
      for (;;) {
        /** @type {FileSystemEntry[]} */
        const batch = await new Promise((ok, no) => reader.readEntries(ok, no));
        if (!batch.length) break;
        for (const e of batch) await walk(e);
      }
    }
  };
  for (const e of entries) await walk(e);
  return files;
}

export class Viewer {
  /**
   * @param {{ open(files: File[]): Promise<Opened | { error: string, errors: string[] }>,
   *   show(index: number): Promise<{ index: number, step: number, error?: string }>, opened(r: Opened): void,
   *   frameShown(): void }} hooks open and show: the worker's calls; opened(result) when frames replace the live
   *   tissue; frameShown()
   */
  constructor(hooks) {
    this.hooks = hooks;
    this.active = false;
    this.seed = 0;
    /** @type {{ name: string, step: number }[]} */
    this.frames = [];
    this.index = 0;
    this.playing = false;
    this.generation = 0; // a newer play loop ends older ones
    this.fps = 4; // frames per second while playing
    // What the tests read: the frames opened, the errors, and every frame shown.
    /** @type {{ frames: { name: string, step: number }[], errors: string[], shown: number[], opened: number }} */
    this.state = { frames: [], errors: [], shown: [], opened: 0 };
    for (const id of ['open-files', 'open-dir']) {
      const picker = /** @type {HTMLInputElement} */ ($(id));
      picker.addEventListener('change', () => this.open([...(picker.files ?? [])]));
    }
    $('player-play').addEventListener('click', () => this.toggle());
    const slider = /** @type {HTMLInputElement} */ ($('player-slider'));
    slider.addEventListener('input', () => {
      this.setPlaying(false);
      this.show(Number(slider.value));
    });
    window.addEventListener('dragover', (e) => {
      e.preventDefault();
      document.body.classList.add('dropping');
    });
    window.addEventListener('dragleave', () => document.body.classList.remove('dropping'));
    window.addEventListener('drop', (e) => {
      e.preventDefault();
      document.body.classList.remove('dropping');
      if (e.dataTransfer) droppedFiles(e.dataTransfer).then((files) => this.open(files));
    });
  }

  /** @param {File[]} files */
  async open(files) {
    if (!files.length) return;
    this.setPlaying(false);
    let r;
    try {
      r = await this.hooks.open(files);
    } catch (e) {
      r = { error: String(/** @type {Error} */ (e).message ?? e), errors: [] };
    }
    if ('error' in r) {
      this.errors([`Could not open the run: ${r.error}`, ...r.errors]);
      return;
    }
    this.errors(r.errors);
    this.active = true;
    this.seed = r.seed;
    this.frames = r.frames;
    this.index = 0;
    this.state.frames = r.frames;
    this.state.shown = [r.frames[0].step];
    this.state.opened++;
    const slider = /** @type {HTMLInputElement} */ ($('player-slider'));
    slider.max = String(r.frames.length - 1);
    slider.value = '0';
    $('player').hidden = false;
    this.label();
    this.hooks.opened(r);
  }

  // Back to the live simulation (Reset).
  close() {
    this.setPlaying(false);
    this.active = false;
    $('player').hidden = true;
  }

  /** @param {number} index */
  async show(index) {
    const r = await this.hooks.show(index);
    if (r.error) this.errors([r.error], true);
    else {
      this.index = index;
      this.state.shown.push(r.step);
    }
    /** @type {HTMLInputElement} */ ($('player-slider')).value = String(this.index);
    this.label();
    this.hooks.frameShown();
  }

  toggle() {
    this.setPlaying(!this.playing);
  }

  /** @param {boolean} on */
  setPlaying(on) {
    this.playing = on && this.frames.length > 0;
    $('player-play').textContent = this.playing ? 'Pause' : 'Play';
    $('player-play').setAttribute('aria-pressed', String(this.playing));
    if (this.playing) this.play(++this.generation);
  }

  // Shows the frames one after the other (from the start after the last), each once the
  // worker has shown the one before: as fast as it can, up to `fps`.
  /** @param {number} generation */
  async play(generation) {
    while (this.playing && generation === this.generation) {
      const t0 = performance.now();
      await this.show((this.index + 1) % this.frames.length);
      await sleep(Math.max(0, 1000 / this.fps - (performance.now() - t0)));
    }
  }

  label() {
    const f = this.frames[this.index];
    if (f) $('player-label').textContent = `frame ${this.index + 1} of ${this.frames.length}: ${f.name} (step ${f.step.toLocaleString('en')})`;
  }

  /** @param {string[]} lines */
  errors(lines, add = false) {
    this.state.errors = add ? [...this.state.errors, ...lines] : lines;
    const list = $('player-errors');
    list.replaceChildren(...this.state.errors.map((l) => Object.assign(document.createElement('li'), { textContent: l })));
    list.hidden = this.state.errors.length === 0;
  }
}
