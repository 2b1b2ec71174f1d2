//! The frame pipeline of an animation: each frame runs only the stages the
//! scene's effects call for, and only when their inputs changed.
//!
//! | stage | runs when |
//! |---|---|
//! | `self_collide` | dynamics and self-collision: the previous frame's density map pushes hair out of dense cells |
//! | `simulate` | dynamics, for procedural hair on a moving head (the first frame also settles the hair) |
//! | `body_collide` | dynamics and body collision |
//! | `pose` | the hair moved: drawn strands from the guides, or the rest hair under the head |
//! | `density` | self-shadowing (or a self-collision still lacking a map) and the hair moved since the last fill |
//! | `transmittance` | self-shadowing and the density was just filled |
//! | `filter` | self-shadowing and the hair moved |
//! | `shade` | the hair moved |
//! | `draw` | the hair moved; otherwise the last picture is the frame |
//!
//! The light never moves, so "the hair moved" is the whole test of whether
//! a shadow result can be reused.

mod motion;

use std::time::Instant;

use glam::Affine3A;
use shadow::{DensityMapMethod, MethodConfig};
use strands::Hair;

use crate::animate::Animator;
use crate::{
    Composite, Drawn, EngineError, Executor, FrameNeeds, FrameStats, LocalExecutor, PosePlan,
    PoseReport, Renderer, Scene, Site, Stage, Strands,
};

/// Which hair a map or result was computed from: the pose counter.
type Version = u64;

/// The frames of one scene, rendered in order.
///
/// The sequence plans each frame and owns the [`Executor`] that runs the
/// stages which grow with the hair: in this process by default, or on
/// cluster workers. When the executor holds the drawn hair itself
/// ([`Executor::drawing`]) and the shadows are the density map's, the
/// sequence never poses the drawn hair here: it fits the maps to the
/// extents the executor reports, and composites the partial pictures it
/// returns over the head.
#[derive(Debug)]
pub struct Sequence {
    scene: Scene,
    anim: Animator,
    /// The drawn hair's box at rest and a sample of its points (at most
    /// about 16K, evenly): what the camera is framed on.
    rest: (strands::Bounds, Vec<glam::Vec3>),
    renderer: Renderer,
    executor: Box<dyn Executor>,
    /// Where the frame being prepared draws its hair, as planned at its
    /// start ([`Self::plan`]); every stage of the frame takes it.
    site: Site,
    /// What the last frame rendered cost its call, until the next plan
    /// tells the executor.
    finished: Option<crate::FrameTime>,
    /// Self-collisions' own density map, when the shadows do not fill one
    /// (self-shadowing off, or another shadow method).
    collision_map: Option<DensityMapMethod>,
    /// Counts poses of the drawn hair.
    version: Version,
    /// The head transform the drawn hair was last posed under.
    posed_head: Affine3A,
    /// The groom file's sample the next pose takes the rest hair from (an
    /// animated groom's frame), and the one the last pose took.
    sample: u32,
    posed_sample: u32,
    /// What the last pose reported, when it was posed elsewhere or once
    /// measured here.
    report: Option<PoseReport>,
    /// The plan of the last pose.
    last_plan: Option<PosePlan>,
    /// Whether the drawn hair in this process lags the hair posed
    /// elsewhere.
    stale_here: bool,
    /// The hair the self-collision map holds.
    collision_at: Option<Version>,
    /// The hair the shadow result (and the filtered transmittance) holds.
    shadow_at: Option<Version>,
    shaded_at: Option<Version>,
    picture: Option<(Version, image::RgbImage)>,
    next: u64,
    /// Frames the caller will still ask for, when it said.
    expected: Option<u64>,
    /// The next frame is the last one again ([`Self::again`]): no motion.
    repeat: bool,
    /// The next frame's wisps were given ([`Self::resume_at`]): it poses
    /// them without stepping.
    resumed: bool,
    /// The next frame's stages before its drawing, and its site, when
    /// they ran ahead.
    ahead: Option<Result<(FrameStats, Site), EngineError>>,
    /// Threads of their own for compositing while the next frame's stages
    /// run (on the global pool's threads, which would otherwise wait for
    /// the compositing to finish).
    compositor: Option<rayon::ThreadPool>,
    /// Threads that rasterize a frame drawn here while the next frame's
    /// stages run on the global pool: on the global pool itself, those
    /// stages' parallel work (the self-collision field, the filter) would
    /// queue behind the rasterization.
    drawer: Option<rayon::ThreadPool>,
}

