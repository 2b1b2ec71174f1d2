//! The executor boundary: where a frame's parallel work runs.
//!
//! Every stage whose work grows with the hair can run away from the frame
//! pipeline, each on any share of its input: the simulation of the wisps
//! (any share of wisps), the filling of the density map (any share of
//! strands) and its sweep (any share of columns), and, for an executor
//! that holds the drawn hair itself ([`Executor::drawing`]: cluster workers),
//! the pose, filter, shade and rasterization of whole groups of strands
//! (see [`crate::Groups`]). [`LocalExecutor`] runs the first three in this
//! process and leaves the rest to the frame, which runs the same stage
//! code ([`crate::HairPart`]) on all the hair; either way the pictures are
//! the same bytes.

use glam::{Affine3A, Vec3};
use raster::{Camera, HairLayer, HairLook, Shading};
use shadow::{DensityMap, Extent, Fiber, FillStats, Light, Transmittance};
use sim::Body;
use strands::{Bounds, Hair};

use crate::{Animator, EngineError, FrameStats, Stage};

/// One frame's worth of simulation steps of every wisp (or one settling
/// frame's), then the pose of the drawn hair.
#[derive(Debug, Clone, PartialEq)]
pub struct StepPlan {
    /// The head transform at the end of each step.
    pub heads: Vec<Affine3A>,
    /// The bodies the guides collide with at each step (each empty without
    /// body collisions).
    pub bodies: Vec<Vec<Body>>,
    /// The self-collision acceleration at every guide point of every wisp,
    /// wisp after wisp, scene units/s^2: sampled once from the previous
    /// frame's density map and held through the frame's steps. `None`
    /// without self-collisions.
    pub accel: Option<Vec<Vec3>>,
    /// The pose of the drawn hair after the steps.
    pub pose: PosePlan,
}

/// How the drawn hair is posed in a frame, and what the frame needs to
/// know of it when it is posed elsewhere.
#[derive(Debug, Clone, PartialEq)]
pub struct PosePlan {
    /// The head transform the hair is posed under.
    pub head: Affine3A,
    /// The sample of an animated groom file the rest hair is taken from
    /// ([`crate::Animator::sample_at`]; 0 for other hair).
    pub sample: u32,
    /// Simulated hair: bodies the drawn points are pushed out of (empty:
    /// not pushed).
    pub drawn_bodies: Vec<Body>,
    /// The pose counter the drawn hair has once posed;
    /// [`Executor::density`] is told it again.
    pub version: u64,
    /// The lights whose map extents are measured, from `anchor`.
    pub lights: Vec<Light>,
    /// The point extents are measured from.
    pub anchor: Vec3,
}

/// What the frame needs of drawn hair posed wherever it is: its bounds
/// (for framing the camera) and its extent along each light's map axes
/// (for fitting the maps). Reports of shares of the hair combine exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseReport {
    /// The posed hair's box.
    pub bounds: Bounds,
    /// Its extent along each light's map axes, in the plan's order.
    pub extents: Vec<Extent>,
}

impl PoseReport {
    /// The report of `hair` as `plan` posed it.
    pub fn of(hair: &Hair, plan: &PosePlan) -> PoseReport {
        PoseReport {
            bounds: hair.bounds(),
            extents: plan
                .lights
                .iter()
                .map(|l| Extent::of(l, plan.anchor, hair.points()))
                .collect(),
        }
    }

    /// The report of both shares.
    pub fn union(self, o: &PoseReport) -> PoseReport {
        PoseReport {
            bounds: self.bounds.union(o.bounds),
            extents: self
                .extents
                .iter()
                .zip(&o.extents)
                .map(|(a, b)| a.union(*b))
                .collect(),
        }
    }
}

