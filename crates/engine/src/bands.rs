//! How the workers draw a frame's picture among themselves: its rows cut
//! in bands, each band owned by one worker ([`BandPlan`]), and what the
//! others send a band's owner ([`Stripe`]): their partial picture of its
//! rows (sort-last: every worker rasterizes its own strands) or their
//! shaded segments of its rows (sort-middle: the owner rasterizes every
//! strand of its rows, so each pixel's work is done once).

use std::ops::Range;
use std::time::Instant;

use glam::Vec3;
use raster::{BandSegments, Canvas, HairLayer};

use crate::EngineError;
use crate::stats::{DrawTimes, ms};

/// How the workers draw a frame's picture among themselves: its rows cut
/// in bands, dealt out to the workers in turn (band `b` to worker
/// `b % workers`, so that each gets about as much hair), by direct send.
/// Each sends what it drew of the others' bands to them ([`Stripe`]),
/// and resolves its own bands, with the head, from its own hair and what
/// the others sent.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BandPlan {
    /// Band `b` is rows `cuts[b]..cuts[b + 1]`: from 0 to the picture's
    /// height, ascending, each on a multiple of [`Canvas::BAND_ROWS`]
    /// (but the last).
    pub cuts: Vec<u32>,
    /// The workers the bands are dealt to.
    pub workers: usize,
    /// This share's worker.
    pub own: usize,
    /// What the workers send each other.
    pub sort: Sort,
}

/// What the workers send the owner of a band (Molnar's classification of
/// parallel rendering).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Sort {
    /// Their partial picture of its rows: exact sums and nearest
    /// fragments per pixel (each worker rasterizes its own strands).
    #[default]
    Last,
    /// Their shaded segments of its rows: the owner rasterizes every
    /// strand there, so a pixel's work is done once, and the bytes sent
    /// grow with the drawn segments, not the pixels they cover.
    Middle,
}

impl Sort {
    /// Both sorts, in the order [`Self::index`] numbers them: what keeps
    /// a figure per sort keeps it in this order.
    pub const ALL: [Sort; 2] = [Sort::Middle, Sort::Last];

    /// The sort's place in [`Self::ALL`].
    pub fn index(self) -> usize {
        match self {
            Sort::Middle => 0,
            Sort::Last => 1,
        }
    }
}

impl BandPlan {
    /// Bands of `rows` rows (rounded up to whole canvas bands) of a
    /// picture of `height` rows, dealt to `workers` workers.
    pub fn dealt(height: u32, rows: u32, workers: usize, own: usize) -> BandPlan {
        let band = Canvas::BAND_ROWS;
        let step = rows.max(1).div_ceil(band) * band;
        let mut cuts: Vec<u32> = (0..height.div_ceil(step)).map(|i| i * step).collect();
        cuts.push(height);
        BandPlan {
            cuts,
            workers,
            own,
            sort: Sort::Last,
        }
    }

    /// `bands` bands (or fewer, for a short picture) dealt to `workers`
    /// workers in turn, where `row_ms[r]` is what rows `16 r .. 16 (r +
    /// 1)` of a picture of `height` rows cost to draw last: cut on
    /// multiples of [`Canvas::BAND_ROWS`], each band at least that tall,
    /// so that worker `w`'s bands hold `shares[w]` of the cost (shares
    /// summing to 1, split evenly among its bands); empty `shares`, or
    /// shares that are not one a worker of positive finite values, share
    /// the cost evenly. A row's cost counts at least a hundredth of the
    /// mean, as even a row of background is written. `None` when the
    /// costs do not fit the picture or are not finite.
    pub fn weighted(
        height: u32,
        row_ms: &[f64],
        shares: &[f64],
        bands: usize,
        workers: usize,
        own: usize,
    ) -> Option<BandPlan> {
        let step = Canvas::BAND_ROWS;
        let units = height.div_ceil(step) as usize;
        if row_ms.len() != units || bands == 0 || row_ms.iter().any(|c| !c.is_finite() || *c < 0.0)
        {
            return None;
        }
        let mean = row_ms.iter().sum::<f64>() / units as f64;
        let floor = (mean / 100.0).max(f64::MIN_POSITIVE);
        let cost: Vec<f64> = row_ms.iter().map(|c| c.max(floor)).collect();
        let total: f64 = cost.iter().sum();
        let bands = bands.min(units);
        // Each band's share of the cost: its worker's share over its
        // worker's bands; then the cost the bands up to each end on.
        let w = workers.max(1);
        let even = shares.len() != w || shares.iter().any(|s| !s.is_finite() || *s <= 0.0);
        let sum: f64 = shares.iter().sum();
        let mut goal = Vec::with_capacity(bands);
        let mut upto = 0.0;
        for b in 0..bands {
            // Bands `c < bands` with `c % w == b % w`.
            let of_worker = (bands - b % w).div_ceil(w) as f64;
            upto += if even {
                1.0 / bands as f64
            } else {
                shares[b % w] / sum / of_worker
            };
            goal.push(total * upto);
        }
        let mut cuts = vec![0u32];
        let mut acc = 0.0;
        for (u, c) in cost.iter().enumerate() {
            let left_units = units - u;
            let left_bands = bands - (cuts.len() - 1);
            acc += c;
            // Cut after this unit when its band has its share of the cost,
            // or when every band left needs one of the units left.
            let share = goal[cuts.len() - 1];
            let must = left_units - 1 < left_bands;
            if u + 1 < units && left_bands > 1 && (acc >= share || must) {
                cuts.push((u as u32 + 1) * step);
            }
        }
        cuts.push(height);
        Some(BandPlan {
            cuts,
            workers,
            own,
            sort: Sort::Last,
        })
    }