/// A composite resolved: the canvas to reuse and the picture, or the
/// composite back with its error.
type Resolved = Result<(Option<raster::Canvas>, image::RgbImage), (Composite, EngineError)>;

/// `composite` waited for and resolved (on `pool`'s threads when given),
/// and its milliseconds; a picture finished elsewhere that failed gives
/// back the composite with the error.
#[allow(clippy::result_large_err)]
fn resolve_timed(mut composite: Composite, pool: Option<&rayon::ThreadPool>) -> (Resolved, f64) {
    let t = Instant::now();
    let out = match composite.wait() {
        Err(e) => Err((composite, e)),
        Ok(()) => match pool {
            Some(p) => p.install(|| composite.resolve()),
            None => composite.resolve(),
        },
    };
    (out, t.elapsed().as_secs_f64() * 1e3)
}

/// A pool of `threads` threads named `wisplight-{name}-i`, to work beside
/// the global pool; none when no thread can be started (the work then
/// shares the global pool).
fn side_pool(threads: usize, name: &'static str) -> Option<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(move |i| format!("wisplight-{name}-{i}"))
        .build()
        .ok()
}

/// Self-collisions' own density map for `scene`, when they need one and
/// the shadows do not fill it.
fn collision_map(scene: &Scene, anim: &Animator) -> Result<Option<DensityMapMethod>, EngineError> {
    let shares_map =
        scene.effects.self_shadow && matches!(scene.shadow.method, MethodConfig::DensityMap { .. });
    let collides = anim.simulates() && scene.effects.self_collision;
    if !collides || shares_map {
        return Ok(None);
    }
    Ok(Some(DensityMapMethod::new(
        scene.shadow.cells().max(1),
        false,
    )?))
}

/// The box of `hair` and a sample of its points, at most about 16K,
/// evenly.
fn rest_sample(hair: &Hair) -> (strands::Bounds, Vec<glam::Vec3>) {
    let points = hair.points();
    let stride = points.len().div_ceil(1 << 14).max(1);
    let sample = points.iter().step_by(stride).copied().collect();
    (hair.bounds(), sample)
}

/// `executor`'s drawing part, for a frame planned [`Site::Elsewhere`]: a
/// typed failure when it gave it up.
fn drawing(executor: &mut dyn Executor) -> Result<&mut dyn crate::Drawing, EngineError> {
    executor.drawing().ok_or(EngineError::SiteLost)
}

/// The hair a frame's maps are filled from, at pose counter `version`:
/// the executor's when the frame draws elsewhere, else `hair`, here.
fn strands_of(site: Site, hair: &Hair, version: Version) -> Strands<'_> {
    match site {
        Site::Elsewhere => Strands::Held { posed: version },
        Site::Here => Strands::Here {
            hair,
            posed: Some(version),
        },
    }
}

impl Sequence {
    /// The frames of `scene`, in this process until an executor is set.
    pub fn new(scene: &Scene) -> Result<Sequence, EngineError> {
        let anim = Animator::new(scene)?;
        let mut renderer = Renderer::new(scene)?;
        renderer.set_groups(anim.groups().strands.clone());
        let collision_map = collision_map(scene, &anim)?;
        Ok(Sequence {
            scene: scene.clone(),
            posed_head: anim.head(),
            sample: 0,
            posed_sample: 0,
            rest: rest_sample(anim.hair()),
            anim,
            renderer,
            executor: Box::new(LocalExecutor),
            site: Site::Here,
            finished: None,
            collision_map,
            version: 0,
            report: None,
            stale_here: false,
            last_plan: None,
            collision_at: None,
            shadow_at: None,
            shaded_at: None,
            picture: None,
            next: 0,
            expected: None,
            repeat: false,
            resumed: false,
            ahead: None,
            compositor: None,
            drawer: None,
        })
    }

