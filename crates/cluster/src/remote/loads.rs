//! What each worker's own share of the hair costs it a frame, and the
//! share of the picture's rows it is then dealt: the workers draw bands
//! of rows on top of their own strands, so a worker whose strands cost
//! more gets bands that cost less, and every worker's frame adds up alike.

use engine::Sort;

/// How much of a frame's new measure goes into the smoothed cost.
const SMOOTHING: f64 = 0.5;

/// The least share of the rows' cost a worker keeps, against an even
/// share: a worker whose own strands measured slow still draws bands, so
/// its next frames measure them again.
const LEAST_SHARE: f64 = 0.25;

/// Per live worker, in their order: what its own strands cost it (its
/// steps and pose, then filter, shade and rasterization or binning of its
/// strands: what follows the groups it holds), ms a frame, smoothed over
/// frames, apart for each sort (a worker rasterizes its own strands whole
/// in sort-last, and only bins them in sort-middle).
#[derive(Debug, Default, Clone)]
pub(super) struct Loads {
    /// Per sort (in the order of [`engine::Sort::ALL`]) and worker, the
    /// smoothed cost, once measured.
    own: [Vec<Option<f64>>; 2],
    /// Per worker, the frame's steps so far (they come before its Draw).
    steps: Vec<f64>,
}

impl Loads {
    /// Forgets every measure: the workers, or their shares, changed.
    pub(super) fn clear(&mut self) {
        self.own = Default::default();
        self.steps.clear();
    }

    fn fit(&mut self, workers: usize) {
        if self.steps.len() != workers {
            self.own = [vec![None; workers], vec![None; workers]];
            self.steps = vec![0.0; workers];
        }
    }

    /// Worker `w` of `workers` stepped and posed its wisps in `ms`.
    pub(super) fn stepped(&mut self, w: usize, workers: usize, ms: f64) {
        self.fit(workers);
        if w < workers && ms.is_finite() && ms >= 0.0 {
            self.steps[w] += ms;
        }
    }

    /// Worker `w` of `workers` filtered, shaded and rasterized (or binned)
    /// its strands in `ms` for `sort`: with its steps since, the frame's
    /// measure of its own work.
    pub(super) fn drew(&mut self, sort: Sort, w: usize, workers: usize, ms: f64) {
        self.fit(workers);
        if w >= workers || !ms.is_finite() || ms < 0.0 {
            return;
        }
        let now = std::mem::take(&mut self.steps[w]) + ms;
        let own = &mut self.own[sort.index()];
        own[w] = Some(match own[w] {
            Some(was) => was + SMOOTHING * (now - was),
            None => now,
        });
    }

    /// Each worker's share of the rows' cost, when the rows cost
    /// `rows_ms` a frame to draw and every worker's own work was
    /// measured: the share that brings each worker's own work and bands
    /// to the same total, `T = (sum_w own_w + rows_ms) / workers`, share
    /// `(T - own_w) / rows_ms`, but at least [`LEAST_SHARE`] of an even
    /// one (then scaled to sum to 1). Empty otherwise (even shares).
    pub(super) fn row_shares(&self, sort: Sort, workers: usize, rows_ms: f64) -> Vec<f64> {
        let own: Option<Vec<f64>> = self.own[sort.index()].iter().copied().collect();
        let Some(own) = own.filter(|o| o.len() == workers && workers >= 2) else {
            return Vec::new();
        };
        if !rows_ms.is_finite() || rows_ms <= 0.0 {
            return Vec::new();
        }
        let n = workers as f64;
        let total = (own.iter().sum::<f64>() + rows_ms) / n;
        let least = LEAST_SHARE * rows_ms / n;
        let raw: Vec<f64> = own.iter().map(|o| (total - o).max(least)).collect();
        let sum: f64 = raw.iter().sum();
        raw.iter().map(|r| r / sum).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    const M: Sort = Sort::Middle;

    #[test]
    fn a_worker_busier_with_its_own_strands_is_dealt_less_of_the_rows() {
        let mut l = Loads::default();
        // Not every worker measured: even.
        l.drew(M, 0, 3, 40.0);
        assert!(l.row_shares(M, 3, 90.0).is_empty());
        l.stepped(1, 3, 5.0);
        l.drew(M, 1, 3, 15.0);
        l.drew(M, 2, 3, 20.0);
        // Own work 40, 20, 20 and rows of 90: each frame 170 / 3; worker
        // 0's rows 16.7 ms, the others' 36.7 each.
        let s = l.row_shares(M, 3, 90.0);
        let want = [50.0 / 3.0 / 90.0, 110.0 / 3.0 / 90.0, 110.0 / 3.0 / 90.0];
        for (got, want) in s.iter().zip(want) {
            assert!((got - want).abs() < 1e-9, "{s:?}");
        }
        // Smoothed: a second frame of 80 for worker 0 moves it halfway.
        l.drew(M, 0, 3, 80.0);
        assert_eq!(l.own[0][0], Some(60.0));
        // The other sort's are its own.
        assert!(l.row_shares(Sort::Last, 3, 90.0).is_empty());
        // A worker far behind keeps a quarter of an even share.
        l.drew(M, 0, 3, 1000.0);
        let s = l.row_shares(M, 3, 90.0);
        // Own 530, 20, 20: each frame would be 220; worker 0 keeps 7.5
        // (a quarter of 30), the others 200 each.
        assert!((s[0] - 7.5 / 407.5).abs() < 1e-9, "{s:?}");
        assert!((s[1] - 200.0 / 407.5).abs() < 1e-9, "{s:?}");
        assert!((s.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        // Another count of workers starts again.
        l.drew(M, 0, 2, 10.0);
        assert!(l.row_shares(M, 2, 90.0).is_empty());
        // Nonsense is left out.
        l.drew(M, 1, 2, f64::NAN);
        l.drew(M, 1, 2, -1.0);
        assert!(l.row_shares(M, 2, 90.0).is_empty());
        l.drew(M, 1, 2, 10.0);
        assert_eq!(l.row_shares(M, 2, 90.0), vec![0.5, 0.5]);
        assert!(l.row_shares(M, 2, f64::NAN).is_empty());
        l.clear();
        assert!(l.row_shares(M, 2, 90.0).is_empty());
    }
}
