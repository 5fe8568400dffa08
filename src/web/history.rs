//! The page's "What if?": the question of `monolayer intervene` (does the tissue still tear when
//! the motion is switched off?) asked of the hole a visitor has just watched open.
//!
//! The live tissue keeps a short [`History`]: its state every [`SAVE_EVERY`] active steps, the
//! last [`KEPT`], each in the snapshot codec of the page's shipped states
//! ([`crate::formats::snapshot`]), with the fingerprint it had and the hole tracker as it stood.
//! [`History::rewind_point`] is the latest state at least [`LEAD`] steps before a hole's first
//! row (the command line branches 1–5 frames of 1,000 steps before a nucleation); a replay from
//! it is watched ([`Watch`]) for as many steps as the original took to the hole plus [`MARGIN`],
//! for a hole that nucleates within R of where the original opened, as the experiment's
//! `TearWatch` counts a tear. Plain Rust, tested natively; `sim::WebSim` is its binding.

use std::collections::VecDeque;

use crate::analysis::{periodic_distance, HoleTracker};
use crate::formats::snapshot;
use crate::model::{Monolayer, Params, SimError, State};

/// Active steps between two saved states: a multiple of the readouts' rows
/// (`ROW_EVERY` of the readouts), so that the GPU engine hands over every state to be saved.
pub const SAVE_EVERY: u64 = 500;
/// Saved states kept: the oldest is dropped for a new one (what they weigh:
/// docs/performance.md, the saved states of "What if?").
pub const KEPT: usize = 10;
/// The rewind's state is at least this many steps before the hole's first row: one frame of
/// the command-line runs, the shortest lead of `monolayer intervene`.
pub const LEAD: u64 = 1_000;
/// Steps a replay is watched past the step the original hole was first counted at.
pub const MARGIN: u64 = 500;

/// Where and when a hole nucleated: its first row of readouts and the centroid it had there
/// (the tracker's `history[0]`, as the experiment takes a tear's site).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Nucleation {
    pub step: u64,
    pub x: f64,
    pub y: f64,
}

/// One saved state of the live tissue.
#[derive(Clone, Debug)]
pub struct Saved {
    pub step: u64,
    /// The state in the snapshot codec, under `key`.
    bytes: Vec<u8>,
    key: u64,
    pub params: Params,
    pub seed: u64,
    /// The cells' colour keys (a removed cell's is gone).
    pub keys: Vec<u32>,
    /// The core's fingerprint of the state when it was saved.
    pub fingerprint: u64,
    /// The hole tracker as it stood after this state's row, so that a replay does not count a
    /// hole that was already open as a new one.
    pub tracker: Option<HoleTracker>,
}

impl Saved {
    /// The state of `m` now (past its relaxation), with the page's colour keys and tracker.
    pub fn of(m: &Monolayer, keys: &[u32], tracker: Option<&HoleTracker>) -> Saved {
        let (params, seed, step) = (m.params().clone(), m.seed(), m.step_count());
        let key = snapshot::key_at(&params, seed, step).unwrap_or_else(|| snapshot::relaxation_key(&params, seed));
        Saved {
            step,
            bytes: snapshot::encode(&m.state(), key),
            key,
            params,
            seed,
            keys: keys.to_vec(),
            fingerprint: m.fingerprint(),
            tracker: tracker.cloned(),
        }
    }

    /// The saved state, decoded.
    pub fn state(&self) -> Result<State, SimError> {
        snapshot::decode(&self.bytes, self.key, self.params.box_size)
    }

    /// The tissue again, bit for bit as it was saved (its fingerprint is [`Saved::fingerprint`]).
    pub fn monolayer(&self) -> Result<Monolayer, SimError> {
        Monolayer::from_state(self.params.clone(), self.seed, self.state()?)
    }

    /// Bytes the saved state takes.
    pub fn size(&self) -> usize {
        self.bytes.len()
    }
}