    /// Runs the stages that grow with the hair through `executor` (cluster
    /// workers) from the next frame on. The pictures are the same bytes.
    pub fn set_executor(&mut self, mut executor: Box<dyn Executor>) -> Result<(), EngineError> {
        executor.attach(&self.anim)?;
        self.executor = executor;
        // Hair held elsewhere is posed there before it is used.
        self.invalidate();
        Ok(())
    }

    /// The scene as the frames now render it.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Renders the frames from the next on with `scene`'s lights, effects,
    /// shading and shadow settings, the hair's motion carrying on where it
    /// is (nothing is simulated again) and the camera kept. The next frame
    /// runs the shadow stages (when on), the shading and the drawing anew;
    /// with hair held elsewhere, its pose too (an executor whose own
    /// settings depend on the changed ones is replaced with
    /// [`Self::set_executor`] after this). Refused, leaving the sequence as
    /// it was, when `scene` has other hair, motion or dynamics settings, or
    /// another number of lights: such a scene needs a sequence of its own.
    pub fn set_scene(&mut self, scene: &Scene) -> Result<(), EngineError> {
        let same_motion = scene.hair == self.scene.hair
            && scene.animation == self.scene.animation
            && scene.dynamics == self.scene.dynamics
            && scene.effects.dynamics == self.scene.effects.dynamics
            && scene.head == self.scene.head
            && scene.render == self.scene.render
            && scene.fiber == self.scene.fiber
            && scene.lights.len() == self.scene.lights.len();
        if !same_motion {
            return Err(EngineError::Unchangeable(
                "a running sequence changes only its lights (not their number), effects \
                 (but dynamics), shading and shadow settings",
            ));
        }
        // The next frame's stages ran beside this one's drawing: the hair
        // has moved on, and the last frame cannot be rendered again with
        // the new settings (see `again`).
        if self.ahead.is_some() {
            return Err(EngineError::executor(
                "the scene cannot change once the next frame's stages ran ahead \
                 (expect one frame at a time to render a frame again)",
            ));
        }
        let renderer = self.renderer.remade(scene)?;
        self.collision_map = collision_map(scene, &self.anim)?;
        self.renderer = renderer;
        self.scene = scene.clone();
        self.invalidate();
        Ok(())
    }

    /// Looks through `camera` from the next frame on (it shades and draws
    /// anew; nothing else reruns).
    pub fn set_camera(&mut self, camera: raster::Camera) {
        self.renderer.set_camera(camera);
        self.shaded_at = None;
        self.picture = None;
    }

    /// Makes the next frame the last one again: no motion, and only the
    /// stages whose inputs changed since (by [`Self::set_camera`] or
    /// [`Self::set_scene`]) run; with nothing changed, none. Before the
    /// first frame, the next is the first.
    pub fn hold(&mut self) {
        if self.next > 0 && self.ahead.is_none() && !self.repeat {
            self.next -= 1;
            self.repeat = true;
            if let Some(n) = &mut self.expected {
                *n += 1;
            }
        }
    }

    /// Index of the next frame [`Self::next_frame`] renders.
    pub fn next_index(&self) -> u64 {
        self.next
    }

    /// Forgets every result that depends on the scene's settings: the
    /// next frame poses (where the hair is held elsewhere), shadows, shades
    /// and draws anew.
    fn invalidate(&mut self) {
        self.report = None;
        self.shadow_at = None;
        self.collision_at = None;
        self.shaded_at = None;
        self.picture = None;
        self.ahead = None;
    }

    /// The drawn hair as last posed in this process (when the executor
    /// draws elsewhere, the hair as it stood before).
    pub fn hair(&self) -> &strands::Hair {
        self.anim.hair()
    }

