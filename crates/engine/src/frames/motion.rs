//! The motion of a [`Sequence`]'s frames: simulated steps or a rigid
//! move, the pose of the drawn hair and its report, frames skipped (their
//! motion alone) and a sequence resumed from saved wisps.

use glam::Affine3A;
use shadow::fit_to_extent;
use sim::Body;

use super::{Sequence, drawing, strands_of};
use crate::collide::DensityRepulsion;
use crate::{EngineError, FrameStats, PosePlan, PoseReport, Site, Stage, StepPlan};

impl Sequence {
    /// Runs the next frame's motion alone, and nothing that only its
    /// picture needs (no shadows but the self-collision map its steps
    /// read, no shading, no drawing): what a run that renders a later
    /// range, or writes a simulation cache, does with the frames before.
    /// Hair that is not simulated has no motion to carry: its frames
    /// follow from the head's transform alone, so nothing runs. The next
    /// frame rendered is then the one after; its picture is the bytes a
    /// run that rendered every frame gives.
    pub fn skip_frame(&mut self) -> Result<FrameStats, EngineError> {
        let index = self.next;
        let mut stats = FrameStats::new(index, index as f32 * self.anim.frame_dt());
        if self.ahead.is_some() {
            return Err(EngineError::executor(
                "a frame cannot be skipped once its stages ran ahead",
            ));
        }
        if self.anim.simulates() || self.repeat || self.resumed {
            let _span = tracing::warn_span!("frame", index).entered();
            self.finished = None;
            self.plan(index, false);
            self.motion(index, &mut stats)?;
        }
        if let Some(n) = &mut self.expected {
            *n = n.saturating_sub(1);
        }
        self.next += 1;
        Ok(stats)
    }

    /// The state of every wisp, as the last frame's steps left it (`None`
    /// for hair that is not simulated): what a simulation cache holds.
    pub fn wisp_states(&self) -> Option<Vec<sim::WispState>> {
        if !self.anim.simulates() {
            return None;
        }
        (0..self.anim.wisp_count())
            .map(|w| self.anim.wisp_state(w).cloned())
            .collect()
    }

    /// Makes frame `index` the next, its wisps standing as `states` say
    /// (as the steps up to that frame left them, read from a simulation
    /// cache): it poses them without stepping, and the frames after it
    /// step on from there. The executor is told the new state
    /// ([`crate::Executor::attach`]). Refused, leaving the sequence as it was,
    /// for hair that is not simulated or states of another shape.
    pub fn resume_at(
        &mut self,
        index: u64,
        states: Vec<sim::WispState>,
    ) -> Result<(), EngineError> {
        if !self.anim.simulates() {
            return Err(EngineError::Unchangeable(
                "the scene's hair is not simulated: it has no wisps to resume",
            ));
        }
        if states.len() != self.anim.wisp_count() {
            return Err(EngineError::Sim(sim::SimError::Guides(format!(
                "{} wisp states for a scene of {} wisps",
                states.len(),
                self.anim.wisp_count()
            ))));
        }
        let before: Vec<sim::WispState> = self.wisp_states().unwrap_or_default();
        for (w, state) in states.into_iter().enumerate() {
            if let Err(e) = self.anim.set_wisp_state(w, state) {
                for (w, old) in before.into_iter().enumerate() {
                    let _ = self.anim.set_wisp_state(w, old);
                }
                return Err(e);
            }
        }
        self.executor.attach(&self.anim)?;
        self.invalidate();
        self.next = index;
        self.repeat = false;
        self.resumed = true;
        Ok(())
    }

