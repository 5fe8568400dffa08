//! How many conjugate-gradient iterations a step records for each friction solve, and how many
//! steps one submission holds.
//!
//! The GPU cannot stop a recorded loop early, only make its remaining dispatches return at
//! once (`friction.wgsl`), so the count is chosen on the host between submissions from what
//! the solves took: too few and a submission is put back and taken again with more; too many
//! and every step pays for dispatches that do nothing. A solve that converged gives the same
//! bits whatever the count recorded after it, so the rule changes the cost, never the run.
//!
//! The rule ([`IterationRule`]): after accepted steps, the count follows the most any solve took
//! plus a margin, but is lowered only after [`LOWER_AFTER`] accepted submissions in a row asked
//! for less, and never below a count that failed within the last [`FAILURE_MEMORY`]
//! submissions; after a failure it grows by half (at least [`GROWTH_MIN`]) up to its ceiling.
//! So a solve that needs one iteration more than recorded costs one redo, not a cycle of
//! lowering and failing. [`steps_per_submission`] keeps a submission's dispatches under
//! [`MAX_DISPATCHES_PER_SUBMISSION`], whatever the count: a long submission is what a driver's
//! watchdog kills.

/// Dispatches at most in one submission: about a tenth of a second of a laptop GPU's
/// launches, well under the two seconds after which drivers reset a busy device.
pub const MAX_DISPATCHES_PER_SUBMISSION: usize = 20_000;
/// Accepted submissions in a row that asked for fewer iterations before the count is lowered.
pub const LOWER_AFTER: u32 = 4;
/// Submissions during which a count that failed is not recorded again.
pub const FAILURE_MEMORY: u32 = 32;
/// The least growth after a failure, in iterations.
pub const GROWTH_MIN: usize = 2;

/// The iterations recorded per solve: between `fewest` and `most`, following what the solves
/// take.
#[derive(Clone, Debug, PartialEq)]
pub struct IterationRule {
    /// The count recorded now.
    pub recorded: usize,
    /// Bounds of the count.
    pub fewest: usize,
    pub most: usize,
    /// The least count not known to fail lately (a count that failed, plus one), and the
    /// submissions it is still remembered for.
    floor: usize,
    floor_left: u32,
    /// Accepted submissions in a row whose solves asked for fewer iterations than recorded.
    quiet: u32,
}

/// What to do after a submission whose solves missed their tolerance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AfterFailure {
    /// Take the same steps again with this many iterations.
    Retry(usize),
    /// The count is at its ceiling already: the solves do not converge.
    GiveUp,
}

impl IterationRule {
    /// Starts at `recorded` (at most `most`; below `fewest` it stays until the solves ask for
    /// more), the count then kept within [`fewest`, `most`] (`fewest` at least 1).
    pub fn new(recorded: usize, fewest: usize, most: usize) -> Self {
        let fewest = fewest.max(1);
        let most = most.max(fewest);
        IterationRule { recorded: recorded.clamp(1, most), fewest, most, floor: fewest, floor_left: 0, quiet: 0 }
    }

    /// The count the solves of a submission ask for, when the most any took was `taken`: that
    /// plus a quarter of it, at least one more.
    pub fn wanted(taken: usize) -> usize {
        taken + (taken / 4).max(1)
    }

    /// After accepted steps whose solves took at most `taken` iterations.
    pub fn accepted(&mut self, taken: usize) {
        if self.floor > self.fewest && taken + 1 >= self.floor {
            // The solves needed what once failed again: remember it afresh.
            self.floor_left = FAILURE_MEMORY;
        } else if self.floor_left > 0 {
            self.floor_left -= 1;
        } else {
            self.floor = self.fewest;
        }
        let want = Self::wanted(taken).max(self.floor).clamp(self.fewest, self.most);
        if want >= self.recorded {
            self.quiet = 0;
            return;
        }
        self.quiet += 1;
        if self.quiet >= LOWER_AFTER {
            self.recorded = want;
            self.quiet = 0;
        }
    }

    /// After steps whose solves missed their tolerance within the recorded count.
    pub fn failed(&mut self) -> AfterFailure {
        self.quiet = 0;
        if self.recorded >= self.most {
            return AfterFailure::GiveUp;
        }
        self.floor = self.recorded + 1;
        self.floor_left = FAILURE_MEMORY;
        self.recorded = (self.recorded + (self.recorded / 2).max(GROWTH_MIN)).min(self.most);
        AfterFailure::Retry(self.recorded)
    }
}

