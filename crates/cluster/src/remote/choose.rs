//! `--draw auto`: how each frame is drawn, sort-middle, sort-last or on
//! the coordinator (the paper's scheme), chosen by what the frames before
//! measured. Every scheme gives the same bytes, so trying one costs time
//! alone.

use engine::{FrameNeeds, Site, Sort};

use super::RemoteExecutor;

/// How a frame's drawn hair is posed, filtered, shaded and rasterized
/// with two or more workers (Molnar's classification of parallel
/// rendering).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scheme {
    /// On the workers, each band's owner rasterizing every strand's
    /// segments of its rows.
    Middle,
    /// On the workers, each band's owner compositing every worker's
    /// partial picture of its rows.
    Last,
    /// On the coordinator, every strand (the paper's scheme): the workers
    /// step, fill and sweep.
    Coordinator,
}

impl Scheme {
    /// Every scheme, in the order [`Self::index`] numbers them: what keeps
    /// a figure per scheme keeps it in this order.
    pub const ALL: [Scheme; 3] = [Scheme::Middle, Scheme::Last, Scheme::Coordinator];

    /// The scheme's place in [`Self::ALL`].
    pub fn index(self) -> usize {
        match self {
            Scheme::Middle => 0,
            Scheme::Last => 1,
            Scheme::Coordinator => 2,
        }
    }

    /// What the workers send a band's owner, when they draw.
    pub fn sort(self) -> Option<Sort> {
        match self {
            Scheme::Middle => Some(Sort::Middle),
            Scheme::Last => Some(Sort::Last),
            Scheme::Coordinator => None,
        }
    }

    /// The scheme's name, as `--draw` spells it.
    pub fn name(self) -> &'static str {
        match self {
            Scheme::Middle => "sort-middle",
            Scheme::Last => "sort-last",
            Scheme::Coordinator => "coordinator",
        }
    }
}

impl From<Sort> for Scheme {
    fn from(s: Sort) -> Scheme {
        match s {
            Sort::Middle => Scheme::Middle,
            Sort::Last => Scheme::Last,
        }
    }
}

impl RemoteExecutor {
    /// The one place a frame's scheme is decided. With one worker the
    /// coordinator draws: a lone worker's partial picture would cross the
    /// wire only to be composited here (`bench scaling`, curly, 0.4 core a
    /// node: 420 ms a frame drawn on the worker against 288 drawn here,
    /// one process 299). With [`DrawAt::Auto`], the scheme whose frames
    /// measured cheapest ([`Chooser`]): a frame costs what the call that
    /// rendered it took ([`engine::FrameTime`]: its drawing, and the next
    /// frame's stages that ran beside its picture), so a scheme whose
    /// picture is finished beside the next frame is charged for it, not
    /// the scheme of the next. A worker lost in the frame leaves the
    /// scheme as planned: the survivors finish it.
    pub(super) fn plan(&mut self, needs: FrameNeeds) -> Site {
        if let Some(done) = needs.finished
            && let Some(&(_, scheme)) = self.chosen.iter().find(|c| c.0 == done.index)
        {
            self.chooser.measured(scheme, done.ms);
        }
        // Frames long past are forgotten (a frame's cost comes at most
        // two plans later).
        self.chosen.retain(|c| c.0 + 4 > needs.index);
        let choice = needs.may_draw_elsewhere && self.draw.on_workers() && self.workers.len() >= 2;
        self.scheme = match (choice, self.draw.sort()) {
            (false, _) => Scheme::Coordinator,
            (true, Some(sort)) => Scheme::from(sort),
            // A frame of motion alone (skipped before a range) is no
            // measure, and takes no turn of the choice's.
            (true, None) if !needs.picture => self.chooser.best().unwrap_or(Scheme::Middle),
            (true, None) => {
                let s = self.chooser.next();
                if needs.picture {
                    self.chosen.push((needs.index, s));
                }
                s
            }
        };
        if needs.picture {
            let (scheme, c) = (self.scheme, &self.chooser);
            let estimates = Scheme::ALL.map(|s| c.estimate(s).unwrap_or(0.0));
            self.clock(|t| {
                t.frames[scheme.index()] += 1;
                t.estimate_ms = estimates;
            });
        }
        match self.scheme {
            Scheme::Coordinator => Site::Here,
            Scheme::Middle | Scheme::Last => Site::Elsewhere,
        }
    }
}