    /// Frame `index`'s motion: simulated steps (or, for the frame the
    /// sequence [resumed at](Self::resume_at), the pose of the wisps it
    /// was given), or a rigid move of the head; then the pose, when the
    /// hair moved. Where, the frame's plan says (`self.site`).
    pub(super) fn motion(&mut self, index: u64, stats: &mut FrameStats) -> Result<(), EngineError> {
        let t = index as f32 * self.anim.frame_dt();
        let fx = self.scene.effects;
        let elsewhere = self.site == Site::Elsewhere;
        let head = self.anim.head_at(t);
        self.sample = self.anim.sample_at(index);
        let drawn = |seq: &Self| {
            if fx.body_collision && seq.anim.simulates() {
                seq.bodies(&head)
            } else {
                Vec::new()
            }
        };
        if std::mem::take(&mut self.repeat) {
            // The frame rendered again: the hair stays where it is.
        } else if std::mem::take(&mut self.resumed) {
            // The wisps stand where this frame's steps left them.
            let d = drawn(self);
            self.pose(stats, head, d)?;
        } else if self.anim.simulates() {
            let n = self.anim.substeps() as usize;
            let drawn = drawn(self);
            if index == 0 {
                // Settle at the first pose: frames' worth of steps, the
                // collision map refreshed once per such frame.
                let settle = self.anim.settle_frames();
                for f in 0..settle {
                    let last = f + 1 == settle;
                    let d = if last { drawn.clone() } else { Vec::new() };
                    self.advance(stats, vec![head; n], head, d)?;
                }
                if settle == 0 {
                    self.pose(stats, head, drawn)?;
                }
            } else {
                let (t0, dt) = (t - self.anim.frame_dt(), self.anim.frame_dt());
                let anim = &self.anim;
                let heads: Vec<Affine3A> = (1..=n)
                    .map(|s| anim.head_at(t0 + dt * s as f32 / n as f32))
                    .collect();
                self.advance(stats, heads, head, drawn)?;
            }
        } else if head != self.posed_head
            || self.sample != self.posed_sample
            || (elsewhere && self.report.is_none())
        {
            self.pose(stats, head, Vec::new())?;
        }
        if !elsewhere && self.stale_here {
            // Posed elsewhere until a change of settings brought the
            // drawing here: posed here as it was there.
            let plan = self.pose_again();
            self.posed(stats, &plan, None)?;
        }
        self.renderer.set_head_pose(head);
        // Hair held elsewhere whose report was forgotten (new lights)
        // reports again before its version is read.
        if elsewhere && self.report.is_none() {
            self.report(stats)?;
        }
        Ok(())
    }

    /// What the drawn hair's last pose reported: measured here the first
    /// time it is asked for, when the hair is posed here; hair held
    /// elsewhere is first posed there as it stands (at rest, under the
    /// head, as [`Animator::new`] poses it here).
    pub(super) fn report(&mut self, stats: &mut FrameStats) -> Result<&PoseReport, EngineError> {
        if self.report.is_none() {
            let plan = self.pose_again();
            if self.site == Site::Elsewhere {
                self.posed(stats, &plan, None)?;
            } else {
                self.report = Some(PoseReport::of(self.anim.hair(), &plan));
            }
        }
        Ok(self.report.as_ref().expect("measured above"))
    }

    /// The last pose again: the same hair, as a new version, the lights
    /// as they are now; before any, the hair as it stands.
    pub(super) fn pose_again(&self) -> PosePlan {
        match &self.last_plan {
            Some(p) => PosePlan {
                version: self.version + 1,
                lights: self.scene.lights.clone(),
                ..p.clone()
            },
            None => self.pose_plan(self.posed_head, Vec::new()),
        }
    }

    /// The plan of the next pose under `head`, pushed out of `drawn_bodies`.
    pub(super) fn pose_plan(&self, head: Affine3A, drawn_bodies: Vec<Body>) -> PosePlan {
        PosePlan {
            head,
            sample: self.sample,
            drawn_bodies,
            version: self.version + 1,
            lights: self.scene.lights.clone(),
            anchor: self.anim.anchor_at(&head),
        }
    }

    /// Poses the drawn hair under `head`, pushed out of `drawn_bodies`
    /// (simulated hair), after the steps (if any) that led there: here, or
    /// where the executor holds it. A new version of the hair.
    pub(super) fn pose(
        &mut self,
        stats: &mut FrameStats,
        head: Affine3A,
        drawn_bodies: Vec<Body>,
    ) -> Result<(), EngineError> {
        let plan = self.pose_plan(head, drawn_bodies);
        self.posed(stats, &plan, None)
    }