    /// Rows of band `b`.
    pub fn rows(&self, b: usize) -> Range<u32> {
        self.cuts[b]..self.cuts[b + 1]
    }

    /// Bands.
    pub fn bands(&self) -> usize {
        self.cuts.len().saturating_sub(1)
    }

    /// The worker band `b` belongs to.
    pub fn owner(&self, b: usize) -> usize {
        b % self.workers.max(1)
    }

    /// The rows of each band of worker `w`, top to bottom.
    pub fn rows_of(&self, w: usize) -> Vec<Range<u32>> {
        (0..self.bands())
            .filter(|&b| self.owner(b) == w)
            .map(|b| self.rows(b))
            .collect()
    }

    /// Whether row `row` lies in one of this share's bands.
    pub fn owns_row(&self, row: u32) -> bool {
        let b = self.cuts.partition_point(|&c| c <= row);
        b >= 1 && b < self.cuts.len() && self.owner(b - 1) == self.own
    }

    /// The most rows, at most `rows`, of canvas bands that cut this plan's
    /// bands whole ([`Canvas::set_band_rows`]).
    pub fn band_rows_within(&self, rows: u32) -> u32 {
        let step = Canvas::BAND_ROWS;
        let divides = |r: u32| {
            self.cuts[..self.cuts.len().saturating_sub(1)]
                .iter()
                .all(|c| c.is_multiple_of(r))
        };
        (1..=rows / step)
            .rev()
            .map(|m| m * step)
            .find(|&r| divides(r))
            .unwrap_or(step)
    }

    /// Checks the plan against a picture of `height` rows.
    pub fn check(&self, height: u32) -> Result<(), EngineError> {
        let band = Canvas::BAND_ROWS;
        let ok = self.cuts.len() >= 2
            && self.own < self.workers
            && self.cuts.first() == Some(&0)
            && self.cuts.last() == Some(&height)
            && self.cuts.windows(2).all(|w| w[0] < w[1])
            && self.cuts[..self.cuts.len() - 1]
                .iter()
                .all(|c| c.is_multiple_of(band));
        if ok {
            Ok(())
        } else {
            Err(EngineError::executor(format!(
                "bands {:?} (worker {} of {}) do not cut a picture of {height} rows in whole bands of {band}",
                self.cuts, self.own, self.workers
            )))
        }
    }
}

/// What a worker sends the owner of a band: see [`Sort`].
#[derive(Debug, Clone, PartialEq)]
pub enum Stripe {
    /// A partial picture of the band's rows.
    Layer(HairLayer),
    /// Shaded segments of the band's rows.
    Segments(BandSegments),
}

/// What a share drew of its own bands, waiting for the others'.
#[derive(Debug)]
pub(crate) enum Own {
    /// Its partial picture of them.
    Layer(Option<HairLayer>),
    /// Its segments of each.
    Segments(Vec<BandSegments>),
}