/// Measured frames kept per scheme: the estimate is the least of them, so
/// that one frame slowed by something else (a busy machine) does not turn
/// the choice.
const KEEP: usize = 3;

/// Every this many frames a scheme not chosen is measured again (each in
/// turn), so that the choice follows the hair (a groom growing denser on
/// screen, a camera moving closer).
const REVISIT: u64 = 16;

/// A scheme whose first frame cost more than this many times the best
/// estimate is not measured a second time before the choice.
const HOPELESS: f64 = 1.5;

/// What the frames cost, per scheme, and the choice that follows.
#[derive(Debug, Clone, Default)]
pub(super) struct Chooser {
    /// Per scheme of [`Scheme::ALL`], the last frames' costs (ms), oldest
    /// first.
    costs: [Vec<f64>; 3],
    /// Frames planned.
    frames: u64,
    /// Revisits so far: which scheme not chosen is measured next.
    revisits: usize,
    /// The scheme of the last frame planned, and how many frames in a
    /// row were planned with it.
    last: Option<Scheme>,
    run: u32,
    /// Whether a frame was measured yet: the first is not counted (it
    /// pays for the run's warm-up, the workers dialling each other).
    warm: bool,
}

impl Chooser {
    /// The scheme of the next frame: each is measured twice first, in
    /// pairs of frames, a scheme after another (so that a machine growing
    /// busier weighs on all alike), but a scheme whose first frame cost
    /// [`HOPELESS`] times the best estimate once; then the one whose
    /// measured cost is least, but for every [`REVISIT`]th frame, which
    /// measures another again. In pairs, as a frame's cost takes in the
    /// next frame's stages that run beside its picture: the first of a
    /// pair is charged with its own scheme's, not another's (the
    /// coordinator's stages, after a sort-middle frame of the production
    /// groom, made it cost 2168 ms against its 1233).
    pub(super) fn next(&mut self) -> Scheme {
        self.frames += 1;
        let best = self.best();
        let wanted = |s: Scheme| -> usize {
            let n = self.costs[s.index()].len();
            let hopeless = match (self.estimate(s), best.and_then(|b| self.estimate(b))) {
                (Some(mine), Some(least)) => mine > HOPELESS * least,
                _ => false,
            };
            let want: usize = if hopeless { 1 } else { 2 };
            want.saturating_sub(n)
        };
        let fewer = Scheme::ALL
            .iter()
            .copied()
            .filter(|&s| wanted(s) > 0)
            .min_by_key(|&s| {
                // The less measured first; of two alike, not the last one,
                // then in the order of ALL.
                (self.costs[s.index()].len(), Some(s) == self.last)
            });
        // The second of a pair, while its scheme still wants measures;
        // else the least measured.
        let again = self.last.filter(|&l| self.run == 1 && wanted(l) > 0);
        let scheme = match (again.or(fewer), best) {
            (Some(s), _) => s,
            (None, None) => Scheme::ALL[0],
            (None, Some(best)) => {
                if self.frames.is_multiple_of(REVISIT) {
                    let others: Vec<Scheme> =
                        Scheme::ALL.into_iter().filter(|&s| s != best).collect();
                    self.revisits += 1;
                    others[(self.revisits - 1) % others.len()]
                } else {
                    best
                }
            }
        };
        self.run = if self.last == Some(scheme) {
            self.run + 1
        } else {
            1
        };
        self.last = Some(scheme);
        scheme
    }

    /// A frame drawn with `scheme` took `ms`: from its start to the next
    /// frame's.
    pub(super) fn measured(&mut self, scheme: Scheme, ms: f64) {
        if !ms.is_finite() || ms < 0.0 || !std::mem::replace(&mut self.warm, true) {
            return;
        }
        let c = &mut self.costs[scheme.index()];
        c.push(ms);
        if c.len() > KEEP {
            c.remove(0);
        }
    }

    /// The estimated cost of a frame drawn with `scheme`, ms: the least of
    /// its last frames.
    pub(super) fn estimate(&self, scheme: Scheme) -> Option<f64> {
        self.costs[scheme.index()].iter().copied().reduce(f64::min)
    }

