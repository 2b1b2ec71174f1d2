//! The hair of a scene over time: simulated wisps, or hair carried rigidly
//! by the head.

use std::ops::Range;

use glam::{Affine3A, Vec3};
use rayon::prelude::*;
use sim::{Body, ForceField, HairSim, Motion, SimParams, WispState};
use strands::{Hair, WispModel, resample_into};

use crate::hair::build_hair_at;
use crate::{EngineError, HairSource, Scene};

/// Where the drawn hair of each frame comes from.
#[derive(Debug)]
enum Source {
    /// The hair at rest, moved by the head's transform.
    Rigid { rest: Hair },
    /// Wisps simulated through their guides; drawn strands are
    /// interpolated from the guides and Catmull-Rom smoothed.
    Wisps {
        model: WispModel,
        sim: Box<HairSim>,
        control: Hair,
        subdivide: u32,
    },
}

/// The drawn hair of one scene, frame after frame.
#[derive(Debug)]
pub struct Animator {
    motion: Motion,
    /// The head's centre at rest: the motion turns about it.
    pivot: Vec3,
    /// Seconds per frame.
    frame_dt: f32,
    /// Simulation steps per frame: the scene's time step, rounded so that a
    /// frame holds a whole number of steps.
    substeps: u32,
    /// Frames' worth of steps simulated at the first pose before frame 0.
    settle_frames: u32,
    source: Source,
    hair: Hair,
    /// The head transform the drawn hair is posed under.
    head: Affine3A,
    groups: Groups,
    /// An animated groom file whose frames follow its samples.
    cache: Option<Cache>,
}

/// An animated groom file (Alembic, USD) the rest hair is read from, a
/// sample a frame.
#[derive(Debug)]
struct Cache {
    /// The scene, whose hair file is read again at each sample.
    scene: Box<Scene>,
    /// The file's samples.
    samples: u32,
    /// The sample the rest hair is now.
    sample: u32,
}

/// How many groups the drawn hair is drawn in (see [`Groups`]).
pub const GROUPS: usize = 6;

/// The fixed partition of the drawn hair into groups of whole strands
/// (and, for simulated hair, of whole wisps): the unit in which hair is
/// shared out to cluster workers, and in which the canvas sums fragments
/// in floats before adding groups exactly. Any share of whole groups,
/// drawn anywhere, composites to the same bytes. Six groups share evenly
/// over 1, 2, 3 and 6 workers.
#[derive(Debug, Clone, PartialEq)]
pub struct Groups {
    /// Group `g` is drawn strands `strands[g]..strands[g + 1]`.
    pub strands: Vec<u32>,
    /// For simulated hair, group `g` is wisps `wisps[g]..wisps[g + 1]`.
    pub wisps: Option<Vec<u32>>,
}

impl Groups {
    /// Groups.
    pub fn count(&self) -> usize {
        self.strands.len() - 1
    }

    /// The drawn strands of groups `groups`.
    pub fn strand_range(&self, groups: Range<usize>) -> Range<usize> {
        self.strands[groups.start] as usize..self.strands[groups.end] as usize
    }

    /// The wisps of groups `groups` (empty for hair that is not simulated).
    pub fn wisp_range(&self, groups: Range<usize>) -> Range<usize> {
        match &self.wisps {
            Some(w) => w[groups.start] as usize..w[groups.end] as usize,
            None => 0..0,
        }
    }

    /// The group boundaries inside groups `groups`, as strand indices from
    /// their first strand: what [`raster::Canvas::draw_hair`] takes for
    /// those strands alone.
    pub fn within(&self, groups: Range<usize>) -> Vec<u32> {
        let first = self.strands[groups.start];
        self.strands[groups.start..=groups.end]
            .iter()
            .map(|&s| s - first)
            .collect()
    }
}

/// Cuts `0..len` into `parts` contiguous ranges whose `weight` sums are
/// about equal (a range may be empty).
pub fn split_by(len: usize, parts: usize, weight: impl Fn(usize) -> u64) -> Vec<Range<usize>> {
    let total: u64 = (0..len).map(&weight).sum();
    let mut out = Vec::with_capacity(parts);
    let (mut start, mut acc, mut i) = (0, 0u64, 0);
    for p in 1..=parts {
        let goal = total * p as u64 / parts as u64;
        while i < len && (acc < goal || p == parts) {
            acc += weight(i);
            i += 1;
        }
        out.push(start..i);
        start = i;
    }
    out
}

