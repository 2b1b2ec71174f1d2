//! A share of a scene's hair, held away from the frame pipeline (a cluster
//! worker's): whole groups of strands (and their wisps), stepped, posed,
//! filled into density maps, filtered, shaded and rasterized into a partial
//! picture where they are, by the same stage code as in one process.

use std::ops::Range;
use std::time::Instant;

use glam::Vec3;
use raster::{Canvas, HairLayer};

use crate::bands::{BandPlan, BandWork, Own, Sort, Stripe};
use crate::bounce::HairIn;
use crate::stats::{DrawTimes, ms};
use shadow::{DensityMap, Fiber, FillStats, LightFrame, Transmittance};
use strands::Hair;

use crate::part::{HeadPoint, Seen, draw_head, head_lambert};
use crate::pipeline::surface_transmittance;
use crate::{
    Animator, DrawJob, EngineError, FrameStats, HairPart, Head, PosePlan, PoseReport, Scene,
    StepPlan, step_wisps, step_wisps_while,
};

/// Whole groups `groups` of a scene's drawn hair (see [`crate::Groups`]).
#[derive(Debug)]
pub struct Share {
    anim: Animator,
    groups: Range<usize>,
    head: Option<Head>,
    /// The share's drawn strands as last posed, and that hair's version.
    posed: Option<(u64, Hair)>,
    /// The guides' interpolated strands the last pose resampled (kept for
    /// their memory).
    control: Hair,
    part: HairPart,
    canvas: Option<Canvas>,
    /// What resolving a band of the picture needs of the scene.
    background: Vec3,
    head_shadow: bool,
    /// The fiber the head's light is scattered by, when the head lights
    /// the hair ([`crate::bounce`]).
    head_optics: Option<raster::FiberOptics>,
    /// The scene's picture, width and height in pixels: the only size a
    /// Draw of it may ask for.
    picture: (u32, u32),
}

impl Share {
    /// Groups `groups` of `scene`'s hair, at rest.
    pub fn new(scene: &Scene, groups: Range<usize>) -> Result<Share, EngineError> {
        let anim = Animator::new(scene)?;
        let n = anim.groups().count();
        if groups.start > groups.end || groups.end > n {
            return Err(EngineError::executor(format!(
                "groups {}..{} of a scene of {n}",
                groups.start, groups.end
            )));
        }
        let head = scene
            .head
            .as_ref()
            .map(|h| Head::load(h, scene))
            .transpose()?;
        Ok(Share {
            anim,
            groups,
            head,
            posed: None,
            control: Hair::new(),
            part: HairPart::default(),
            canvas: None,
            background: scene.render.background,
            head_shadow: scene.effects.head_shadow,
            head_optics: crate::part::head_optics(scene),
            picture: (scene.render.width, scene.render.height),
        })
    }

    /// The scene's picture size, pixels: width and height.
    pub fn picture_size(&self) -> (u32, u32) {
        self.picture
    }

    /// The scene's background colour (linear RGB).
    pub fn background(&self) -> Vec3 {
        self.background
    }

    /// The share's groups.
    pub fn groups(&self) -> Range<usize> {
        self.groups.clone()
    }

    /// The index of the share's first strand in the whole hair.
    fn first_strand(&self) -> u32 {
        self.anim.groups().strand_range(self.groups.clone()).start as u32
    }

    /// The share's wisps (empty for hair that is not simulated).
    pub fn wisps(&self) -> Range<usize> {
        self.anim.groups().wisp_range(self.groups.clone())
    }

    /// The scene's whole animator, of which the share steps its wisps.
    pub fn animator(&self) -> &Animator {
        &self.anim
    }

    /// The animator, to set the state of the share's wisps.
    pub fn animator_mut(&mut self) -> &mut Animator {
        &mut self.anim
    }

    /// `plan`'s steps on the share's wisps, with `accel` the self-collision
    /// accelerations of their guide points.
    pub fn step(&mut self, plan: &StepPlan, accel: Option<&[Vec3]>, stats: &mut FrameStats) {
        let wisps = self.wisps();
        step_wisps(&mut self.anim, wisps, plan, accel, stats);
    }

    /// [`Self::step`], stopping before any step when `go()` says no:
    /// whether every step ran (otherwise the wisps stand part-way).
    pub fn step_while(
        &mut self,
        plan: &StepPlan,
        accel: Option<&[Vec3]>,
        stats: &mut FrameStats,
        go: impl Fn() -> bool,
    ) -> bool {
        let wisps = self.wisps();
        step_wisps_while(&mut self.anim, wisps, plan, accel, stats, go)
    }

