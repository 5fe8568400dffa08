// Property test of the page's URL parsing (www/js/state.js), in Node: whatever a query string
// holds, parseUrl never throws, every value it returns is finite and inside its range, the field
// is a real FieldKind, and the URL of a parsed state parses back to the same state without a
// notice. Cases come from a seeded generator, so a failure reproduces; 3,000 cases take well
// under a second. Needs www/pkg (scripts/serve.sh --build-only), as the page does.
import { test } from 'node:test';
import assert from 'node:assert/strict';

import { PARAMS, FIELDS, PRESETS, SIZES, ENGINES, MAX_THREADS, parseUrl, toUrl, fieldName, shippedStateFor, SHIPPED_STATES, DEFAULT_PRESET } from '../../www/js/state.js';

// mulberry32: a small, well-mixed 32-bit generator.
function rng(seed) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

const KEYS = [...Object.keys(PARAMS), 'preset', 'field', 'embed', 'paused', 'relax', 'size', 'engine', 'threads', 'tour', 'junk', ''];
const NASTY = ['', 'NaN', 'nan', 'Infinity', '-Infinity', '1e999', '-1e999', '.5', '5.', '0x10', '1e-400', ' 3 ',
  'abc', '%', '%%20', '∞', '🙂', '-0', '4294967296', '-1', '1,5', 'null', 'undefined', '[]', '{}', '&&', '=='];

function value(r) {
  const k = r();
  if (k < 0.3) return NASTY[Math.floor(r() * NASTY.length)];
  if (k < 0.6) return String((r() - 0.5) * 10 ** Math.floor(r() * 12 - 4));
  if (k < 0.7) return Object.keys(PRESETS)[Math.floor(r() * 5)] ?? 'x';
  if (k < 0.75) return Object.keys(SIZES)[Math.floor(r() * 3)] ?? 'x';
  if (k < 0.8) return Object.keys(ENGINES)[Math.floor(r() * 4)] ?? 'x';
  if (k < 0.9) return fieldName([...FIELDS.keys()][Math.floor(r() * FIELDS.size)]);
  return String.fromCharCode(...Array.from({ length: Math.floor(r() * 6) }, () => 32 + Math.floor(r() * 0x2fff)));
}

function query(r) {
  const parts = [];
  const n = Math.floor(r() * 8);
  for (let i = 0; i < n; i++) {
    const key = KEYS[Math.floor(r() * KEYS.length)];
    parts.push(r() < 0.1 ? key : `${encodeURIComponent(key)}=${encodeURIComponent(value(r))}`);
  }
  return (r() < 0.5 ? '?' : '') + parts.join(r() < 0.9 ? '&' : '&&');
}

function assertValid(state, search) {
  for (const [name, p] of Object.entries(PARAMS)) {
    const v = state[name];
    assert.ok(Number.isFinite(v), `${search}: ${name} = ${v} is not finite`);
    assert.ok(v >= p.min && v <= p.max, `${search}: ${name} = ${v} outside [${p.min}, ${p.max}]`);
    if (p.integer) assert.ok(Number.isInteger(v), `${search}: ${name} = ${v} is not an integer`);
  }
  assert.ok(FIELDS.has(state.field), `${search}: field ${state.field} is not a FieldKind`);
  assert.ok(state.preset === null || state.preset in PRESETS, `${search}: preset ${state.preset}`);
  assert.ok(state.size in SIZES, `${search}: size ${state.size}`);
  assert.ok(state.engine in ENGINES, `${search}: engine ${state.engine}`);
  assert.ok(state.threads === null || (Number.isInteger(state.threads) && state.threads >= 1 && state.threads <= MAX_THREADS),
    `${search}: threads ${state.threads}`);
}

test('any query string parses to a valid state, and its URL round-trips', () => {
  const r = rng(20261201);
  for (let i = 0; i < 3000; i++) {
    const search = query(r);
    let parsed;
    assert.doesNotThrow(() => { parsed = parseUrl(search); }, `parseUrl threw on ${JSON.stringify(search)}`);
    assertValid(parsed.state, JSON.stringify(search));
    const again = parseUrl(toUrl(parsed.state));
    assert.deepEqual(again.notices, [], `${JSON.stringify(search)} → ${toUrl(parsed.state)}: ${again.notices}`);
    const { preset, ...rest } = parsed.state;
    const { preset: preset2, ...rest2 } = again.state;
    assert.deepEqual(rest2, rest, `round trip of ${JSON.stringify(search)}`);
    assert.equal(preset2, preset);
  }
});