/// Steps in one submission: at most `wanted`, and as many as keep `dispatches_per_step` each
/// under [`MAX_DISPATCHES_PER_SUBMISSION`] (at least one).
pub fn steps_per_submission(wanted: u64, dispatches_per_step: usize) -> u64 {
    let fit = (MAX_DISPATCHES_PER_SUBMISSION / dispatches_per_step.max(1)).max(1) as u64;
    wanted.min(fit)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `submissions` submissions whose solves need `need(i)` iterations each; returns the
    /// redone submissions and the counts recorded at the end of each.
    fn simulate(rule: &mut IterationRule, need: impl Fn(usize) -> usize, submissions: usize) -> (usize, Vec<usize>) {
        let (mut redos, mut counts) = (0, vec![]);
        for i in 0..submissions {
            loop {
                if need(i) <= rule.recorded {
                    rule.accepted(need(i));
                    break;
                }
                redos += 1;
                assert_eq!(rule.failed(), AfterFailure::Retry(rule.recorded), "gave up at {}", rule.recorded);
            }
            counts.push(rule.recorded);
        }
        (redos, counts)
    }

    #[test]
    fn a_solve_needing_one_more_iteration_costs_one_redo_not_a_cycle() {
        // Solves that take 4 iterations, and every tenth submission one that needs 6, one more
        // than the 5 the count settles at. The rule before this one (halve while the most
        // taken is under a third, double on a failure) lowered again after each such solve and
        // failed at the next: a redo every ten submissions.
        let need = |i: usize| if i % 10 == 5 { 6 } else { 4 };
        let mut rule = IterationRule::new(7, 1, 240);
        let (redos, counts) = simulate(&mut rule, need, 100);
        assert_eq!(counts[4], 5, "settled at {counts:?}");
        assert_eq!(redos, 1, "counts {counts:?}");
        assert!(counts[5..].iter().all(|&c| c >= 6), "lowered back below a count that failed: {counts:?}");
    }

    #[test]
    fn the_count_follows_what_the_solves_take_with_a_margin_and_lowers_slowly() {
        let mut rule = IterationRule::new(30, 7, 240);
        let (redos, counts) = simulate(&mut rule, |_| 5, 12);
        assert_eq!(redos, 0);
        // Lowered only after LOWER_AFTER quiet submissions, to 5 + 1 = 6, kept at fewest = 7.
        assert_eq!(&counts[..LOWER_AFTER as usize - 1], &[30, 30, 30]);
        assert_eq!(counts[LOWER_AFTER as usize - 1], 7);
        assert_eq!(*counts.last().unwrap(), 7);
        // Many iterations: the margin is a quarter.
        assert_eq!(IterationRule::wanted(40), 50);
    }

    #[test]
    fn growth_is_by_half_up_to_the_ceiling_then_it_gives_up() {
        let mut rule = IterationRule::new(1, 1, 10);
        let grown: Vec<_> = std::iter::from_fn(|| match rule.failed() {
            AfterFailure::Retry(n) => Some(n),
            AfterFailure::GiveUp => None,
        })
        .collect();
        assert_eq!(grown, vec![3, 5, 7, 10]);
        assert_eq!(rule.failed(), AfterFailure::GiveUp);
    }

    #[test]
    fn a_failed_count_is_forgotten_after_its_memory() {
        let mut rule = IterationRule::new(4, 1, 240);
        assert_eq!(rule.failed(), AfterFailure::Retry(6));
        for _ in 0..FAILURE_MEMORY + LOWER_AFTER + 1 {
            rule.accepted(1);
        }
        assert_eq!(rule.recorded, IterationRule::wanted(1), "the floor of the old failure still holds");
    }

    #[test]
    fn a_submission_stays_under_the_dispatch_cap() {
        assert_eq!(steps_per_submission(50, 100), 50);
        assert_eq!(steps_per_submission(50, 1_000), 20);
        assert_eq!(steps_per_submission(50, 100_000), 1);
        assert_eq!(steps_per_submission(50, 0), 50);
    }
}
