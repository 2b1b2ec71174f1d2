//! Wisps of three guide strands, each a chain of rigid links (paper 5.1).
//!
//! Each step of a guide, with time step `dt`:
//!
//! 1. its first two points follow the head (the root and the direction the
//!    hair leaves the scalp);
//! 2. the others move by Verlet integration, `x += (x - x_prev) e^(-c dt)
//!    + (g + f(x)) dt^2`, with damping rate `c` (1/s), gravity `g` and the
//!    acceleration `f` of a force field (self-collisions);
//! 3. `iterations` rounds of constraint projection (position-based
//!    dynamics): each point moves a fraction `stiffness` towards its groomed
//!    place (carried along by the head) and each link is projected back to
//!    its rest length. (Pulling a point towards its parent's position plus
//!    the groomed offset instead feeds back along the chain and oscillates.)
//! 4. a last pass from the root to the tip sets every link to exactly its
//!    rest length (follow the leader), so lengths never drift;
//! 5. body collisions: from the root to the tip, a point inside a body
//!    sphere is pushed to its surface and put back at link length from its
//!    parent.
//!
//! The force field is sampled before the step ([`HairSim::sample_field`]),
//! and steps 2-4 ([`HairSim::integrate`]) and 5 ([`HairSim::collide`]) are
//! separate calls, so a frame pipeline can time and skip them apart.
//!
//! A wisp's step reads only its own state, the head transform, the bodies
//! and the force field (the previous frame's density map): wisps can be
//! stepped in any order, on any thread or machine, with the same bytes.

use std::ops::Range;

use glam::{Affine3A, Vec3};
use rayon::prelude::*;
use strands::{GUIDES_PER_WISP, Hair};

use crate::SimError;

/// Dynamics settings. Scene units are taken as centimetres (the procedural
/// head has radius 10), so gravity is 981 units/s^2.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimParams {
    /// Time step, seconds.
    pub dt: f32,
    /// Gravity, scene units per s^2.
    pub gravity: Vec3,
    /// Velocity damping rate `c`, 1/s.
    pub damping: f32,
    /// Fraction of the way each point moves towards its groomed place per
    /// iteration, in [0, 1]: how firmly the hair keeps its style.
    pub stiffness: f32,
    /// Constraint iterations per step.
    pub iterations: u32,
}

impl Default for SimParams {
    fn default() -> Self {
        SimParams {
            dt: 1.0 / 60.0,
            gravity: Vec3::new(0.0, -981.0, 0.0),
            damping: 3.0,
            stiffness: 0.02,
            iterations: 4,
        }
    }
}

impl SimParams {
    /// Checks every setting, naming the first out of range.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |what: &str, v: String| Err(SimError::Params(format!("{what} = {v}")));
        if !(self.dt.is_finite() && self.dt > 0.0 && self.dt <= 1.0) {
            return bad("time step (must be in (0, 1] s)", self.dt.to_string());
        }
        if !self.gravity.is_finite() {
            return bad("gravity (must be finite)", self.gravity.to_string());
        }
        if !(self.damping.is_finite() && self.damping >= 0.0) {
            return bad("damping (must be >= 0)", self.damping.to_string());
        }
        if !(0.0..=1.0).contains(&self.stiffness) {
            return bad("stiffness (must be in [0, 1])", self.stiffness.to_string());
        }
        if !(1..=64).contains(&self.iterations) {
            return bad(
                "iterations (must be in 1..=64)",
                self.iterations.to_string(),
            );
        }
        Ok(())
    }
}

/// A sphere hair collides with (head, neck, shoulders), in world space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Body {
    /// Centre, scene units.
    pub center: Vec3,
    /// Radius, scene units.
    pub radius: f32,
}

/// An acceleration field acting on hair points (self-collision repulsion).
pub trait ForceField: Sync {
    /// Acceleration at `p`, scene units per s^2. Must be finite.
    fn acceleration(&self, p: Vec3) -> Vec3;
}