    /// Poses the drawn hair as `plan` says, here or where the executor
    /// holds it; hair held elsewhere that the executor already posed so
    /// (with the steps) gave its `report`. The sequence is the one owner
    /// of the pose's counter, plan and report.
    pub(super) fn posed(
        &mut self,
        stats: &mut FrameStats,
        plan: &PosePlan,
        report: Option<PoseReport>,
    ) -> Result<(), EngineError> {
        self.last_plan = Some(plan.clone());
        if self.site == Site::Elsewhere {
            self.report = Some(match report {
                Some(r) => r,
                None => {
                    let ex = drawing(self.executor.as_mut())?;
                    stats.time(Stage::Pose, || ex.pose(plan))?
                }
            });
            self.stale_here = true;
        } else {
            self.stale_here = false;
            let anim = &mut self.anim;
            stats.time(Stage::Pose, || -> Result<(), EngineError> {
                anim.set_sample(plan.sample)?;
                anim.set_head(plan.head);
                Ok(())
            })?;
            if !plan.drawn_bodies.is_empty() {
                let b = &plan.drawn_bodies;
                stats.time(Stage::BodyCollide, || self.anim.collide_drawn(b));
            }
            self.report = None;
        }
        self.version = plan.version;
        self.posed_head = plan.head;
        self.posed_sample = plan.sample;
        Ok(())
    }

    /// One frame's worth of simulation steps through the executor, under
    /// the head transforms `heads`, then the pose of the drawn hair under
    /// `head`, pushed out of `drawn_bodies`.
    pub(super) fn advance(
        &mut self,
        stats: &mut FrameStats,
        heads: Vec<Affine3A>,
        head: Affine3A,
        drawn_bodies: Vec<Body>,
    ) -> Result<(), EngineError> {
        let fx = self.scene.effects;
        let c = self.scene.collision;
        if fx.self_collision && self.collision_at != Some(self.version) {
            // The density map of the hair as it is now (the previous frame's).
            let report = self.report(stats)?.clone();
            let anchor = self.anim.anchor_at(&self.posed_head);
            let strands = strands_of(self.site, self.anim.hair(), self.version);
            let ex = self.executor.as_mut();
            match self.collision_map.as_mut() {
                Some(m) => {
                    let light = &self.scene.lights[0];
                    let frame = fit_to_extent(light, &[], (anchor, report.extents[0]), m.cells())?;
                    let fiber = &self.scene.fiber;
                    stats.time(Stage::Density, || {
                        m.density_with(frame, &[], |map| ex.density(0, map, strands, fiber))
                    })?;
                }
                None => {
                    let shadows = self.renderer.shadows_mut();
                    let extents = Some((anchor, &report.extents[..]));
                    stats.time(Stage::Density, || {
                        shadows.density_with(strands, extents, ex)
                    })?;
                    // The shadow result now lags the map: recompute it.
                    self.shadow_at = None;
                }
            }
            self.collision_at = Some(self.version);
        }
        let map = match &self.collision_map {
            Some(m) => m.map(),
            None => self.renderer.shadows().density_map(),
        };
        let field = map.filter(|_| fx.self_collision).and_then(|m| {
            DensityRepulsion::new(
                m,
                &self.scene.fiber,
                c.density,
                c.repulsion,
                c.max_acceleration,
            )
        });
        let accel = field.map(|f| stats.time(Stage::SelfCollide, || self.anim.sample_field(&f)));
        let bodies = heads
            .iter()
            .map(|h| {
                if fx.body_collision {
                    self.bodies(h)
                } else {
                    Vec::new()
                }
            })
            .collect();
        let plan = StepPlan {
            heads,
            bodies,
            accel,
            pose: self.pose_plan(head, drawn_bodies),
        };
        let report = self.executor.simulate(&mut self.anim, &plan, stats)?;
        self.posed(stats, &plan.pose, report)
    }

    /// The head and the scene's bodies under head transform `head`.
    pub(super) fn bodies(&self, head: &Affine3A) -> Vec<Body> {
        let s = &self.scene;
        s.head
            .as_ref()
            .map(|h| Body {
                center: head.transform_point3(h.center),
                radius: h.radius,
            })
            .into_iter()
            .chain(s.bodies.iter().map(|b| Body {
                center: if b.follows_head {
                    head.transform_point3(b.center)
                } else {
                    b.center
                },
                radius: b.radius,
            }))
            .collect()
    }
}