    /// Poses the share's strands as `plan` says and reports on them.
    pub fn pose(&mut self, plan: &PosePlan) -> Result<PoseReport, EngineError> {
        // An animated groom's frame: the rest hair of its sample.
        self.anim.set_sample(plan.sample)?;
        // The last pose's memory, reused: a new pose of a large share
        // would fault in tens of MB of fresh pages a frame.
        let mut hair = self.posed.take().map(|(_, h)| h).unwrap_or_default();
        self.anim.pose_part_into(
            self.groups.clone(),
            plan.head,
            &plan.drawn_bodies,
            &mut hair,
            &mut self.control,
        );
        let report = PoseReport::of(&hair, plan);
        self.posed = Some((plan.version, hair));
        Ok(report)
    }

    /// The share's strands as posed last, when they are hair `version`.
    pub fn posed(&self, version: u64) -> Result<&Hair, EngineError> {
        match &self.posed {
            Some((v, hair)) if *v == version => Ok(hair),
            Some((v, _)) => Err(EngineError::executor(format!(
                "the posed strands are hair version {v}, not {version}"
            ))),
            None => Err(EngineError::executor("no strands posed here yet")),
        }
    }

    /// Adds the density of the share's strands, posed as hair `version`,
    /// to `map`.
    pub fn deposit(
        &self,
        version: u64,
        map: &mut DensityMap,
        fiber: &Fiber,
    ) -> Result<FillStats, EngineError> {
        self.deposit_while(version, map, fiber, || true)
            .map(|s| s.unwrap_or_default())
    }

    /// [`deposit`](Self::deposit), asking `go` between runs of strands
    /// (see [`DensityMap::deposit_while`]): `Ok(None)` when it said stop.
    pub fn deposit_while(
        &self,
        version: u64,
        map: &mut DensityMap,
        fiber: &Fiber,
        go: impl Fn() -> bool,
    ) -> Result<Option<FillStats>, EngineError> {
        let hair = self.posed(version)?;
        Ok(map.deposit_while(hair, 0..hair.strand_count(), fiber, go))
    }

    /// Adds the head, under the head motion's transform `pose`, to `map`
    /// as an opaque occluder, as the frame's shadow stages add it to theirs
    /// (see [`shadow::DensityMapMethod::density_with`]): for a share that
    /// sweeps columns of a map summed where it is. False when the scene
    /// has no head.
    pub fn deposit_head(&mut self, map: &mut DensityMap, pose: glam::Affine3A) -> bool {
        let Some(head) = &mut self.head else {
            return false;
        };
        head.set_pose(pose);
        map.deposit_body(&head.occluder(), shadow::OPAQUE_DEPTH);
        true
    }

    /// The columns of a map in `frame` that filtering the share's strands
    /// posed as hair `version` reads (see [`shadow::columns_read`]).
    pub fn columns_read(
        &self,
        version: u64,
        frame: &LightFrame,
        filter: bool,
    ) -> Result<Vec<u64>, EngineError> {
        let hair = self.posed(version)?;
        if self.head_optics.is_some() && self.head.is_some() {
            // The head's light asks for the head's own points all round:
            // every column.
            let n = frame.columns();
            let mut all = vec![u64::MAX; n.div_ceil(64)];
            if !n.is_multiple_of(64)
                && let Some(last) = all.last_mut()
            {
                *last = (1u64 << (n % 64)) - 1;
            }
            return Ok(all);
        }
        Ok(shadow::columns_read(frame, hair.points(), filter))
    }

    /// Filters the transmittance of `maps` (one per light, holding at
    /// least [`Self::columns_read`]) at the share's vertices, shades them
    /// and rasterizes them behind the head: the share's partial picture.
    pub fn draw(
        &mut self,
        job: &DrawJob,
        maps: &[Transmittance],
    ) -> Result<(HairLayer, DrawTimes), EngineError> {
        let (canvas, mut times) = self.bin(job, maps, None)?;
        let t = Instant::now();
        let layer = canvas.layer();
        times.raster_ms += ms(t);
        Ok((layer, times))
    }

