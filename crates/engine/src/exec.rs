//! The executor boundary: where a frame's parallel work runs.
//!
//! Three stages can run away from the frame pipeline, each on any share of
//! its input: the simulation of the wisps (any share of wisps), the filling
//! of the density map (any share of strands) and its sweep (any share of
//! columns). [`LocalExecutor`] runs them in this process; cluster mode's
//! executor runs them on workers. Everything else (posing the drawn hair,
//! filtering, shading, drawing) is the same code either way, so both give
//! the same bytes.

use glam::{Affine3A, Vec3};
use shadow::{DensityMap, Fiber, FillStats, Transmittance};
use sim::Body;
use strands::Hair;

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
    /// After the steps, the drawn hair is posed and pushed out of these
    /// bodies (empty: not pushed).
    pub drawn_bodies: Vec<Body>,
    /// The pose counter the drawn hair has once posed after these steps;
    /// [`Executor::fill`] is told it again.
    pub version: u64,
}

/// Where the simulation, the density map's fill and its sweep run.
/// Implementations must give exactly the results of [`LocalExecutor`].
pub trait Executor: Send + Sync + std::fmt::Debug {
    /// Runs `plan`'s steps on every wisp of `anim` and leaves the stepped
    /// state in `anim` (the caller then poses the drawn hair).
    fn simulate(
        &mut self,
        anim: &mut Animator,
        plan: &StepPlan,
        stats: &mut FrameStats,
    ) -> Result<(), EngineError>;
    /// Adds the density of every strand of `hair` to `map` (empty, in its
    /// frame) for light `light`. `version` is the hair's pose counter when
    /// it was posed after [`Self::simulate`] with a plan of that version
    /// (an executor that simulated elsewhere may fill from the strands it
    /// posed there), `None` for any other hair.
    fn fill(
        &mut self,
        light: usize,
        map: &mut DensityMap,
        hair: &Hair,
        fiber: &Fiber,
        version: Option<u64>,
    ) -> Result<FillStats, EngineError>;
    /// Sweeps every column of `map` (paper 4.2).
    fn sweep(&mut self, light: usize, map: &DensityMap) -> Result<Transmittance, EngineError>;
}

/// Every stage in this process, on all threads.
#[derive(Debug, Default, Clone, Copy)]
pub struct LocalExecutor;

impl Executor for LocalExecutor {
    fn simulate(
        &mut self,
        anim: &mut Animator,
        plan: &StepPlan,
        stats: &mut FrameStats,
    ) -> Result<(), EngineError> {
        let all = 0..anim.wisp_count();
        step_wisps(anim, all, plan, plan.accel.as_deref(), stats);
        Ok(())
    }

    fn fill(
        &mut self,
        _light: usize,
        map: &mut DensityMap,
        hair: &Hair,
        fiber: &Fiber,
        _version: Option<u64>,
    ) -> Result<FillStats, EngineError> {
        Ok(map.deposit(hair, 0..hair.strand_count(), fiber))
    }

    fn sweep(&mut self, _light: usize, map: &DensityMap) -> Result<Transmittance, EngineError> {
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
    for (head, bodies) in plan.heads.iter().zip(&plan.bodies) {
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
}