impl Animator {
    /// The scene's hair at time 0, at rest.
    pub fn new(scene: &Scene) -> Result<Animator, EngineError> {
        let (rest, samples) = build_hair_at(scene, None)?;
        let motion = scene.animation.motion.clone();
        let frame_dt = 1.0 / scene.animation.fps;
        let substeps = scene.dynamics.steps_per_frame(scene.animation.fps);
        let pivot = match (&scene.head, &scene.hair) {
            (Some(h), _) => h.center,
            (None, HairSource::Style(p)) => p.head_center,
            (None, HairSource::File { .. } | HairSource::Inline(_)) => {
                let b = rest.bounds();
                if b.is_empty() { Vec3::ZERO } else { b.center() }
            }
        };
        let simulate = scene.effects.dynamics && !motion.is_still();
        let source = match &scene.hair {
            HairSource::Style(p) if simulate => {
                let model = WispModel::generate(p);
                let params = SimParams {
                    dt: frame_dt / substeps as f32,
                    ..scene.dynamics.params
                };
                let sim = HairSim::new(&model.guides, params)?;
                let control = model.interpolate();
                Source::Wisps {
                    model,
                    sim: Box::new(sim),
                    control,
                    subdivide: scene.subdivide,
                }
            }
            _ => Source::Rigid { rest: rest.clone() },
        };
        let settle_frames = (scene.dynamics.settle_s / frame_dt).ceil() as u32;
        let groups = match &source {
            Source::Wisps { model, .. } => {
                let mut per = vec![0u64; model.wisp_count()];
                for m in &model.members {
                    per[m.wisp as usize] += 1;
                }
                let g = GROUPS.min(per.len()).max(1);
                let wisps = split_by(per.len(), g, |w| per[w]);
                Groups {
                    strands: std::iter::once(0)
                        .chain(
                            wisps
                                .iter()
                                .map(|r| model.member_range(r.clone()).end as u32),
                        )
                        .collect(),
                    wisps: Some(
                        std::iter::once(0)
                            .chain(wisps.iter().map(|r| r.end as u32))
                            .collect(),
                    ),
                }
            }
            Source::Rigid { rest } => {
                let n = rest.strand_count();
                let g = GROUPS.min(n).max(1);
                let offsets = rest.offsets();
                let strands = split_by(n, g, |s| u64::from(offsets[s + 1] - offsets[s]) + 1);
                Groups {
                    strands: std::iter::once(0)
                        .chain(strands.iter().map(|r| r.end as u32))
                        .collect(),
                    wisps: None,
                }
            }
        };
        // A groom file of several samples, none fixed: its frames follow
        // them.
        let cache = match (&source, &scene.hair) {
            (Source::Rigid { .. }, HairSource::File { sample: None, .. }) if samples > 1 => {
                Some(Cache {
                    scene: Box::new(scene.clone()),
                    samples,
                    sample: 0,
                })
            }
            _ => None,
        };
        if let Some(c) = &cache {
            tracing::info!(
                samples = c.samples,
                "hair.file is an animated groom: frame k reads its sample k (the last past it)"
            );
        }
        let mut a = Animator {
            cache,
            head: motion.at(0.0, pivot),
            motion,
            pivot,
            frame_dt,
            substeps,
            settle_frames,
            source,
            hair: rest,
            groups,
        };
        a.pose();
        Ok(a)
    }

    /// The sample of the groom file frame `frame` is posed from: `frame`
    /// itself (the last sample past the last) for an animated groom whose
    /// frames follow its samples, else 0.
    pub fn sample_at(&self, frame: u64) -> u32 {
        self.cache
            .as_ref()
            .map_or(0, |c| frame.min(u64::from(c.samples - 1)) as u32)
    }

    /// Takes the rest hair from `sample` of the animated groom file (the
    /// next pose poses it); nothing for other hair. Its strands must be
    /// those of the first sample, point for point.
    pub fn set_sample(&mut self, sample: u32) -> Result<(), EngineError> {
        let (Some(c), Source::Rigid { rest }) = (&mut self.cache, &mut self.source) else {
            return Ok(());
        };
        if c.sample == sample {
            return Ok(());
        }
        let (hair, _) = build_hair_at(&c.scene, Some(sample))?;
        if hair.offsets() != rest.offsets() {
            return Err(EngineError::Topology {
                scene: c.scene.source.path.clone(),
                sample,
                strands: hair.strand_count(),
                points: hair.point_count(),
                first_strands: rest.strand_count(),
                first_points: rest.point_count(),
            });
        }
        *rest = hair;
        c.sample = sample;
        Ok(())
    }

    /// The drawn hair as last posed.
    pub fn hair(&self) -> &Hair {
        &self.hair
    }