    /// [`Self::draw`], the partial picture handed to `emit` a stripe of
    /// `stripe_rows` rows at a time (rounded up to whole bands), top to
    /// bottom, each as soon as it is rasterized: a worker sends one stripe
    /// while it rasterizes the next, and the coordinator decodes it
    /// meanwhile. The stripes, appended, are [`Self::draw`]'s layer. An
    /// error from `emit` stops the drawing and is returned.
    pub fn draw_stripes(
        &mut self,
        job: &DrawJob,
        maps: &[Transmittance],
        stripe_rows: u32,
        mut emit: impl FnMut(HairLayer) -> Result<(), EngineError>,
    ) -> Result<DrawTimes, EngineError> {
        let (canvas, mut times) = self.bin(job, maps, None)?;
        let band = canvas.band_rows();
        let step = stripe_rows.max(1).div_ceil(band) * band;
        let mut y = 0;
        while y < canvas.height() {
            let t = Instant::now();
            let stripe = canvas.layer_rows(y..(y + step).min(canvas.height()));
            times.raster_ms += ms(t);
            emit(stripe)?;
            y += step;
        }
        Ok(times)
    }

    /// [`Self::draw`] drawn on the workers, as `plan` says, up to the
    /// compositing: what this share drew of each other worker's band
    /// handed to `send(worker, stripe)` as it is drawn, top to bottom (its
    /// partial picture of those rows, sort-last, or its shaded segments
    /// there, sort-middle), then this share's own bands drawn as far as
    /// they can be alone; [`BandWork::resolve`] finishes them with what
    /// the others sent, away from the share (which may meanwhile step and
    /// fill the next frame). The canvas goes with the work; hand it back
    /// with [`Self::put_canvas`].
    pub fn draw_band(
        &mut self,
        job: &DrawJob,
        maps: &[Transmittance],
        plan: &BandPlan,
        mut send: impl FnMut(usize, Stripe) -> Result<(), EngineError>,
    ) -> Result<BandWork, EngineError> {
        let height = job.camera.height();
        plan.check(height)?;
        let own = plan.rows_of(plan.own);
        let background = self.background;
        let first_group = self.groups.start as u32;
        let (_, mut times) = self.bin(job, maps, Some(plan))?;
        let canvas = self.canvas.take().expect("binned above");
        let take = |rows: Range<u32>| match plan.sort {
            Sort::Last => Stripe::Layer(canvas.layer_rows(rows)),
            Sort::Middle => Stripe::Segments(canvas.segments_rows(rows, first_group)),
        };
        let sent = (|| {
            for b in 0..plan.bands() {
                let to = plan.owner(b);
                if to == plan.own {
                    continue;
                }
                let t = Instant::now();
                let stripe = take(plan.rows(b));
                times.raster_ms += ms(t);
                send(to, stripe)?;
            }
            Ok(())
        })();
        if let Err(e) = sent {
            self.canvas = Some(canvas);
            return Err(e);
        }
        // This share's own bands, while the others' stripes travel.
        let t = Instant::now();
        let mine = match plan.sort {
            Sort::Last => {
                let mut mine: Option<HairLayer> = None;
                for rows in &own {
                    let l = canvas.layer_rows(rows.clone());
                    match &mut mine {
                        Some(all) => all.append_layer(l),
                        None => mine = Some(l),
                    }
                }
                Own::Layer(mine)
            }
            Sort::Middle => Own::Segments(
                own.iter()
                    .map(|rows| canvas.segments_rows(rows.clone(), first_group))
                    .collect(),
            ),
        };
        times.raster_ms += ms(t);
        // Every strand of the bands, for sort-middle: bands as tall as the
        // whole hair is dense (as one process draws it), whole in the plan's.
        let (w, h) = (job.camera.width(), job.camera.height());
        let groups = self.anim.groups();
        let all_strands = groups.strand_range(0..groups.count()).len().max(1);
        let own_strands = groups.strand_range(self.groups.clone()).len().max(1);
        let drawn = self
            .posed
            .as_ref()
            .map_or(0, |(_, hair)| hair.segment_count());
        let band_rows = plan.band_rows_within(Canvas::band_rows_for(
            w,
            h,
            drawn * all_strands / own_strands,
        ));
        Ok(BandWork {
            canvas,
            own,
            mine,
            background,
            band_rows,
            times,
        })
    }

    /// Gives back the canvas of a [`BandWork`], for the next draw.
    pub fn put_canvas(&mut self, canvas: Canvas) {
        if self.canvas.is_none() {
            self.canvas = Some(canvas);
        }
    }