    /// The hair over time.
    pub fn animator(&self) -> &Animator {
        &self.anim
    }

    /// The renderer, with the last frame's transmittance and colours (when
    /// drawn in this process).
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// Plans the frame about to run, once: where its drawn hair is posed,
    /// filtered, shaded and rasterized ([`Executor::plan_frame`]: elsewhere
    /// only when the executor can hold it and no shadow method needs all
    /// of it here, [`MethodConfig::needs_all_hair`]). The one place that
    /// decides; every stage of the frame reads `self.site`.
    fn plan(&mut self, index: u64, picture: bool) -> Site {
        let all_here = self.scene.effects.self_shadow && self.scene.shadow.method.needs_all_hair();
        self.site = self.executor.plan_frame(FrameNeeds {
            index,
            finished: self.finished.take(),
            picture,
            may_draw_elsewhere: !all_here,
        });
        self.site
    }

    /// Says that the caller will ask for `frames` more frames (and no
    /// more). With an executor that draws elsewhere, each frame but the
    /// last then runs the next frame's stages up to its drawing (the
    /// simulation, the pose and the shadows, which need only this frame's
    /// density map, not its picture) while its own picture is composited:
    /// the workers step and fill while the coordinator composites. With an
    /// executor that [runs elsewhere](Executor::runs_elsewhere) but leaves
    /// the drawing here, the next frame's stages likewise run while this
    /// frame is rasterized. The pictures are the same bytes; the next
    /// frame's stages are timed in its own [`FrameStats`].
    pub fn expect_frames(&mut self, frames: u64) {
        self.expected = Some(frames);
    }

    /// Renders the next frame: its picture and what each stage did. A
    /// frame that fails is the next frame still (a frame held with
    /// [`Self::hold`] stays held).
    pub fn next_frame(&mut self) -> Result<(&image::RgbImage, FrameStats), EngineError> {
        let repeat = self.repeat;
        let (start, index) = (Instant::now(), self.next);
        let stats = match self.render_next() {
            Ok(stats) => stats,
            Err(e) => {
                self.repeat = repeat;
                self.finished = None;
                return Err(e);
            }
        };
        self.finished = Some(crate::FrameTime {
            index,
            ms: start.elapsed().as_secs_f64() * 1e3,
        });
        let (_, img) = self.picture.as_ref().expect("drawn");
        Ok((img, stats))
    }

