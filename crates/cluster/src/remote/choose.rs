//! `--draw auto`: which sort each Draw round on the workers uses,
//! sort-middle or sort-last, chosen by what the rounds before measured.
//! Either gives the same bytes, so trying one costs time alone.

use engine::Sort;

/// Measured rounds kept per sort: the estimate is the least of them, so
/// that one round slowed by something else (a busy machine) does not
/// turn the choice.
const KEEP: usize = 3;

/// Every this many rounds the sort not chosen is measured again, so that
/// the choice follows the hair (a groom growing denser on screen, a
/// camera moving closer).
const REVISIT: u64 = 16;

/// What the Draw rounds cost, per sort, and the choice that follows.
#[derive(Debug, Clone, Default)]
pub(super) struct Chooser {
    /// Per sort of [`Sort::ALL`], the last rounds' costs (ms), oldest first.
    costs: [Vec<f64>; 2],
    /// Rounds planned.
    rounds: u64,
    /// Rounds planned with each sort.
    pub(super) chosen: [u32; 2],
    /// The sort of the last round planned.
    last: Option<Sort>,
    /// Whether a round was measured yet: the first is not counted (it
    /// pays for the run's warm-up, the workers dialling each other).
    warm: bool,
}

impl Chooser {
    /// The sort of the next round: each is measured twice first, in
    /// turn (so that a machine growing busier weighs on both alike); then
    /// the one whose measured cost is least, but for every [`REVISIT`]th
    /// round, which measures the other again.
    pub(super) fn next(&mut self) -> Sort {
        self.rounds += 1;
        let measured = |s: Sort| self.costs[s.index()].len();
        let fewer = Sort::ALL
            .iter()
            .copied()
            .filter(|&s| measured(s) < 2)
            .min_by_key(|&s| {
                // The less measured first; of two alike, not the last one.
                (measured(s), Some(s) == self.last)
            });
        let sort = match fewer {
            Some(s) => s,
            None => {
                let best = self.best().unwrap_or(Sort::Middle);
                let other = if best == Sort::Middle {
                    Sort::Last
                } else {
                    Sort::Middle
                };
                if self.rounds.is_multiple_of(REVISIT) {
                    other
                } else {
                    best
                }
            }
        };
        self.chosen[sort.index()] += 1;
        self.last = Some(sort);
        sort
    }

    /// A round of `sort` took `ms`: the frame from its start to the next
    /// round's.
    pub(super) fn measured(&mut self, sort: Sort, ms: f64) {
        if !ms.is_finite() || ms < 0.0 || !std::mem::replace(&mut self.warm, true) {
            return;
        }
        let c = &mut self.costs[sort.index()];
        c.push(ms);
        if c.len() > KEEP {
            c.remove(0);
        }
    }

    /// The estimated cost of a round of `sort`, ms: the least of its last
    /// rounds.
    pub(super) fn estimate(&self, sort: Sort) -> Option<f64> {
        self.costs[sort.index()].iter().copied().reduce(f64::min)
    }

    /// The sort of least estimated cost, once both were measured.
    fn best(&self) -> Option<Sort> {
        let (m, l) = (self.estimate(Sort::Middle)?, self.estimate(Sort::Last)?);
        Some(if m <= l { Sort::Middle } else { Sort::Last })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tries_each_sort_in_turn_then_keeps_the_cheaper_and_looks_again_now_and_then() {
        let mut c = Chooser::default();
        // Sort-last measures cheaper here.
        let cost = |s: Sort| if s == Sort::Middle { 90.0 } else { 60.0 };
        let mut seen = Vec::new();
        for _ in 0..32 {
            let s = c.next();
            c.measured(s, cost(s));
            seen.push(s);
        }
        // The first round's measure is not counted; then each in turn
        // until each has two.
        use Sort::{Last, Middle};
        assert_eq!(&seen[..5], &[Middle, Last, Middle, Last, Middle]);
        // Then sort-last, but for one look at sort-middle each 16 rounds.
        let middle: Vec<usize> = (5..32).filter(|&i| seen[i] == Middle).collect();
        assert_eq!(middle, vec![15, 31], "rounds 16 and 32");
        assert_eq!(c.chosen, [5, 27]);
        // The hair changes: sort-middle is measured cheaper when looked at
        // again, and taken from then on.
        c.measured(Middle, 30.0);
        assert_eq!(c.next(), Middle);
        // One slow round does not turn the choice; an estimate keeps the
        // least of the last three.
        c.measured(Middle, 500.0);
        assert_eq!(c.estimate(Middle), Some(30.0));
        assert_eq!(c.next(), Middle);
        // Nonsense times are ignored.
        c.measured(Last, f64::NAN);
        c.measured(Last, -1.0);
        assert_eq!(c.estimate(Last), Some(60.0));
    }
}