/// A share's bands of a picture drawn on the workers, rasterized (sort-last)
/// or binned (sort-middle) and waiting for what the other workers send
/// (see [`crate::Share::draw_band`]).
#[derive(Debug)]
pub struct BandWork {
    pub(crate) canvas: Canvas,
    pub(crate) own: Vec<Range<u32>>,
    /// This share's own hair in its bands.
    pub(crate) mine: Own,
    pub(crate) background: Vec3,
    /// The band rows that draw every strand of the bands fastest.
    pub(crate) band_rows: u32,
    /// The times so far: filter, shade, raster.
    pub times: DrawTimes,
}

impl BandWork {
    /// The canvas alone, when the work is given up.
    pub fn into_canvas(self) -> Canvas {
        self.canvas
    }

    /// The other shares' stripes of this share's bands, `others`, added to
    /// its own hair over the head: each band, top to bottom, as its rows
    /// and their finished 8-bit sRGB pixels (the same bytes as those rows
    /// of the whole picture drawn in one process) with what drawing it
    /// here took; the times, and the canvas, to give back to the share
    /// (whatever the outcome). Refuses stripes of another kind
    /// than the plan's, of rows that are not this share's bands, or that
    /// bring one group of strands twice to a band.
    #[allow(clippy::type_complexity)]
    pub fn resolve(
        self,
        others: Vec<Stripe>,
    ) -> (Result<(Vec<ResolvedBand>, DrawTimes), EngineError>, Canvas) {
        let t = Instant::now();
        let BandWork {
            mut canvas,
            own,
            mine,
            background,
            band_rows,
            mut times,
        } = self;
        let wrong = |what: &str| EngineError::executor(format!("a band's stripes: {what}"));
        let mut binned = vec![0.0; own.len()];
        let layers = match mine {
            Own::Layer(mine) => {
                let mut layers = Vec::with_capacity(others.len() + 1);
                for s in others {
                    match s {
                        Stripe::Layer(l) => layers.push(l),
                        Stripe::Segments(_) => {
                            return (Err(wrong("segments in a sort-last round")), canvas);
                        }
                    }
                }
                layers.extend(mine);
                Some(layers)
            }
            Own::Segments(mine) => {
                let mut all = mine;
                for s in others {
                    match s {
                        Stripe::Segments(s) => all.push(s),
                        Stripe::Layer(_) => {
                            return (
                                Err(wrong("a partial picture in a sort-middle round")),
                                canvas,
                            );
                        }
                    }
                }
                if let Err(e) = check_segments(&all, &own) {
                    return (Err(wrong(&e)), canvas);
                }
                // Every strand of the bands drawn here, group after group;
                // the binning counted to the band it is for.
                all.sort_by_key(|s| (s.first_group(), s.rows().start));
                canvas.clear_hair();
                canvas.set_band_rows(band_rows);
                for s in &all {
                    let t = Instant::now();
                    if let Err(e) = canvas.draw_segments(s) {
                        return (Err(EngineError::from(e)), canvas);
                    }
                    if let Some(b) = own.iter().position(|r| *r == s.rows()) {
                        binned[b] += ms(t);
                    }
                }
                None
            }
        };
        let out = own
            .into_iter()
            .zip(binned)
            .map(|(rows, binned)| {
                let t = Instant::now();
                let rgb = match &layers {
                    Some(layers) => canvas.resolve_layer_rows(background, layers, rows.clone()),
                    None => canvas.resolve_rows(background, &[], rows.clone()),
                };
                ResolvedBand {
                    rows,
                    rgb,
                    ms: binned + ms(t),
                }
            })
            .collect();
        times.composite_ms = ms(t);
        (Ok((out, times)), canvas)
    }
}

/// A band of finished rows.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedBand {
    /// Its rows.
    pub rows: Range<u32>,
    /// Their 8-bit sRGB pixels, row after row.
    pub rgb: Vec<u8>,
    /// What drawing the band here took, ms: binning what the others sent
    /// of it and resolving it (the cost the next frame's bands are cut by,
    /// [`BandPlan::weighted`]).
    pub ms: f64,
}