/// The state of one wisp: its three guides' points, now and one step ago.
#[derive(Debug, Clone, PartialEq)]
pub struct WispState {
    /// The three guides' points, guide after guide.
    pub pos: Vec<Vec3>,
    /// The same points one step ago (Verlet).
    pub prev: Vec<Vec3>,
}

/// The guides of every wisp and their rest shape.
#[derive(Debug, Clone)]
pub struct HairSim {
    params: SimParams,
    /// Points per guide.
    n: usize,
    /// Rest points of every guide, in head space.
    rest: Vec<Vec3>,
    /// Rest length of every link, `n - 1` per guide.
    lengths: Vec<f32>,
    wisps: Vec<WispState>,
}

impl HairSim {
    /// Guides at rest in head space: strands `3w .. 3w + 3` are wisp `w`,
    /// all with the same number of points (at least 3).
    pub fn new(guides: &Hair, params: SimParams) -> Result<HairSim, SimError> {
        params.validate()?;
        let count = guides.strand_count();
        if count == 0 || !count.is_multiple_of(GUIDES_PER_WISP) {
            return Err(SimError::Guides(format!(
                "{count} guides is not a positive multiple of {GUIDES_PER_WISP}"
            )));
        }
        let n = guides.strand(0).len();
        if n < 3 || guides.strands().any(|s| s.len() != n) {
            return Err(SimError::Guides(
                "every guide needs the same number of points, at least 3".into(),
            ));
        }
        let rest = guides.points().to_vec();
        let lengths: Vec<f32> = guides
            .strands()
            .flat_map(|s| s.windows(2).map(|w| w[0].distance(w[1])))
            .collect();
        let wisps = rest
            .chunks(GUIDES_PER_WISP * n)
            .map(|c| WispState {
                pos: c.to_vec(),
                prev: c.to_vec(),
            })
            .collect();
        Ok(HairSim {
            params,
            n,
            rest,
            lengths,
            wisps,
        })
    }

    /// The settings it steps with.
    pub fn params(&self) -> &SimParams {
        &self.params
    }

    /// Wisps simulated.
    pub fn wisp_count(&self) -> usize {
        self.wisps.len()
    }

    /// Places every guide at its rest shape under `head`, at rest.
    pub fn reset(&mut self, head: &Affine3A) {
        let per = GUIDES_PER_WISP * self.n;
        for (w, s) in self.wisps.iter_mut().enumerate() {
            for (i, (p, q)) in s.pos.iter_mut().zip(s.prev.iter_mut()).enumerate() {
                *p = head.transform_point3(self.rest[w * per + i]);
                *q = *p;
            }
        }
    }

    /// One whole step of every wisp, in parallel: [`Self::sample_field`],
    /// [`Self::integrate`], then [`Self::collide`].
    pub fn step(&mut self, head: &Affine3A, bodies: &[Body], field: Option<&dyn ForceField>) {
        self.step_wisps(0..self.wisps.len(), head, bodies, field);
    }

    /// One whole step of wisps `range` only (a worker's share).
    pub fn step_wisps(
        &mut self,
        range: Range<usize>,
        head: &Affine3A,
        bodies: &[Body],
        field: Option<&dyn ForceField>,
    ) {
        let mut accel = Vec::new();
        if let Some(f) = field {
            self.sample_field(range.clone(), f, &mut accel);
        }
        self.integrate(range.clone(), head, field.map(|_| accel.as_slice()));
        self.collide(range, head, bodies);
    }

    /// Points per wisp: three guides' worth.
    pub fn points_per_wisp(&self) -> usize {
        GUIDES_PER_WISP * self.n
    }

    /// The acceleration of `field` at every point of wisps `range`, wisp
    /// after wisp, into `out` (self-collisions: evaluated where the hair is
    /// at the start of the step).
    pub fn sample_field(&self, range: Range<usize>, field: &dyn ForceField, out: &mut Vec<Vec3>) {
        let per = self.points_per_wisp();
        out.resize(range.len() * per, Vec3::ZERO);
        out.par_chunks_mut(per)
            .zip(&self.wisps[range])
            .for_each(|(o, s)| {
                for (a, &p) in o.iter_mut().zip(&s.pos) {
                    let f = field.acceleration(p);
                    *a = if f.is_finite() { f } else { Vec3::ZERO };
                }
            });
    }