    /// The guide strands as last posed, when the wisps are simulated.
    pub fn guides(&self) -> Option<&Hair> {
        match &self.source {
            Source::Wisps { model, .. } => Some(&model.guides),
            Source::Rigid { .. } => None,
        }
    }

    /// Whether the wisps are simulated (else the hair moves rigidly).
    pub fn simulates(&self) -> bool {
        matches!(self.source, Source::Wisps { .. })
    }

    /// Seconds between frames.
    pub fn frame_dt(&self) -> f32 {
        self.frame_dt
    }

    /// Simulation steps per frame.
    pub fn substeps(&self) -> u32 {
        self.substeps
    }

    /// Frames' worth of steps simulated before frame 0.
    pub fn settle_frames(&self) -> u32 {
        self.settle_frames
    }

    /// The head transform at time `t` (seconds).
    pub fn head_at(&self, t: f32) -> Affine3A {
        self.motion.at(t, self.pivot)
    }

    /// The head transform the drawn hair is posed under.
    pub fn head(&self) -> Affine3A {
        self.head
    }

    /// Wisps simulated (0 for rigid hair).
    pub fn wisp_count(&self) -> usize {
        match &self.source {
            Source::Wisps { sim, .. } => sim.wisp_count(),
            Source::Rigid { .. } => 0,
        }
    }

    /// Guide points per wisp (0 for rigid hair).
    pub fn points_per_wisp(&self) -> usize {
        match &self.source {
            Source::Wisps { sim, .. } => sim.points_per_wisp(),
            Source::Rigid { .. } => 0,
        }
    }

    /// The acceleration of `field` at every guide point of every wisp,
    /// wisp after wisp (self-collisions, sampled where the hair is now).
    pub fn sample_field(&self, field: &dyn ForceField) -> Vec<Vec3> {
        let mut accel = Vec::new();
        if let Source::Wisps { sim, .. } = &self.source {
            sim.sample_field(0..sim.wisp_count(), field, &mut accel);
        }
        accel
    }

    /// One time step of wisps `wisps` with the roots on `head`, under
    /// `accel` (one acceleration per guide point of those wisps) if given.
    pub fn integrate(&mut self, wisps: Range<usize>, head: &Affine3A, accel: Option<&[Vec3]>) {
        if let Source::Wisps { sim, .. } = &mut self.source {
            sim.integrate(wisps, head, accel);
        }
    }

    /// Keeps wisps `wisps` out of `bodies`.
    pub fn collide(&mut self, wisps: Range<usize>, head: &Affine3A, bodies: &[Body]) {
        if let Source::Wisps { sim, .. } = &mut self.source {
            sim.collide(wisps, head, bodies);
        }
    }

    /// Wisp `w`'s state, when the wisps are simulated.
    pub fn wisp_state(&self, w: usize) -> Option<&WispState> {
        match &self.source {
            Source::Wisps { sim, .. } if w < sim.wisp_count() => Some(sim.wisp(w)),
            _ => None,
        }
    }

    /// Replaces wisp `w`'s state (simulated on another machine). The drawn
    /// hair changes at the next pose.
    pub fn set_wisp_state(&mut self, w: usize, state: WispState) -> Result<(), EngineError> {
        match &mut self.source {
            Source::Wisps { sim, .. } if w < sim.wisp_count() => Ok(sim.set_wisp(w, state)?),
            _ => Err(EngineError::executor(format!(
                "wisp {w} is not a simulated wisp of this scene"
            ))),
        }
    }

    /// The fixed groups the drawn hair is drawn in.
    pub fn groups(&self) -> &Groups {
        &self.groups
    }

    /// A point near the hair under head transform `head`, from which map
    /// extents are measured (precision for hair far from the origin): the
    /// head's centre (or the rest hair's), moved with the head.
    pub fn anchor_at(&self, head: &Affine3A) -> Vec3 {
        head.transform_point3(self.pivot)
    }

    /// The drawn strands of groups `groups` alone, with their colours,
    /// under head transform `head`: posed from the simulated guides and
    /// pushed out of `bodies`, or the rest hair moved rigidly. The very
    /// points [`Self::set_head`] (and [`Self::collide_drawn`]) give those
    /// strands, for a share of the hair posed away from the rest.
    pub fn pose_part(&mut self, groups: Range<usize>, head: Affine3A, bodies: &[Body]) -> Hair {
        let mut out = Hair::new();
        self.pose_part_into(groups, head, bodies, &mut out, &mut Hair::new());
        out
    }