/// Checks that segments `all` are of rows `own` alone, each group of
/// strands at most once per band.
fn check_segments(all: &[BandSegments], own: &[Range<u32>]) -> Result<(), String> {
    for rows in own {
        let mut groups: Vec<(u32, u32)> = all
            .iter()
            .filter(|s| s.rows() == *rows)
            .filter_map(|s| Some((s.first_group()?, s.last_group()?)))
            .collect();
        groups.sort_unstable();
        if groups.windows(2).any(|g| g[1].0 <= g[0].1) {
            return Err(format!("groups of strands come twice to rows {rows:?}"));
        }
    }
    match all.iter().find(|s| !own.contains(&s.rows())) {
        Some(s) => Err(format!(
            "segments of rows {:?}, not a band of this worker",
            s.rows()
        )),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(plan: &BandPlan, height: u32, bands: usize) {
        assert_eq!(plan.bands(), bands, "{:?}", plan.cuts);
        plan.check(height).unwrap();
    }

    #[test]
    fn bands_cut_by_cost_share_it_evenly_on_whole_bands() {
        // Even costs: the bands of 48 rows that dealing gives.
        let even = BandPlan::weighted(720, &[1.0; 45], &[], 15, 3, 0).unwrap();
        check(&even, 720, 15);
        assert_eq!(even.cuts, BandPlan::dealt(720, 48, 3, 0).cuts);
        // Hair in rows 320..400 alone: thin bands there, wide elsewhere,
        // every band's cost within one unit's of the mean.
        let mut cost = vec![0.0; 45];
        cost[20..25].iter_mut().for_each(|c| *c = 10.0);
        let plan = BandPlan::weighted(720, &cost, &[], 8, 2, 1).unwrap();
        check(&plan, 720, 8);
        let rows_in = |b: usize| plan.rows(b).len() as u32;
        let narrow = (0..8).filter(|&b| plan.rows(b).start >= 320 && plan.rows(b).end <= 400);
        assert!(narrow.clone().count() >= 4, "{:?}", plan.cuts);
        assert!(narrow.map(rows_in).all(|r| r <= 32), "{:?}", plan.cuts);
        // More bands than rows of 16: one each; a short last band.
        let short = BandPlan::weighted(56, &[1.0, 0.0, 5.0, 1.0], &[], 8, 3, 2).unwrap();
        assert_eq!(short.cuts, vec![0, 16, 32, 48, 56]);
        check(&short, 56, 4);
        // Costs that do not fit the picture, or are not numbers.
        assert!(BandPlan::weighted(720, &[1.0; 44], &[], 15, 3, 0).is_none());
        assert!(BandPlan::weighted(56, &[1.0, f64::NAN, 1.0, 1.0], &[], 2, 2, 0).is_none());
        assert!(BandPlan::weighted(56, &[1.0; 4], &[], 0, 2, 0).is_none());
    }

    #[test]
    fn a_worker_given_a_smaller_share_gets_bands_of_less_cost() {
        // Even rows, three workers, 15 bands; worker 0 busy with its own
        // strands: a fifth of the rows' cost, the others two fifths each.
        let shares = [0.2, 0.4, 0.4];
        let plan = BandPlan::weighted(720, &[1.0; 45], &shares, 15, 3, 0).unwrap();
        check(&plan, 720, 15);
        let rows = |w: usize| -> u32 { plan.rows_of(w).iter().map(|r| r.len() as u32).sum() };
        // 45 units of 16 rows: worker 0 about 9 (144 rows), the others
        // about 18 (288), each within a unit a band.
        assert!((rows(0) as i32 - 144).abs() <= 5 * 16, "{:?}", plan.cuts);
        assert!(
            rows(1) > rows(0) + 64 && rows(2) > rows(0) + 64,
            "{:?}",
            plan.cuts
        );
        assert_eq!(rows(0) + rows(1) + rows(2), 720);
        // Shares that are not one a worker, or not positive: even.
        let even = BandPlan::weighted(720, &[1.0; 45], &[], 15, 3, 0).unwrap();
        for bad in [&[0.5, 0.5][..], &[0.2, f64::NAN, 0.4], &[0.0, 0.5, 0.5]] {
            let p = BandPlan::weighted(720, &[1.0; 45], bad, 15, 3, 0).unwrap();
            assert_eq!(p.cuts, even.cuts);
        }
        // Shares need not sum to one.
        let scaled = BandPlan::weighted(720, &[1.0; 45], &[1.0, 2.0, 2.0], 15, 3, 0).unwrap();
        assert_eq!(scaled.cuts, plan.cuts);
    }
}