    /// Moves wisps `range` one time step under gravity and `accel` (one
    /// acceleration per point of the range, from [`Self::sample_field`]),
    /// with the roots on `head`, and projects the links back to length.
    pub fn integrate(&mut self, range: Range<usize>, head: &Affine3A, accel: Option<&[Vec3]>) {
        let (n, params) = (self.n, self.params);
        let per = GUIDES_PER_WISP * n;
        if let Some(a) = accel {
            assert_eq!(a.len(), range.len() * per, "one acceleration per point");
        }
        let (rest, lengths) = (&self.rest, &self.lengths);
        self.wisps[range.clone()]
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, s)| {
                let w = range.start + i;
                for g in 0..GUIDES_PER_WISP {
                    let at = g * n..(g + 1) * n;
                    let (rest, len) = guide_rest(rest, lengths, n, w, g);
                    let ext = accel.map(|a| &a[i * per + g * n..i * per + (g + 1) * n]);
                    step_guide(
                        &mut s.pos[at.clone()],
                        &mut s.prev[at],
                        rest,
                        len,
                        head,
                        &params,
                        ext,
                    );
                }
            });
    }

    /// Pushes the points of wisps `range` out of `bodies`, keeping every
    /// link at its rest length: from the root to the tip, each point is
    /// pushed to the surface of any sphere it is inside, then put back at
    /// link length from its parent (twice, so a point pushed along a curved
    /// surface settles on it).
    pub fn collide(&mut self, range: Range<usize>, head: &Affine3A, bodies: &[Body]) {
        if bodies.is_empty() {
            return;
        }
        let n = self.n;
        let (rest, lengths) = (&self.rest, &self.lengths);
        self.wisps[range.clone()]
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, s)| {
                let w = range.start + i;
                for g in 0..GUIDES_PER_WISP {
                    let pos = &mut s.pos[g * n..(g + 1) * n];
                    let (rest, len) = guide_rest(rest, lengths, n, w, g);
                    for k in 2..n {
                        let parent = pos[k - 1];
                        let fallback = head.transform_vector3(rest[k] - rest[k - 1]);
                        for _ in 0..2 {
                            push_out(&mut pos[k], bodies);
                            pos[k] = at_length(parent, pos[k], len[k - 1], fallback);
                        }
                    }
                }
            });
    }

    /// The state of wisp `w`.
    pub fn wisp(&self, w: usize) -> &WispState {
        &self.wisps[w]
    }

    /// Replaces wisp `w`'s state (from another machine).
    pub fn set_wisp(&mut self, w: usize, state: WispState) -> Result<(), SimError> {
        let per = GUIDES_PER_WISP * self.n;
        if state.pos.len() != per || state.prev.len() != per {
            return Err(SimError::Guides(format!(
                "wisp {w} state has {} points, expected {per}",
                state.pos.len()
            )));
        }
        if !state.pos.iter().chain(&state.prev).all(|p| p.is_finite()) {
            return Err(SimError::Guides(format!("wisp {w} state is not finite")));
        }
        self.wisps[w] = state;
        Ok(())
    }

    /// The guides' current points, in the order of the guides given to
    /// [`Self::new`].
    pub fn write_guides(&self, guides: &mut Hair) {
        let pts = guides.points_mut();
        assert_eq!(
            pts.len(),
            self.rest.len(),
            "the guides given to HairSim::new"
        );
        for (chunk, s) in pts.chunks_mut(GUIDES_PER_WISP * self.n).zip(&self.wisps) {
            chunk.copy_from_slice(&s.pos);
        }
    }

    /// The largest relative deviation of any link from its rest length.
    pub fn max_stretch(&self) -> f32 {
        let n = self.n;
        let mut worst = 0.0f32;
        for (w, s) in self.wisps.iter().enumerate() {
            for g in 0..GUIDES_PER_WISP {
                let pts = &s.pos[g * n..(g + 1) * n];
                let guide = w * GUIDES_PER_WISP + g;
                for (k, pair) in pts.windows(2).enumerate() {
                    let rest = self.lengths[guide * (n - 1) + k];
                    if rest > 0.0 {
                        worst = worst.max((pair[0].distance(pair[1]) / rest - 1.0).abs());
                    }
                }
            }
        }
        worst
    }
}