    /// The scheme of least estimated cost, of those measured.
    pub(super) fn best(&self) -> Option<Scheme> {
        Scheme::ALL
            .into_iter()
            .filter_map(|s| Some((s, self.estimate(s)?)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(s, _)| s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Scheme::{Coordinator, Last, Middle};

    fn run(c: &mut Chooser, frames: usize, cost: impl Fn(Scheme) -> f64) -> Vec<Scheme> {
        (0..frames)
            .map(|_| {
                let s = c.next();
                c.measured(s, cost(s));
                s
            })
            .collect()
    }

    #[test]
    fn tries_each_scheme_in_turn_then_keeps_the_cheapest_and_looks_again_now_and_then() {
        let mut c = Chooser::default();
        // Sort-last measures cheaper here; the coordinator is close behind.
        let cost = |s: Scheme| match s {
            Middle => 90.0,
            Last => 60.0,
            Coordinator => 80.0,
        };
        let seen = run(&mut c, 48, cost);
        // The first frame's measure is not counted; then each in turn, two
        // frames in a row, until each has two measures.
        assert_eq!(
            &seen[..7],
            &[Middle, Middle, Last, Last, Coordinator, Coordinator, Middle]
        );
        // Then sort-last, but for one look at another each 16 frames, in
        // turn.
        let others: Vec<(usize, Scheme)> = (7..48)
            .filter(|&i| seen[i] != Last)
            .map(|i| (i, seen[i]))
            .collect();
        assert_eq!(others, vec![(15, Middle), (31, Coordinator), (47, Middle)]);
        // The hair changes: sort-middle is measured cheaper when looked at
        // again, and taken from then on.
        c.measured(Middle, 30.0);
        assert_eq!(c.next(), Middle);
        // One slow frame does not turn the choice; an estimate keeps the
        // least of the last three.
        c.measured(Middle, 500.0);
        assert_eq!(c.estimate(Middle), Some(30.0));
        assert_eq!(c.next(), Middle);
        // Nonsense times are ignored.
        c.measured(Last, f64::NAN);
        c.measured(Last, -1.0);
        assert_eq!(c.estimate(Last), Some(60.0));
    }

    #[test]
    fn a_scheme_far_behind_at_its_first_frame_is_not_measured_twice() {
        let mut c = Chooser::default();
        let cost = |s: Scheme| match s {
            Middle => 100.0,
            Last => 110.0,
            Coordinator => 250.0,
        };
        let seen = run(&mut c, 15, cost);
        // Warm-up, then each in turn; the coordinator's 250 ms is more
        // than 1.5x sort-middle's 100, so it is not drawn a second time.
        assert_eq!(
            &seen[..7],
            &[Middle, Middle, Last, Last, Coordinator, Middle, Middle]
        );
        assert_eq!(
            seen.iter().filter(|&&s| s == Coordinator).count(),
            1,
            "{seen:?}"
        );
        assert_eq!(c.best(), Some(Middle));
    }

    #[test]
    fn a_frame_charged_with_the_coordinators_stages_does_not_lose_its_scheme_the_choice() {
        // A frame's cost comes two plans later, and takes in the next
        // frame's stages beside its picture: 100 ms more when that next
        // frame is the coordinator's. Sort-middle is cheapest on its own.
        let base = |s: Scheme| match s {
            Middle => 100.0,
            Last => 110.0,
            Coordinator => 140.0,
        };
        let mut c = Chooser::default();
        let mut seen: Vec<Scheme> = Vec::new();
        for j in 0..20 {
            if j >= 2 {
                let i = j - 2;
                let charged = if seen[i + 1] == Coordinator {
                    100.0
                } else {
                    0.0
                };
                c.measured(seen[i], base(seen[i]) + charged);
            }
            seen.push(c.next());
        }
        // In turn, a scheme's first frame of a pair is followed by its
        // own: sort-middle's first measure is its own 100 ms, not 200 (at
        // 200, 1.5x sort-last's 110, it would have been given up).
        assert_eq!(c.estimate(Middle), Some(100.0), "{seen:?}");
        assert_eq!(c.best(), Some(Middle), "{seen:?}");
        // From the last measure on, sort-middle but for the 16th frame's
        // look at another.
        let others: Vec<usize> = (7..20).filter(|&i| seen[i] != Middle).collect();
        assert_eq!(others, vec![15], "{seen:?}");
    }
}