    fn render_next(&mut self) -> Result<FrameStats, EngineError> {
        let index = self.next;
        let (mut stats, site) = match self.ahead.take() {
            Some(ahead) => ahead?,
            None => self.before_draw(index)?,
        };
        // Every log line of the frame (here and in an executor) names it,
        // warnings included.
        let span = tracing::warn_span!("frame", index).entered();
        let more = self.expected.is_some_and(|n| n > 1);
        if let Some(n) = &mut self.expected {
            *n = n.saturating_sub(1);
        }
        let fx = self.scene.effects;
        let version = self.version;
        if site == Site::Elsewhere {
            if self.picture.as_ref().is_none_or(|p| p.0 != version) {
                self.frame_camera()?;
                let job = self.renderer.draw_job(version, fx.self_shadow)?;
                let start = Instant::now();
                let ex = drawing(self.executor.as_mut())?;
                // Ahead of the next frame, the head is drawn here too (while
                // the hair's call waits): if the picture finished elsewhere
                // fails once this frame's stages are gone, the frame drawn
                // again is composited on it.
                let elsewhere = ex.composites() && !more;
                let (composite, drawn) =
                    self.renderer.compose_later(fx.self_shadow, elsewhere, || {
                        if more {
                            ex.draw_ahead(&job)
                        } else {
                            ex.draw(&job)
                        }
                    })?;
                let mut ms = start.elapsed().as_secs_f64() * 1e3;
                drop(span);
                let (finished, resolve_ms) = if more {
                    // Composited in a thread of its own, on half the global
                    // pool's threads (at least one), while the next frame's
                    // stages run here.
                    let threads = rayon::current_num_threads().div_ceil(2);
                    let pool = self
                        .compositor
                        .take()
                        .or_else(|| side_pool(threads, "composite"));
                    let resolved = self.resolve_beside_next(composite, pool.as_ref(), index + 1);
                    self.compositor = pool;
                    resolved
                } else {
                    resolve_timed(composite, None)
                };
                let (canvas, img) = match finished {
                    Ok(done) => done,
                    Err((mut composite, e)) => {
                        let _span = tracing::warn_span!("frame", index).entered();
                        tracing::warn!(error = %e, "the picture finished elsewhere failed; the frame is drawn again");
                        let again = drawing(self.executor.as_mut())?.redraw(&job)?;
                        let t = Instant::now();
                        let again = match again.drawn {
                            Drawn::Picture(img) => Ok((None, img)),
                            Drawn::Layers(layers) if composite.has_head() => {
                                if composite.add_layers(layers) {
                                    composite.resolve().map_err(|(_, e)| e)
                                } else {
                                    Err(EngineError::executor("a partial picture of another size"))
                                }
                            }
                            _ => Err(EngineError::executor("no head drawn here to draw it on")),
                        };
                        let done = again.map_err(|again| {
                            EngineError::executor(format!(
                                "frame {index} could not be drawn again ({again}): {e}"
                            ))
                        })?;
                        ms += t.elapsed().as_secs_f64() * 1e3;
                        done
                    }
                };
                ms += resolve_ms;
                self.renderer.restore_canvas(canvas);
                if fx.self_shadow {
                    stats.record(Stage::Filter, drawn.filter_ms);
                }
                stats.record(Stage::Shade, drawn.shade_ms);
                stats.record(Stage::Draw, ms - drawn.filter_ms - drawn.shade_ms);
                self.shaded_at = Some(version);
                self.picture = Some((version, img));
            }
        } else {
            self.frame_camera()?;
            let hair = self.anim.hair();
            if self.shaded_at != Some(version) {
                let r = &mut self.renderer;
                stats.time(Stage::Shade, || r.shade(hair, fx.self_shadow))?;
                self.shaded_at = Some(version);
            }
            if self.picture.as_ref().is_none_or(|p| p.0 != version) {
                let r = &mut self.renderer;
                let img = if more && self.executor.runs_elsewhere() {
                    // Rasterized in a thread of its own while the next
                    // frame's stages run (the workers step and fill while
                    // this process draws): binned first, so that it reads
                    // nothing the next frame changes.
                    let start = Instant::now();
                    let composite = r.draw_later(hair, fx.self_shadow)?;
                    let bin_ms = start.elapsed().as_secs_f64() * 1e3;
                    drop(span);
                    let threads = rayon::current_num_threads();
                    let pool = self.drawer.take().or_else(|| side_pool(threads, "draw"));
                    let (finished, resolve_ms) =
                        self.resolve_beside_next(composite, pool.as_ref(), index + 1);
                    self.drawer = pool;
                    let (canvas, img) = finished.map_err(|(_, e)| e)?;
                    self.renderer.restore_canvas(canvas);
                    stats.record(Stage::Draw, bin_ms + resolve_ms);
                    img
                } else {
                    stats.time(Stage::Draw, || r.draw(hair, fx.self_shadow))?
                };
                self.picture = Some((version, img));
            }
        }
        self.next += 1;
        Ok(stats)
    }

    /// `composite` resolved (on `pool`'s threads) in a thread of its own
    /// while frame `next`'s stages run here, their result kept for it.
    fn resolve_beside_next(
        &mut self,
        composite: Composite,
        pool: Option<&rayon::ThreadPool>,
        next: u64,
    ) -> (Resolved, f64) {
        let (resolved, ahead) = std::thread::scope(|s| {
            let resolved = s.spawn(|| resolve_timed(composite, pool));
            let ahead = self.before_draw(next);
            let resolved = resolved
                .join()
                .unwrap_or_else(|p| std::panic::resume_unwind(p));
            (resolved, ahead)
        });
        self.ahead = Some(ahead);
        resolved
    }