/// The last [`KEPT`] saved states of the live tissue, oldest first.
#[derive(Clone, Debug, Default)]
pub struct History {
    saved: VecDeque<Saved>,
}

impl History {
    /// Whether the state of `m` is due to be saved: active, a multiple of [`SAVE_EVERY`] steps
    /// since activity started, and not saved yet.
    pub fn due(&self, m: &Monolayer) -> bool {
        let (step, relax) = (m.step_count(), m.params().relax_steps);
        step >= relax && (step - relax) % SAVE_EVERY == 0 && self.saved.back().is_none_or(|s| s.step != step)
    }

    /// Saves the state of `m` if it is due. Beyond [`KEPT`] the oldest is dropped, unless it is
    /// the rewind point of `last_hole` (the latest hole): then the next oldest goes, so that the
    /// hole just watched can still be replayed however long the tissue runs on.
    pub fn record_if_due(
        &mut self,
        m: &Monolayer,
        keys: &[u32],
        tracker: Option<&HoleTracker>,
        last_hole: Option<Nucleation>,
    ) {
        if !self.due(m) {
            return;
        }
        self.saved.push_back(Saved::of(m, keys, tracker));
        if self.saved.len() > KEPT {
            let pinned = last_hole.and_then(|h| self.rewind_index(h.step));
            self.saved.remove(if pinned == Some(0) { 1 } else { 0 });
        }
    }

    fn rewind_index(&self, hole_step: u64) -> Option<usize> {
        self.saved.iter().rposition(|s| s.step + LEAD <= hole_step)
    }

    /// The latest saved state at least [`LEAD`] steps before `hole_step`, if one is kept.
    pub fn rewind_point(&self, hole_step: u64) -> Option<&Saved> {
        self.rewind_index(hole_step).map(|i| &self.saved[i])
    }

    /// The saved states, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &Saved> {
        self.saved.iter()
    }

    /// Bytes the saved states take.
    pub fn size(&self) -> usize {
        self.saved.iter().map(Saved::size).sum()
    }
}

/// A replay from a saved state, watched for the hole the original opened.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Watch {
    /// The saved state's step.
    pub from: u64,
    /// The hole the original opened.
    pub hole: Nucleation,
    /// The last step watched: as many steps after `from` as the original took to the hole,
    /// plus [`MARGIN`].
    pub until: u64,
    /// How near the original's site a hole counts as the same tear (the cells' radius R).
    pub radius: f64,
    pub l: usize,
}

/// What a replay has shown so far.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Verdict {
    /// Still watching, no tear yet.
    Watching,
    /// A hole nucleated within R of the original's site, at this nucleation.
    Tore(Nucleation),
    /// None did up to `until`.
    Held,
}

impl Watch {
    /// Watches a replay from `from` for `hole`, on an L×L box of cells of radius `radius`.
    pub fn new(from: u64, hole: Nucleation, radius: f64, l: usize) -> Watch {
        Watch { from, hole, until: hole.step + MARGIN, radius, l }
    }

