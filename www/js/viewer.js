// A run's frames in the page: a run directory or its run.json and frame_*.npz, dropped on the
// page or picked with the file dialogs, are read here and in the worker (nothing is uploaded),
// then played as a movie with the same fields and overlays as the live tissue. The worker checks
// each frame on its own: a bad one is listed, naming the file and what is wrong, and skipped.

const $ = (id) => document.getElementById(id);
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// Every file of a drop, directories walked (webkitGetAsEntry), else the plain file list.
async function droppedFiles(dt) {
  const entries = [...(dt.items ?? [])].map((i) => i.webkitGetAsEntry?.()).filter(Boolean);
  if (!entries.length) return [...dt.files];
  const files = [];
  const walk = async (entry) => {
    if (entry.isFile) {
      files.push(await new Promise((ok, no) => entry.file(ok, no)));
    } else if (entry.isDirectory) {
      const reader = entry.createReader();
      for (;;) {
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
  // hooks: call(method, ...args) on the worker; opened(result) when frames replace the live
  // tissue; frameShown(); report(lines) for messages.
  constructor(hooks) {
    this.hooks = hooks;
    this.active = false;
    this.frames = [];
    this.index = 0;
    this.playing = false;
    this.generation = 0; // a newer play loop ends older ones
    this.fps = 4; // frames per second while playing
    // What the tests read: the frames opened, the errors, and every frame shown.
    this.state = { frames: [], errors: [], shown: [], opened: 0 };
    $('open-files').addEventListener('change', (e) => this.open([...e.target.files]));
    $('open-dir').addEventListener('change', (e) => this.open([...e.target.files]));
    $('player-play').addEventListener('click', () => this.toggle());
    $('player-slider').addEventListener('input', (e) => {
      this.setPlaying(false);
      this.show(Number(e.target.value));
    });
    window.addEventListener('dragover', (e) => {
      e.preventDefault();
      document.body.classList.add('dropping');
    });
    window.addEventListener('dragleave', () => document.body.classList.remove('dropping'));
    window.addEventListener('drop', (e) => {
      e.preventDefault();
      document.body.classList.remove('dropping');
      droppedFiles(e.dataTransfer).then((files) => this.open(files));
    });
  }

  async open(files) {
    if (!files.length) return;
    this.setPlaying(false);
    let r;
    try {
      r = await this.hooks.call('open', files);
    } catch (e) {
      r = { error: String(e.message ?? e), errors: [] };
    }
    if (r.error) {
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
    const slider = $('player-slider');
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

  async show(index) {
    const r = await this.hooks.call('show', index);
    if (r.error) this.errors([r.error], true);
    else {
      this.index = index;
      this.state.shown.push(r.step);
    }
    $('player-slider').value = String(this.index);
    this.label();
    this.hooks.frameShown();
  }

  toggle() {
    this.setPlaying(!this.playing);
  }

  setPlaying(on) {
    this.playing = on && this.frames.length > 0;
    $('player-play').textContent = this.playing ? 'Pause' : 'Play';
    $('player-play').setAttribute('aria-pressed', String(this.playing));
    if (this.playing) this.play(++this.generation);
  }

  // Shows the frames one after the other (from the start after the last), each once the
  // worker has shown the one before: as fast as it can, up to `fps`.
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

  errors(lines, add = false) {
    this.state.errors = add ? [...this.state.errors, ...lines] : lines;
    const list = $('player-errors');
    list.replaceChildren(...this.state.errors.map((l) => Object.assign(document.createElement('li'), { textContent: l })));
    list.hidden = this.state.errors.length === 0;
  }
}