    /// [`Self::pose_part`] into `out`, with `control` the guides'
    /// interpolated strands before resampling: both reuse their memory
    /// when they hold these groups from an earlier pose (a share's next
    /// frame), as [`Self::set_head`] does for the whole hair; otherwise
    /// they are replaced. The same points.
    pub fn pose_part_into(
        &mut self,
        groups: Range<usize>,
        head: Affine3A,
        bodies: &[Body],
        out: &mut Hair,
        control: &mut Hair,
    ) {
        let strands = self.groups.strand_range(groups.clone());
        let wisps = self.groups.wisp_range(groups);
        match &mut self.source {
            Source::Rigid { rest } => {
                let offsets = rest.offsets();
                let (p0, p1) = (
                    offsets[strands.start] as usize,
                    offsets[strands.end] as usize,
                );
                let same = out.strand_count() == strands.len() && out.point_count() == p1 - p0;
                if !same {
                    let mut hair = Hair::with_capacity(strands.len(), p1 - p0);
                    for s in strands.clone() {
                        hair.push_strand(rest.strand(s))
                            .expect("the rest hair's points are finite");
                    }
                    if let Some(c) = rest.colors() {
                        hair.set_colors(c[strands].to_vec());
                    }
                    *out = hair;
                }
                // A rigid move of finite points is finite.
                out.points_mut()
                    .par_chunks_mut(4096)
                    .zip(rest.points()[p0..p1].par_chunks(4096))
                    .for_each(|(o, src)| {
                        for (o, &p) in o.iter_mut().zip(src) {
                            *o = head.transform_point3(p);
                        }
                    });
            }
            Source::Wisps {
                model,
                sim,
                subdivide,
                ..
            } => {
                sim.write_guides(&mut model.guides);
                let members = model.member_range(wisps);
                model.interpolate_members_into(members.clone(), control);
                if control.colors().is_none() {
                    control.set_colors(model.colors[members].to_vec());
                }
                strands::resample_into(control, *subdivide, out);
                if !bodies.is_empty() {
                    push_out_all(out, bodies);
                }
            }
        }
    }

    /// Pushes the drawn points of simulated hair out of `bodies`: strands
    /// interpolated between guides that wrap around a sphere can cut into
    /// it even though the guides stay out.
    pub fn collide_drawn(&mut self, bodies: &[Body]) {
        if bodies.is_empty() || !self.simulates() {
            return;
        }
        push_out_all(&mut self.hair, bodies);
    }

    /// Sets the head to `head` and poses the drawn hair: interpolated from
    /// the simulated guides and smoothed, or the rest hair moved rigidly.
    pub fn set_head(&mut self, head: Affine3A) {
        self.head = head;
        self.pose();
    }

    fn pose(&mut self) {
        match &mut self.source {
            Source::Rigid { rest } => {
                let head = self.head;
                self.hair
                    .points_mut()
                    .par_chunks_mut(4096)
                    .zip(rest.points().par_chunks(4096))
                    .for_each(|(out, src)| {
                        for (o, &p) in out.iter_mut().zip(src) {
                            *o = head.transform_point3(p);
                        }
                    });
            }
            Source::Wisps {
                model,
                sim,
                control,
                subdivide,
            } => {
                sim.write_guides(&mut model.guides);
                model.interpolate_into(control);
                resample_into(control, *subdivide, &mut self.hair);
            }
        }
    }

    /// The largest relative deviation of any guide link from its rest
    /// length (0 for rigid hair).
    pub fn max_stretch(&self) -> f32 {
        match &self.source {
            Source::Wisps { sim, .. } => sim.max_stretch(),
            Source::Rigid { .. } => 0.0,
        }
    }
}

/// Pushes every point of `hair` out of `bodies`.
fn push_out_all(hair: &mut Hair, bodies: &[Body]) {
    hair.points_mut()
        .par_chunks_mut(4096)
        .for_each(|pts| pts.iter_mut().for_each(|p| sim::push_out(p, bodies)));
}
#[cfg(test)]
mod tests {
    use super::split_by;

    #[test]
    fn splits_cover_everything_in_order_and_balance_weight() {
        for (len, parts) in [(0, 3), (1, 3), (10, 3), (100, 1), (7, 7)] {
            let s = split_by(len, parts, |i| (i % 5) as u64 + 1);
            assert_eq!(s.len(), parts);
            assert_eq!(s[0].start, 0);
            assert_eq!(s[parts - 1].end, len);
            assert!(s.windows(2).all(|w| w[0].end == w[1].start));
        }
        let s = split_by(90, 3, |_| 1);
        assert_eq!(s, vec![0..30, 30..60, 60..90]);
    }
}