test('a preset with a parameter changed is no longer that preset', () => {
  const { state } = parseUrl('?preset=short-lived&chi=0.5');
  assert.equal(state.preset, null);
  assert.equal(state.chi, 0.5);
  assert.equal(state.zeta, PRESETS['short-lived'].zeta);
  assert.equal(parseUrl(toUrl(state)).state.chi, 0.5);
  // A bad value falls back to the preset's, which keeps it.
  const kept = parseUrl('?preset=short-lived&chi=abc').state;
  assert.equal(kept.preset, 'short-lived');
  assert.equal(kept.chi, PRESETS['short-lived'].chi);
});

test('bad values are named in a notice and replaced', () => {
  const { state, notices } = parseUrl('?zeta=abc&chi=1e999&gamma=NaN&seed=-3&field=nope&preset=nope');
  assert.equal(state.zeta, PRESETS[DEFAULT_PRESET].zeta);
  assert.equal(state.chi, PRESETS[DEFAULT_PRESET].chi);
  assert.equal(state.seed, PARAMS.seed.min);
  for (const name of ['zeta', 'chi', 'gamma', 'seed', 'field', 'preset']) {
    assert.ok(notices.some((n) => n.startsWith(`${name}=`)), `no notice names ${name}: ${notices}`);
  }
});

test("the paper's preset is the paper's tissue and the page's default, and its size survives a changed parameter", () => {
  const { state, notices } = parseUrl('?preset=paper');
  assert.deepEqual(notices, []);
  assert.equal(state.size, 'paper');
  assert.deepEqual(SIZES.paper, { box: 140, cells: 100, relaxSteps: 10000 });
  assert.deepEqual([state.chi, state.zeta, state.gamma], [0.001, 0.5, 0.06]);
  // The preset opens on its shipped state a short time before its first hole, which the page
  // labels with its seed and steps (tests/relaxed_state.rs holds the numbers to the core).
  const later = shippedStateFor(state);
  assert.match(later.file, /paper-seed1-step12000\.bin$/);
  assert.ok(later.step > SIZES.paper.relaxSteps && later.firstHole > later.step, JSON.stringify(later));
  assert.equal(DEFAULT_PRESET, 'paper');
  assert.deepEqual(parseUrl('').state, state);
  assert.equal(toUrl(parseUrl('').state), '?preset=paper&seed=1');
  // ?relax relaxes live; the same values without the preset start from the relaxation's end.
  assert.equal(shippedStateFor(parseUrl('?preset=paper&relax').state), null);
  assert.match(shippedStateFor(parseUrl('?zeta=0.5&chi=0.001&gamma=0.06').state).file, /relaxed-paper-seed1\.bin$/);
  // Another ζ keeps the size: the URL says size=paper, and the page does not silently shrink.
  const changed = parseUrl('?preset=paper&zeta=0.4').state;
  assert.equal(changed.preset, null);
  assert.equal(changed.size, 'paper');
  assert.equal(parseUrl(toUrl(changed)).state.size, 'paper');
  assert.match(shippedStateFor(changed).file, /relaxed-paper-seed1\.bin$/);
  // A reduced preset at the paper's size is no longer that preset; the reduced size is named.
  assert.equal(parseUrl('?preset=persistent&size=paper').state.preset, null);
  const reduced = parseUrl('?zeta=2&size=reduced').state;
  assert.match(toUrl(reduced), /size=reduced/);
  assert.equal(parseUrl(toUrl(reduced)).state.size, 'reduced');
  assert.match(shippedStateFor(parseUrl('?preset=persistent&seed=1').state).file, /relaxed-seed1\.bin$/);
  assert.equal(shippedStateFor(parseUrl('?preset=paper&seed=2').state), null);
  const bad = parseUrl('?size=huge');
  assert.equal(bad.state.size, 'paper');
  assert.ok(bad.notices.some((n) => n.startsWith('size=huge')), `${bad.notices}`);
  // Every shipped state is one of two kinds: the end of a size's relaxation, or a preset's later step.
  for (const r of SHIPPED_STATES) assert.ok((r.size in SIZES) !== (r.preset in PRESETS), JSON.stringify(r));
});

test('the engine is auto unless the URL chooses one, and a bad one is named', () => {
  assert.equal(parseUrl('').state.engine, 'auto');
  assert.doesNotMatch(toUrl(parseUrl('').state), /engine/);
  for (const e of ['cpu', 'gpu']) {
    const { state, notices } = parseUrl(`?engine=${e}`);
    assert.deepEqual(notices, []);
    assert.equal(state.engine, e);
    assert.equal(parseUrl(toUrl(state)).state.engine, e);
  }
  const bad = parseUrl('?engine=tpu');
  assert.equal(bad.state.engine, 'auto');
  assert.ok(bad.notices.some((n) => n.startsWith('engine=tpu')), `${bad.notices}`);
});