    /// Renders the last frame again, every stage after its motion run anew
    /// as though the hair had just moved: the shadows (density,
    /// transmittance, filter), the shading and the drawing, each timed in
    /// the frame's new [`FrameStats`]; the picture is the same bytes. What
    /// a benchmark of those stages repeats (`bench shadow`, `bench
    /// accuracy`). The first call renders frame 0; frames said to follow
    /// ([`Self::expect_frames`]) are not counted down.
    pub fn again(&mut self) -> Result<(&image::RgbImage, FrameStats), EngineError> {
        if self.next > 0 {
            if self.ahead.is_some() {
                return Err(EngineError::executor(
                    "a frame cannot be rendered again once the next one's stages ran ahead",
                ));
            }
            self.next -= 1;
            self.repeat = true;
            self.shadow_at = None;
            self.shaded_at = None;
            self.picture = None;
            if let Some(n) = &mut self.expected {
                *n += 1;
            }
        }
        self.next_frame()
    }

    /// Frames the camera, the first time, on the hair at rest and the
    /// head as the head's motion carries both through the shot's frames
    /// ([`crate::Animation::framing_last_frame`]): the scene's, not the
    /// frames a run renders, so that frame `k` is the same picture
    /// whatever range is rendered (the swing of simulated hair beyond the
    /// head's motion aside).
    fn frame_camera(&mut self) -> Result<(), EngineError> {
        if self.renderer.camera().is_some() {
            return Ok(());
        }
        let last = self.scene.animation.framing_last_frame();
        // At most 512 samples of the motion, evenly over frames 1..=last
        // (frame 0 is where the bounds are).
        let samples = last.min(512);
        let dt = self.anim.frame_dt();
        let from = self.anim.head_at(0.0).inverse();
        let moves: Vec<Affine3A> = (1..=samples)
            .map(|k| {
                let f = k * last / samples;
                self.anim.head_at(f as f32 * dt) * from
            })
            .collect();
        let (bounds, sample) = &self.rest;
        self.renderer.frame_on_motion(*bounds, sample, &moves)
    }

    /// Frame `index`'s stages before its drawing: the motion (simulated
    /// steps, or a rigid move of the head), the pose and the shadows, each
    /// only when its inputs changed.
    /// The frame is planned first ([`Self::plan`]); its site comes back
    /// with its stats.
    fn before_draw(&mut self, index: u64) -> Result<(FrameStats, Site), EngineError> {
        let _span = tracing::warn_span!("frame", index).entered();
        let t = index as f32 * self.anim.frame_dt();
        let mut stats = FrameStats::new(index, t);
        let fx = self.scene.effects;
        let site = self.plan(index, true);
        self.motion(index, &mut stats)?;

        // Shadows, only when the hair moved since the last result.
        let version = self.version;
        if fx.self_shadow && self.shadow_at != Some(version) {
            let report = self.report(&mut stats)?.clone();
            let anchor = self.anim.anchor_at(&self.posed_head);
            let hair = self.anim.hair();
            let strands = strands_of(site, hair, version);
            let (r, ex) = (&mut self.renderer, self.executor.as_mut());
            let extents = Some((anchor, &report.extents[..]));
            stats.samples = stats
                .time(Stage::Density, || {
                    r.shadows_mut().shadow_density(strands, extents, ex)
                })?
                .samples;
            stats.time(Stage::Transmittance, || {
                r.shadows_mut().transmittance_with(ex)
            })?;
            if site == Site::Here {
                // The camera first: the exact reference looks at each
                // fiber from the side it sees.
                self.frame_camera()?;
                let (r, hair) = (&mut self.renderer, self.anim.hair());
                stats.time(Stage::Filter, || r.filter(hair));
            }
            self.shadow_at = Some(version);
            if self.collision_map.is_none() {
                self.collision_at = Some(version);
            }
        }
        Ok((stats, site))
    }
}