fn step_guide(
    pos: &mut [Vec3],
    prev: &mut [Vec3],
    rest: &[Vec3],
    len: &[f32],
    head: &Affine3A,
    p: &SimParams,
    accel: Option<&[Vec3]>,
) {
    let n = pos.len();
    let dt = p.dt;
    let decay = (-p.damping * dt).exp();
    for i in 0..2 {
        prev[i] = pos[i];
        pos[i] = head.transform_point3(rest[i]);
    }
    for (i, (x, x_prev)) in pos.iter_mut().zip(prev.iter_mut()).enumerate().skip(2) {
        let a = p.gravity + accel.map_or(Vec3::ZERO, |a| a[i]);
        let v = (*x - *x_prev) * decay;
        *x_prev = *x;
        *x += v + a * (dt * dt);
    }
    for _ in 0..p.iterations {
        for i in 2..n {
            let groomed = head.transform_point3(rest[i]);
            pos[i] = pos[i].lerp(groomed, p.stiffness);
            let d = pos[i] - pos[i - 1];
            let l = d.length();
            if l > 1e-12 {
                let corr = d * (1.0 - len[i - 1] / l);
                if i - 1 < 2 {
                    pos[i] -= corr;
                } else {
                    pos[i - 1] += 0.5 * corr;
                    pos[i] -= 0.5 * corr;
                }
            }
        }
    }
    // Follow the leader: every link exactly at rest length.
    for i in 2..n {
        let fallback = head.transform_vector3(rest[i] - rest[i - 1]);
        pos[i] = at_length(pos[i - 1], pos[i], len[i - 1], fallback);
    }
    // A guide that went non-finite (a force field gone wrong) restarts from
    // its groomed shape rather than spreading NaN.
    if !pos.iter().chain(prev.iter()).all(|x| x.is_finite()) {
        for i in 0..n {
            pos[i] = head.transform_point3(rest[i]);
            prev[i] = pos[i];
        }
    }
}

/// Guide `g` of wisp `w`: its rest points and its link lengths, out of all
/// guides' (`n` points per guide).
fn guide_rest<'a>(
    rest: &'a [Vec3],
    lengths: &'a [f32],
    n: usize,
    w: usize,
    g: usize,
) -> (&'a [Vec3], &'a [f32]) {
    let guide = w * GUIDES_PER_WISP + g;
    (
        &rest[guide * n..(guide + 1) * n],
        &lengths[guide * (n - 1)..(guide + 1) * (n - 1)],
    )
}

/// The point at distance `len` from `parent` in the direction of `q` (or of
/// `fallback` when `q` sits on the parent or is not finite).
fn at_length(parent: Vec3, q: Vec3, len: f32, fallback: Vec3) -> Vec3 {
    let d = q - parent;
    let l = d.length();
    let dir = if l > 1e-12 && d.is_finite() {
        d / l
    } else {
        fallback.normalize_or(Vec3::NEG_Y)
    };
    parent + dir * len
}

/// Moves `x` to the surface of every body sphere it is inside (straight
/// out from the centre).
pub fn push_out(x: &mut Vec3, bodies: &[Body]) {
    for b in bodies {
        let d = *x - b.center;
        let l2 = d.length_squared();
        if l2 < b.radius * b.radius {
            let l = l2.sqrt();
            let dir = if l > 1e-12 { d / l } else { Vec3::Y };
            *x = b.center + dir * b.radius;
        }
    }
}