/// The inputs of the per-vertex stages (filter, shade) and of the
/// rasterization, for drawn hair held elsewhere.
#[derive(Debug, Clone, PartialEq)]
pub struct DrawJob {
    /// The hair version to draw: the one posed last.
    pub version: u64,
    /// The camera.
    pub camera: Camera,
    /// How hair is drawn (colour, alpha, width).
    pub look: HairLook,
    /// Kajiya-Kay settings (the highlight off when the effect is).
    pub shading: Shading,
    /// The lights, in order (each vertex is lit from its own direction
    /// with the light's falloff there).
    pub lights: Vec<shadow::Light>,
    /// Whether the lights' transmittance is looked up at every vertex;
    /// otherwise it is 1.
    pub shadows: bool,
    /// Whether the filter stage interpolates the transmittance trilinearly
    /// or takes the cell's value (the scene's `shadow.filter`).
    pub trilinear: bool,
    /// The head transform: hair behind the head is hidden.
    pub head: Affine3A,
    /// Fragments of a pixel composited front to back
    /// ([`raster::Canvas::set_nearest`]).
    pub nearest: u32,
}

/// The rest of a picture being finished elsewhere: see
/// [`Drawing::draw_ahead`].
pub struct PendingPicture(Box<dyn FnOnce() -> Result<image::RgbImage, EngineError> + Send>);

impl PendingPicture {
    /// A picture `finish` completes.
    pub fn new(
        finish: impl FnOnce() -> Result<image::RgbImage, EngineError> + Send + 'static,
    ) -> PendingPicture {
        PendingPicture(Box::new(finish))
    }

    /// Waits for the finished picture.
    pub fn wait(self) -> Result<image::RgbImage, EngineError> {
        (self.0)()
    }
}

impl std::fmt::Debug for PendingPicture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PendingPicture")
    }
}

/// What drawing elsewhere gave: the partial pictures to composite here,
/// or the finished picture, or the promise of it.
#[derive(Debug)]
pub enum Drawn {
    /// Partial pictures, one per share, to composite on the head drawn
    /// here.
    Layers(Vec<HairLayer>),
    /// The finished picture, head and background included, composited
    /// where the hair is (see [`Drawing::composites`]).
    Picture(image::RgbImage),
    /// The finished picture still on its way (see [`Drawing::draw_ahead`]).
    Pending(PendingPicture),
}

impl Default for Drawn {
    /// No partial pictures yet.
    fn default() -> Drawn {
        Drawn::Layers(Vec::new())
    }
}

/// What drawing elsewhere gave, and the slowest share's milliseconds of
/// each stage.
#[derive(Debug, Default)]
pub struct DrawReport {
    /// The partial pictures, or the picture.
    pub drawn: Drawn,
    /// The filter stage, ms.
    pub filter_ms: f64,
    /// Shading, ms.
    pub shade_ms: f64,
    /// Rasterization, ms.
    pub raster_ms: f64,
    /// Compositing where the hair is: waiting for the other shares'
    /// stripes, and resolving a band.
    pub wait_ms: f64,
    /// Resolving the band, ms.
    pub composite_ms: f64,
}

/// The hair a density map is filled from.
#[derive(Debug, Clone, Copy)]
pub enum Strands<'a> {
    /// Hair in this process. `posed` is its pose counter when it was posed
    /// after [`Executor::simulate`] with a plan of that version (an
    /// executor that holds the same hair elsewhere may fill from there),
    /// `None` for any other hair.
    Here {
        /// The strands.
        hair: &'a Hair,
        /// Its pose counter, if posed through the executor.
        posed: Option<u64>,
    },
    /// The hair the executor's [`Drawing`] part holds, posed there at
    /// this counter by [`Drawing::pose`].
    Held {
        /// Its pose counter.
        posed: u64,
    },
}

/// Where a frame's drawn hair is posed, filtered, shaded and rasterized:
/// decided once, at the start of the frame ([`Executor::plan_frame`]), and
/// held by every stage of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Site {
    /// In this process: the frame poses the drawn hair here and draws it.
    #[default]
    Here,
    /// Where the executor's [`Drawing`] part holds the hair.
    Elsewhere,
}