    /// Filters, shades and bins the posed strands for `job`: the canvas
    /// they are binned on, ready to rasterize, and the times so far.
    fn bin(
        &mut self,
        job: &DrawJob,
        maps: &[Transmittance],
        shaded: Option<&BandPlan>,
    ) -> Result<(&Canvas, DrawTimes), EngineError> {
        let mut times = DrawTimes::default();
        let first_strand = self.first_strand();
        let hair = match &self.posed {
            Some((v, hair)) if *v == job.version => hair,
            _ => {
                return Err(EngineError::executor(format!(
                    "no strands posed here as hair version {}",
                    job.version
                )));
            }
        };
        // The fiber that scatters light on to the head, when the head
        // lights the hair.
        let forward = self
            .head_optics
            .filter(|_| job.shadows)
            .map(|o| self.part.dual_table(&o));
        if job.shadows {
            if maps.len() != job.lights.len() {
                return Err(EngineError::executor(format!(
                    "{} maps for {} lights",
                    maps.len(),
                    job.lights.len()
                )));
            }
            let t = Instant::now();
            self.part.filter(hair, maps.len(), |l, pts, out| {
                maps[l].filter(pts, job.trilinear, out)
            });
            // The head's light (see `Renderer::filter`).
            if let (Some(forward), Some(head)) = (&forward, &mut self.head)
                && !job.lights.is_empty()
            {
                head.set_pose(job.head);
                let head_shadow = self.head_shadow;
                let head = crate::part::head_light(
                    head,
                    &job.shading,
                    &job.lights,
                    forward,
                    Some(maps[0].frame()),
                    |l, x, n| {
                        if head_shadow {
                            surface_transmittance(&maps[l], x, n, job.trilinear)
                        } else {
                            1.0
                        }
                    },
                    HairIn::Swept(&maps[0], job.trilinear),
                );
                self.part.filter_head(hair, head);
            }
            times.filter_ms = ms(t);
        }
        let t = Instant::now();
        let seen = Seen {
            camera: &job.camera,
            look: &job.look,
            first_strand,
        };
        self.part
            .shade(hair, seen, &job.shading, &job.lights, job.shadows);
        times.shade_ms = ms(t);
        let t = Instant::now();
        let (w, h) = (job.camera.width(), job.camera.height());
        if !self
            .canvas
            .as_ref()
            .is_some_and(|c| c.width() == w && c.height() == h)
        {
            self.canvas = Some(Canvas::new(w, h)?);
        }
        let canvas = self.canvas.as_mut().expect("made above");
        canvas.clear();
        canvas.set_nearest(job.nearest as usize);
        // Bands as tall as this share's hair is dense, whole in the plan's;
        // sort-middle: the plan's own (its segments of a band are then one
        // bin, in order), and the head in this share's bands alone (the
        // only ones it rasterizes).
        let rows = Canvas::band_rows_for(w, h, hair.segment_count());
        let middle = shaded.filter(|plan| plan.sort == Sort::Middle);
        canvas.set_band_rows(match (middle, shaded) {
            (Some(plan), _) => plan.band_rows_within(64),
            (None, Some(plan)) => plan.band_rows_within(rows),
            (None, None) => rows,
        });
        canvas.set_opaque_rows(middle.map(|plan| plan.rows_of(plan.own)));
        // The head's depth hides the hair behind it; its colour matters
        // only in the rows `shaded` (a band this share resolves).
        if let Some(head) = &mut self.head {
            head.set_pose(job.head);
            let head_shadow = job.shadows && self.head_shadow;
            let (color, shading) = (head.settings().color, &job.shading);
            let (camera, part) = (&job.camera, &self.part);
            let shade = |p: Vec3, n: Vec3| {
                // The row of the pixel centre the point was found at.
                let row = camera.project(p).map_or(-1.0, |s| s.y.floor());
                let mine = row >= 0.0 && shaded.is_some_and(|b| b.owns_row(row as u32));
                if !mine {
                    return Vec3::ZERO;
                }
                let sky = part.sky_over_head(p).filter(|_| job.shadows);
                let at = HeadPoint { p, n, sky };
                head_lambert(color, shading, &job.lights, at, forward.as_deref(), |l| {
                    if head_shadow {
                        surface_transmittance(&maps[l], p, n, job.trilinear)
                    } else {
                        1.0
                    }
                })
            };
            draw_head(canvas, camera, head, shade);
        }
        let groups = self.anim.groups().within(self.groups.clone());
        self.part.draw(hair, seen, &groups, canvas);
        times.raster_ms = ms(t);
        Ok((canvas, times))
    }
}