    /// The verdict at `step`, from the replay's nucleations so far.
    pub fn verdict(&self, step: u64, nucleations: &[Nucleation]) -> Verdict {
        let near = |n: &&Nucleation| {
            n.step > self.from
                && n.step <= self.until
                && periodic_distance(n.x, n.y, self.hole.x, self.hole.y, self.l) <= self.radius
        };
        match nucleations.iter().find(near) {
            Some(n) => Verdict::Tore(*n),
            None if step >= self.until => Verdict::Held,
            None => Verdict::Watching,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small active tissue: relaxation of 20 steps, then activity.
    fn tissue() -> Monolayer {
        let p = Params { box_size: 40, n_cells: 5, relax_steps: 20, ..Params::default() };
        Monolayer::new(p, 4).unwrap()
    }

    #[test]
    fn states_are_saved_every_save_every_active_steps_and_the_oldest_dropped() {
        let mut m = tissue();
        let mut h = History::default();
        h.record_if_due(&m, &[1], None, None);
        assert_eq!(h.iter().count(), 0, "nothing saved while relaxing");
        m.advance(20).unwrap();
        h.record_if_due(&m, &[1], None, None);
        h.record_if_due(&m, &[1], None, None);
        assert_eq!(h.iter().map(|s| s.step).collect::<Vec<_>>(), [20], "the end of the relaxation, once");
        // Stand-ins for later states: the same state under later steps.
        for k in 1..=KEPT as u64 + 2 {
            let mut state = m.state();
            state.step = 20 + k * SAVE_EVERY;
            let later = Monolayer::from_state(m.params().clone(), m.seed(), state).unwrap();
            assert!(h.due(&later));
            h.record_if_due(&later, &[1], None, None);
        }
        let steps: Vec<u64> = h.iter().map(|s| s.step).collect();
        assert_eq!(steps.len(), KEPT);
        assert_eq!(*steps.last().unwrap(), 20 + (KEPT as u64 + 2) * SAVE_EVERY);
        assert_eq!(steps[0], 20 + 3 * SAVE_EVERY, "the oldest went first");
        assert_eq!(h.size(), h.iter().map(Saved::size).sum::<usize>());
    }

    #[test]
    fn the_rewind_point_of_the_last_hole_is_kept_when_the_oldest_go() {
        let m = tissue();
        let mut h = History::default();
        let at = |step: u64| {
            let mut state = m.state();
            state.step = step;
            Monolayer::from_state(m.params().clone(), m.seed(), state).unwrap()
        };
        let hole = Nucleation { step: 20 + 2 * SAVE_EVERY + 10, x: 1.0, y: 2.0 };
        for k in 0..KEPT as u64 + 5 {
            h.record_if_due(&at(20 + k * SAVE_EVERY), &[1], None, Some(hole));
        }
        // The latest state at least LEAD before the hole: step 20 (1,010 before it).
        assert_eq!(h.rewind_point(hole.step).map(|s| s.step), Some(20));
        assert_eq!(h.iter().count(), KEPT);
        assert_eq!(h.iter().nth(1).unwrap().step, 20 + 6 * SAVE_EVERY, "the others went, oldest first");
        // No state LEAD before a hole that opens too early.
        assert!(h.rewind_point(20 + LEAD - 1).is_none());
    }

    #[test]
    fn a_saved_state_comes_back_bit_for_bit_and_steps_on_as_the_original() {
        let mut m = tissue();
        m.advance(30).unwrap();
        let saved = Saved::of(&m, &[1, 2, 3, 4, 5], None);
        assert_eq!(saved.fingerprint, m.fingerprint());
        let mut back = saved.monolayer().unwrap();
        assert_eq!(back.fingerprint(), saved.fingerprint);
        m.advance(7).unwrap();
        back.advance(7).unwrap();
        assert_eq!(back.fingerprint(), m.fingerprint(), "the replay parts from the original");
    }

    #[test]
    fn a_tear_counts_within_r_of_the_site_and_inside_the_window() {
        let hole = Nucleation { step: 2_260, x: 1.0, y: 70.0 };
        let w = Watch::new(1_000, hole, 8.0, 80);
        assert_eq!(w.until, 2_260 + MARGIN);
        let n = |step, x, y| Nucleation { step, x, y };
        assert_eq!(w.verdict(1_500, &[]), Verdict::Watching);
        assert_eq!(w.verdict(w.until, &[]), Verdict::Held);
        // Across the periodic edge: (79, 70) is 2 sites from (1, 70).
        assert_eq!(w.verdict(1_500, &[n(1_400, 79.0, 70.0)]), Verdict::Tore(n(1_400, 79.0, 70.0)));
        // Too far, too late or the saved state's own: not this tear.
        let others = [n(1_400, 10.0, 70.0), n(w.until + 10, 1.0, 70.0), n(1_000, 1.0, 70.0)];
        assert_eq!(w.verdict(w.until + 20, &others), Verdict::Held);
    }
}
