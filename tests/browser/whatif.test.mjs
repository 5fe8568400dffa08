// "What if?"'s words, in Node (www/js/whatif.js): the caption says what each replay showed, and
// for the experiment's finding over all nucleations it names the section of docs/figures.md
// that holds it (the numbers live there only), which must exist.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFile } from 'node:fs/promises';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

import { FINDINGS_SECTION, WHAT_IF_FINDING, whatIfCaption } from '../../www/js/whatif.js';

const ROOT = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../..');

test("What if?'s finding names a section of docs/figures.md that exists, and quotes no number", async () => {
  const figures = await readFile(path.join(ROOT, 'docs', 'figures.md'), 'utf8');
  assert(figures.split('\n').includes(`## ${FINDINGS_SECTION}`), `docs/figures.md has no section "## ${FINDINGS_SECTION}"`);
  assert(WHAT_IF_FINDING.includes(`docs/figures.md, section "${FINDINGS_SECTION}"`), WHAT_IF_FINDING);
  assert.doesNotMatch(WHAT_IF_FINDING, /\d/, 'the finding quotes a number that lives in docs/figures.md');
});

test('the caption says where the replay started, what it watched and what it saw', () => {
  const watch = { from: 13000, savedFingerprint: '0123456789abcdef', holeStep: 14260, holeX: 3, holeY: 4, until: 14760,
    radius: 8, tearStep: null };
  const watching = whatIfCaption({ ...watch, verdict: 'watching' }, 0, 0);
  assert.match(watching, /^Rewound to step 13,000, 1,260 steps before the hole was first counted at step 14,260, and replaying with activity off \(ζ = 0\): watching for a hole within R = 8 sites of where it opened, to step 14,760\./);
  const held = whatIfCaption({ ...watch, verdict: 'held' }, 0.25, 0.5);
  assert.match(held, /replayed with activity halved \(ζ = 0.25\): no hole opened within R = 8 sites of where it opened \(at step 14,260\) in the 1,760 steps watched/);
  const tore = whatIfCaption({ ...watch, verdict: 'tore', tearStep: 14300 }, 0, 0);
  assert.match(tore, /the hole opened again, at step 14,300, within R = 8 sites/);
  for (const c of [watching, held, tore]) assert(c.endsWith(` ${WHAT_IF_FINDING}`), `no finding: ${c}`);
});