/// What a frame cost its caller: the wall time of the call that rendered
/// it ([`crate::Sequence::next_frame`]): its drawing, and the next
/// frame's stages that ran beside its picture (or, for the first frame,
/// its own stages too).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTime {
    /// The frame's index.
    pub index: u64,
    /// Milliseconds.
    pub ms: f64,
}

/// What a frame being planned asks of its executor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameNeeds {
    /// The frame's index.
    pub index: u64,
    /// The last frame rendered since the previous plan, and what it cost
    /// (a frame's cost is known a frame or two after it is planned, as
    /// the next frame's stages run beside its picture).
    pub finished: Option<FrameTime>,
    /// The frame makes a picture; `false`: its motion alone (a frame
    /// skipped before a range), whose time says nothing of a scheme's.
    pub picture: bool,
    /// The drawn hair may be held elsewhere: no shadow method needs all
    /// of it in this process ([`shadow::MethodConfig::needs_all_hair`]).
    pub may_draw_elsewhere: bool,
}

/// Where the stages that grow with the hair run. Implementations must give
/// exactly the results of [`LocalExecutor`] and the frame's own stages.
pub trait Executor: Send + Sync + std::fmt::Debug {
    /// Plans the next frame: where its drawn hair is held and drawn. Asked
    /// once at the start of each frame; the executor holds to the answer
    /// until it is asked again (a cluster that loses a worker in the middle
    /// of a frame finishes the frame where it was planned, and plans the
    /// next one anew). A [`Site::Elsewhere`] answer needs a
    /// [`Self::drawing`] part. The default: elsewhere whenever the
    /// executor has a drawing part and the frame may.
    fn plan_frame(&mut self, needs: FrameNeeds) -> Site {
        if needs.may_draw_elsewhere && self.drawing().is_some() {
            Site::Elsewhere
        } else {
            Site::Here
        }
    }
    /// Learns the scene's hair before any frame: its groups and the state
    /// of its wisps (an executor that holds shares of the hair elsewhere
    /// hands them out from these).
    fn attach(&mut self, anim: &Animator) -> Result<(), EngineError> {
        let _ = anim;
        Ok(())
    }
    /// Runs `plan`'s steps on every wisp of `anim` and leaves the stepped
    /// state in `anim`. An executor that holds the drawn hair may pose it
    /// too, as `plan.pose` says, and return the pose's report (the
    /// frame keeps it, and does not ask [`Drawing::pose`]); `None`: not
    /// posed.
    fn simulate(
        &mut self,
        anim: &mut Animator,
        plan: &StepPlan,
        stats: &mut FrameStats,
    ) -> Result<Option<PoseReport>, EngineError>;
    /// Stage 1, density: adds the density of every strand of `strands` to
    /// `map` (empty, in its frame) for light `light`.
    fn density(
        &mut self,
        light: usize,
        map: &mut DensityMap,
        strands: Strands<'_>,
        fiber: &Fiber,
    ) -> Result<FillStats, EngineError>;
    /// Stage 2, transmittance: sweeps every column of `map` (paper 4.2).
    fn transmittance(
        &mut self,
        light: usize,
        map: &DensityMap,
    ) -> Result<Transmittance, EngineError>;
    /// Whether the stages run away from this process's cores (on remote
    /// workers). When the frame is drawn here, the next frame's stages then
    /// run while it is rasterized ([`crate::Sequence::expect_frames`]);
    /// `false` (the default): they would share the cores the drawing uses,
    /// and run after it.
    fn runs_elsewhere(&self) -> bool {
        false
    }
    /// The executor's drawing part, when it can hold the drawn hair and
    /// pose, filter, shade and rasterize it where it is; `None` (the
    /// default): the frame does, in this process. Used by frames planned
    /// [`Site::Elsewhere`] alone (and to draw such a frame again).
    fn drawing(&mut self) -> Option<&mut dyn Drawing> {
        None
    }
}

/// The part of an executor that holds the drawn hair: it poses it,
/// filters the transmittance at its vertices, shades and rasterizes it
/// where it is.
pub trait Drawing: Send + Sync {
    /// Whether [`Self::draw`] will most likely return the finished picture,
    /// composited where the hair is, head included (so this process need
    /// not draw the head); a report without one is composited here.
    fn composites(&self) -> bool;
    /// Poses the drawn hair as `plan` says, where it is held (after the
    /// simulation's steps, if any), and reports on it.
    fn pose(&mut self, plan: &PosePlan) -> Result<PoseReport, EngineError>;
    /// Filters the transmittance of the last [`Executor::transmittance`] of every
    /// light at the drawn vertices, shades them and rasterizes them, where
    /// they are held: one partial picture per share, or the picture.
    fn draw(&mut self, job: &DrawJob) -> Result<DrawReport, EngineError>;
    /// [`Self::draw`], free to return once the hair is rasterized and
    /// before its picture is finished ([`Drawn::Pending`]), while the
    /// caller runs the next frame's stages through the executor. When the
    /// pending picture fails, [`Self::redraw`] draws the frame of `job`
    /// again.
    fn draw_ahead(&mut self, job: &DrawJob) -> Result<DrawReport, EngineError> {
        self.draw(job)
    }
    /// Draws the frame of `job` again after its pending picture failed
    /// (whatever stages of later frames ran since), as partial pictures
    /// to composite here or as a finished picture.
    fn redraw(&mut self, job: &DrawJob) -> Result<DrawReport, EngineError> {
        self.draw(job)
    }
}

/// The simulation, the fill and the sweep in this process, on all threads;
/// the frame poses, filters, shades and draws.
#[derive(Debug, Default, Clone, Copy)]
pub struct LocalExecutor;

impl Executor for LocalExecutor {
    fn simulate(
        &mut self,
        anim: &mut Animator,
        plan: &StepPlan,
        stats: &mut FrameStats,
    ) -> Result<Option<PoseReport>, EngineError> {
        let all = 0..anim.wisp_count();
        step_wisps(anim, all, plan, plan.accel.as_deref(), stats);
        Ok(None)
    }

    fn density(
        &mut self,
        _light: usize,
        map: &mut DensityMap,
        strands: Strands<'_>,
        fiber: &Fiber,
    ) -> Result<FillStats, EngineError> {
        match strands {
            Strands::Here { hair, .. } => Ok(map.deposit(hair, 0..hair.strand_count(), fiber)),
            Strands::Held { .. } => Err(EngineError::executor(
                "this process holds the hair: no hair is held elsewhere",
            )),
        }
    }

    fn transmittance(
        &mut self,
        _light: usize,
        map: &DensityMap,
    ) -> Result<Transmittance, EngineError> {
        Ok(Transmittance::compute(map))
    }
}

/// `plan`'s steps on wisps `wisps` of `anim`: integration, then body
/// collisions, step after step. `accel` holds the self-collision
/// accelerations of those wisps' guide points (`plan.accel` is ignored).
/// The one implementation of a step, for this process and for a cluster
/// worker's share.
pub fn step_wisps(
    anim: &mut Animator,
    wisps: std::ops::Range<usize>,
    plan: &StepPlan,
    accel: Option<&[Vec3]>,
    stats: &mut FrameStats,
) {
    step_wisps_while(anim, wisps, plan, accel, stats, || true);
}

/// [`step_wisps`], stopping before any step when `go()` says no (a call
/// cancelled or past its deadline): whether every step ran.
pub fn step_wisps_while(
    anim: &mut Animator,
    wisps: std::ops::Range<usize>,
    plan: &StepPlan,
    accel: Option<&[Vec3]>,
    stats: &mut FrameStats,
    go: impl Fn() -> bool,
) -> bool {
    for (head, bodies) in plan.heads.iter().zip(&plan.bodies) {
        if !go() {
            return false;
        }
        stats.time(Stage::Simulate, || {
            anim.integrate(wisps.clone(), head, accel)
        });
        if !bodies.is_empty() {
            stats.time(Stage::BodyCollide, || {
                anim.collide(wisps.clone(), head, bodies)
            });
        }
        stats.steps += 1;
    }
    true
}
