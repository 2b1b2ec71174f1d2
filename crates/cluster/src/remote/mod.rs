//! The coordinator's side: an [`engine::Executor`] that runs every stage
//! that grows with the hair on workers over gRPC, with the same bytes as
//! one process.
//!
//! Each live worker owns a contiguous share of the hair's groups (whole
//! wisps, weighted by their drawn strands) and, per sweep, a contiguous
//! share of the columns (weighted by their occupied cells). Each frame is
//! planned once ([`Scheme`], `choose.rs`): drawn on the workers, each
//! posing, filtering and shading its strands and the workers finishing
//! bands of rows among themselves from the others' stripes (their shaded
//! segments, sort-middle, or partial pictures, sort-last; one worker's,
//! or a round that failed, the coordinator composites), or drawn on the
//! coordinator (the paper's scheme), which poses and draws every strand
//! from the wisps' states. When a
//! worker fails a call (it died, missed the deadline, or sent something
//! malformed) it is dropped: its share goes to the survivors with the
//! state the coordinator gathered last, they pose it again, and the stage
//! runs again, so the frame comes out the same.

mod choose;
mod draw;
mod lights;
mod loads;
mod maps;
mod simulate;

use choose::Chooser;
pub use choose::Scheme;
use draw::*;
use lights::{LightState, SweptMap};
use loads::Loads;

use std::ops::Range;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use engine::{
    Animator, DrawJob, DrawReport, Drawing, Drawn, EngineError, Executor, FrameNeeds, FrameStats,
    PendingPicture, PosePlan, PoseReport, Scene, SceneSource, Site, Stage, StepPlan, Strands,
    split_by,
};
use prost::Message;
use shadow::{ColumnSlab, DensityMap, Fiber, FillStats, LightFrame, Transmittance};
use sim::WispState;
use strands::Hair;

use crate::client::{Remote, call_error, collect, fan_out, fan_out_all, hello, malformed};
use crate::{ClusterError, Timing, Tls, Traffic, WorkerError, WorkerErrorKind, pb, wire};

/// Rows of each band the workers composite (whole canvas bands): bands
/// dealt to the workers in turn share the hair out evenly; 720 rows make
/// 15 bands.
const BAND_ROWS: u32 = 48;

/// Where the drawn hair is posed, filtered, shaded and rasterized, and
/// how the picture is put together (Molnar's classification of parallel
/// rendering). Every scheme gives the same bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DrawAt {
    /// Sort-middle, sort-last or the coordinator's draw, chosen frame by
    /// frame by what the frames before cost (each is measured twice first,
    /// two frames in a row, or once when its frame cost 1.5x the best;
    /// then the cheapest taken,
    /// another measured again every 16 frames); with one worker, on the
    /// coordinator.
    #[default]
    Auto,
    /// On the workers, each its own strands, each rasterizing them into
    /// a partial picture; with two or more, each owns bands of rows and
    /// composites the others' partial pictures of them (sort-last),
    /// with one the coordinator draws.
    SortLast,
    /// On the workers, each its own strands up to their shaded, projected
    /// segments, sent to the worker that owns the rows they fall in,
    /// which rasterizes every strand of its rows (sort-middle): each
    /// pixel's work is done once, and the bytes sent grow with the drawn
    /// segments. With one worker, as [`DrawAt::SortLast`].
    SortMiddle,
    /// On the coordinator, every strand (the paper's scheme: workers
    /// simulate, fill and sweep).
    Coordinator,
}

impl DrawAt {
    /// The choice's name, as the command line spells it.
    pub fn name(self) -> &'static str {
        match self {
            DrawAt::Auto => "auto",
            DrawAt::SortLast => "sort-last",
            DrawAt::SortMiddle => "sort-middle",
            DrawAt::Coordinator => "coordinator",
        }
    }

    /// Whether the workers hold and draw the drawn hair.
    pub(crate) fn on_workers(self) -> bool {
        !matches!(self, DrawAt::Coordinator)
    }

    /// What the workers send each other when they draw together, when
    /// the choice says (not [`DrawAt::Auto`]).
    pub(crate) fn sort(self) -> Option<engine::Sort> {
        match self {
            DrawAt::SortMiddle => Some(engine::Sort::Middle),
            DrawAt::SortLast => Some(engine::Sort::Last),
            DrawAt::Auto | DrawAt::Coordinator => None,
        }
    }
}

/// How a coordinator runs its workers.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// Bounds every call, from its first byte sent to its last received.
    pub deadline: Duration,
    /// Bounds connecting to a worker and its Hello: a worker that does
    /// not answer in time is left out of the run.
    pub connect_timeout: Duration,
    /// Mutual TLS on every connection, when given.
    pub tls: Option<Tls>,
    /// The cluster's token, shown in every call, when the workers
    /// require one.
    pub token: Option<crate::Token>,
    /// Where the hair is drawn.
    pub draw: DrawAt,
}

/// The hair the workers share, learnt from the frame's animator.
#[derive(Debug)]
struct SharedHair {
    /// Drawn strands of each group: the weights for sharing groups out.
    strands: Vec<u64>,
    /// Wisp boundaries of the groups, for simulated hair.
    wisps: Option<Vec<u32>>,
    points_per_wisp: usize,
    /// Every wisp's state as gathered last (reassigned after a loss).
    states: Vec<WispState>,
}

/// Workers that run the stages of the hair (see the module docs).
#[derive(Debug)]
pub struct RemoteExecutor {
    rt: tokio::runtime::Runtime,
    /// The live workers, in order.
    workers: Vec<Remote>,
    deadline: Duration,
    draw: DrawAt,
    /// Counts calls, for the ids of those not about a posed hair version.
    calls: u64,
    traffic: Arc<Mutex<Traffic>>,
    timing: Arc<Mutex<Timing>>,
    /// The scene the workers build their shares from.
    source: SceneSource,
    /// Whether the filter stage interpolates trilinearly (the columns a
    /// worker reads depend on it).
    trilinear: bool,
    hair: Option<SharedHair>,
    /// Each live worker's groups, once assigned.
    shares: Option<Vec<Range<usize>>>,
    /// What the workers hold: the hair version they posed last, and that
    /// pose's plan (posed again after a loss). Its report is the frame's
    /// ([`engine::Sequence`] keeps it).
    posed: Option<u64>,
    last_pose: Option<PosePlan>,
    /// What is kept of each light's map, light by light.
    lights: Vec<LightState>,
    /// Whether the workers composite the picture among themselves (two
    /// or more drawing).
    composite: Collective,
    /// Whether the workers sum and sweep each light's map among
    /// themselves (two or more drawing).
    exchange: Collective,
    /// Whether the maps filled are swept for the frame's shadows (the
    /// density-map method, self-shadowing on); otherwise a fill is the
    /// self-collisions' alone, and the workers need not sweep it.
    sweeps_follow: bool,
    /// Whether the head is shadowed by the hair (the workers resolving
    /// bands shade it: they get every swept column); also whether the
    /// head is in the maps, as an occluder.
    head_shadow: bool,
    /// The name expected in workers' certificates, for their calls to
    /// each other.
    tls_domain: Option<String>,
    /// The first failure of a picture left to finish (see
    /// [`Drawing::draw_ahead`]), for [`Drawing::redraw`].
    failure: Arc<Mutex<Option<ClusterError>>>,
    /// What the workers held when they drew the picture left to finish.
    drawn: Option<Snapshot>,
    /// How this frame is drawn: planned once, at its start
    /// ([`Executor::plan_frame`]), and held until the next.
    scheme: Scheme,
    /// With [`DrawAt::Auto`], what the frames of each scheme cost.
    chooser: Chooser,
    /// The frames [`DrawAt::Auto`] chose a scheme for, by index, until
    /// their cost is known (a frame with a loss or a fallback in it is
    /// no measure of its scheme, and is forgotten).
    chosen: Vec<(u64, Scheme)>,
    /// What each 16 rows of the picture cost to draw in the last round of
    /// each sort: the next round's bands are cut by it.
    row_costs: Arc<Mutex<RowCosts>>,
    /// What each worker's own strands cost it: the bands are dealt so
    /// that its own work and its bands add up alike.
    loads: Loads,
}

/// A step the workers take among themselves (compositing the picture,
/// summing and sweeping the maps): on until it fails twice with no worker
/// lost (they cannot reach each other), then off for the run, the
/// coordinator doing it instead.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Collective {
    /// Tried each frame; `failures` rounds failed so far with none lost.
    On { failures: u32 },
    /// Done through the coordinator from now on.
    Off,
}

impl Default for Collective {
    fn default() -> Collective {
        Collective::On { failures: 0 }
    }
}

impl Collective {
    /// Failures with no worker lost that turn it off.
    const FAILURES: u32 = 2;

    fn is_on(self) -> bool {
        matches!(self, Collective::On { .. })
    }

    /// Counts a round that failed with no worker lost; whether that
    /// turned it off.
    fn failed(&mut self) -> bool {
        match *self {
            Collective::On { failures } if failures + 1 >= Self::FAILURES => {
                *self = Collective::Off;
                true
            }
            Collective::On { failures } => {
                *self = Collective::On {
                    failures: failures + 1,
                };
                false
            }
            Collective::Off => false,
        }
    }
}

/// What drawing a frame again takes, kept while its picture is finished
/// on the workers and the next frame's stages run.
#[derive(Debug)]
struct Snapshot {
    version: u64,
    states: Vec<WispState>,
    pose: Option<PosePlan>,
    lights: Vec<LightState>,
    workers: Vec<String>,
}

impl RemoteExecutor {
    /// Connects to every worker and checks its protocol version, for
    /// `scene` (whose data files are read now, to send them).
    pub fn connect(
        addrs: &[String],
        scene: &Scene,
        options: &Options,
    ) -> Result<RemoteExecutor, ClusterError> {
        if addrs.is_empty() {
            return Err(ClusterError::Setup("no workers given".into()));
        }
        let mut scene = scene.clone();
        scene
            .read_data_files()
            .map_err(|e| ClusterError::Setup(e.to_string()))?;
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .map_err(|e| ClusterError::Setup(format!("cannot start the network runtime: {e}")))?;
        distinct(addrs)?;
        let (fiber, deadline) = (scene.fiber, options.deadline);
        let connect = options.connect_timeout.min(deadline);
        // All at once, each bounded by the connect timeout.
        let answers = rt.block_on(async {
            let calls: Vec<_> = addrs
                .iter()
                .map(|addr| {
                    let (addr, tls) = (addr.clone(), options.tls.clone());
                    let token = options.token.clone();
                    tokio::spawn(async move {
                        let greet = hello(&addr, &fiber, connect, tls.as_ref(), token.as_ref());
                        match tokio::time::timeout(connect, greet).await {
                            Ok(r) => r,
                            Err(_) => Err(ClusterError::Connect {
                                msg: format!("no answer within {} s", connect.as_secs_f64()),
                                addr,
                            }),
                        }
                    })
                })
                .collect();
            let mut out = Vec::with_capacity(calls.len());
            for c in calls {
                out.push(c.await.map_err(|e| ClusterError::Setup(e.to_string()))?);
            }
            Ok::<_, ClusterError>(out)
        })?;
        // A worker that cannot be reached, does not answer or has no room
        // for another session is left out, as one lost mid-run would be;
        // one that refuses (another protocol version, another token)
        // stops the run: it is set up wrong.
        let mut workers = Vec::with_capacity(addrs.len());
        let mut missing = Vec::new();
        for a in answers {
            match a {
                Ok(w) => workers.push(w),
                Err(e @ ClusterError::Connect { .. }) => missing.push(e),
                Err(e) => return Err(e),
            }
        }
        if workers.is_empty() {
            return Err(match missing.len() {
                1 => missing.remove(0),
                _ => ClusterError::Setup(format!(
                    "no worker answered: {}",
                    missing
                        .iter()
                        .map(|e| e.to_string())
                        .collect::<Vec<_>>()
                        .join("; ")
                )),
            });
        }
        for e in &missing {
            tracing::warn!(error = %e, "worker left out of the run");
        }
        Ok(RemoteExecutor {
            rt,
            workers,
            deadline,
            draw: options.draw,
            calls: 0,
            traffic: Arc::new(Mutex::new(Traffic::default())),
            timing: Arc::new(Mutex::new(Timing::default())),
            trilinear: scene.shadow.method.trilinear(),
            lights: vec![LightState::default(); scene.lights.len()],
            composite: Collective::default(),
            exchange: Collective::default(),
            sweeps_follow: scene.effects.self_shadow
                && matches!(scene.shadow.method, shadow::MethodConfig::DensityMap { .. }),
            head_shadow: scene.head.is_some() && scene.effects.head_shadow,
            tls_domain: options
                .tls
                .as_ref()
                .and_then(|t| t.domain().map(str::to_string)),
            failure: Arc::default(),
            drawn: None,
            scheme: Scheme::Coordinator,
            chooser: Chooser::default(),
            chosen: Vec::new(),
            row_costs: Arc::default(),
            loads: Loads::default(),
            source: scene.source,
            hair: None,
            shares: None,
            posed: None,
            last_pose: None,
        })
    }

    /// A handle on where the remote stages' time went.
    pub fn timing(&self) -> Arc<Mutex<Timing>> {
        self.timing.clone()
    }

    /// Workers still in the run.
    pub fn worker_count(&self) -> usize {
        self.workers.len()
    }

    /// A handle on the bytes counted so far (all stages, all frames).
    pub fn traffic(&self) -> Arc<Mutex<Traffic>> {
        self.traffic.clone()
    }

    fn count(&self, f: impl FnOnce(&mut Traffic)) {
        if let Ok(mut t) = self.traffic.lock() {
            f(&mut t);
        }
    }

    fn clock(&self, f: impl FnOnce(&mut Timing)) {
        if let Ok(mut t) = self.timing.lock() {
            f(&mut t);
        }
    }

    fn hair(&self) -> Result<&SharedHair, ClusterError> {
        self.hair
            .as_ref()
            .ok_or_else(|| ClusterError::Setup("the executor was not attached to the hair".into()))
    }

    /// After `e`: drops the worker it names, when others are left, and
    /// returns Ok so the caller runs its stage again on the survivors;
    /// otherwise returns `e`.
    fn lose_worker(&mut self, e: ClusterError) -> Result<(), ClusterError> {
        // A session the worker ended for going unused: this coordinator
        // stalled (the others have ended theirs too), no worker is lost.
        if let ClusterError::Call { addr, error, .. } = &e
            && error.expired
        {
            return Err(ClusterError::Expired {
                addr: addr.clone(),
                msg: error.message.clone(),
            });
        }
        let e = self.at_fault(e);
        let Some(addr) = e.worker() else {
            return Err(e);
        };
        let Some(i) = self.workers.iter().position(|w| w.addr == addr) else {
            return Err(e);
        };
        if self.workers.len() == 1 {
            return Err(e);
        }
        self.workers.remove(i);
        self.chosen.clear();
        self.loads.clear();
        self.shares = None;
        self.posed = None;
        self.lights.iter_mut().for_each(LightState::forget_workers);
        self.clock(|t| t.workers_lost += 1);
        tracing::warn!(
            error = %e,
            survivors = self.workers.len(),
            "worker lost; its share of the hair and its columns go to the survivors"
        );
        Ok(())
    }

    /// The error that names the worker at fault for `e`: a worker that
    /// waited in vain for a peer (its index in the round's plan, which
    /// lists the workers in this order) blames that peer, not itself.
    fn at_fault(&self, e: ClusterError) -> ClusterError {
        if let ClusterError::Call { addr, stage, error } = &e
            && let Some(peer) = error.waited_for.and_then(|b| self.workers.get(b as usize))
            && peer.addr != *addr
        {
            return ClusterError::Call {
                addr: peer.addr.clone(),
                stage,
                error: crate::WorkerError::new(
                    crate::WorkerErrorKind::Unavailable,
                    format!("worker {addr} waited for it in vain ({})", error.message),
                ),
            };
        }
        e
    }

    /// Runs `attempt` until it succeeds, dropping a failed worker before
    /// each new try while others are left.
    fn with_survivors<T>(
        &mut self,
        mut attempt: impl FnMut(&mut Self) -> Result<T, ClusterError>,
    ) -> Result<T, ClusterError> {
        loop {
            match attempt(self) {
                Ok(t) => return Ok(t),
                Err(e) => self.lose_worker(e)?,
            }
        }
    }
}

/// Refuses a list naming one worker twice (the same address, or two that
/// resolve to the same socket): it would be counted as two, and its
/// sessions would share one process.
fn distinct(addrs: &[String]) -> Result<(), ClusterError> {
    use std::net::ToSocketAddrs;
    let mut resolved: Vec<(std::net::SocketAddr, &str)> = Vec::new();
    for (i, a) in addrs.iter().enumerate() {
        if addrs[..i].contains(a) {
            return Err(ClusterError::Setup(format!("worker {a} is given twice")));
        }
        // An address that does not resolve is reported when dialled.
        for r in a.to_socket_addrs().into_iter().flatten() {
            if let Some((_, b)) = resolved.iter().find(|s| s.0 == r && s.1 != a) {
                return Err(ClusterError::Setup(format!(
                    "workers {b} and {a} are the same worker ({r})"
                )));
            }
            resolved.push((r, a));
        }
    }
    Ok(())
}

impl Drop for RemoteExecutor {
    /// Ends this coordinator's session on every live worker (best effort:
    /// a worker that does not answer ends it when it has been idle long
    /// enough).
    fn drop(&mut self) {
        let workers = std::mem::take(&mut self.workers);
        if workers.is_empty() || tokio::runtime::Handle::try_current().is_ok() {
            return;
        }
        self.rt.block_on(async move {
            let ends = workers.into_iter().map(|mut w| {
                tokio::spawn(async move {
                    let end = w.client.end(pb::EndRequest {});
                    let _ = tokio::time::timeout(Duration::from_secs(2), end).await;
                })
            });
            for e in ends.collect::<Vec<_>>() {
                let _ = e.await;
            }
        });
    }
}

fn engine_error(e: ClusterError) -> EngineError {
    EngineError::Executor(Box::new(e))
}

impl Executor for RemoteExecutor {
    fn attach(&mut self, anim: &Animator) -> Result<(), EngineError> {
        let groups = anim.groups();
        let strands = groups
            .strands
            .windows(2)
            .map(|g| u64::from(g[1] - g[0]))
            .collect();
        let states = (0..anim.wisp_count())
            .map(|w| anim.wisp_state(w).cloned())
            .collect::<Option<Vec<_>>>()
            .ok_or_else(|| EngineError::executor("a wisp without a state"))?;
        self.hair = Some(SharedHair {
            strands,
            wisps: groups.wisps.clone(),
            points_per_wisp: anim.points_per_wisp(),
            states,
        });
        self.shares = None;
        self.posed = None;
        Ok(())
    }

    fn simulate(
        &mut self,
        anim: &mut Animator,
        plan: &StepPlan,
        stats: &mut FrameStats,
    ) -> Result<Option<PoseReport>, EngineError> {
        let report = stats
            .time(Stage::Simulate, || {
                self.with_survivors(|ex| ex.simulate(anim, plan))
            })
            .map_err(engine_error)?;
        stats.steps += plan.heads.len() as u32;
        Ok(Some(report))
    }

    fn density(
        &mut self,
        light: usize,
        map: &mut DensityMap,
        strands: Strands<'_>,
        _fiber: &Fiber,
    ) -> Result<FillStats, EngineError> {
        // Hair held on the workers needs no strands sent.
        let (hair, version) = match strands {
            Strands::Here { hair, posed } => (Some(hair), posed),
            Strands::Held { posed } => (None, Some(posed)),
        };
        if let Some(l) = self.lights.get_mut(light) {
            l.exchanged = None;
            l.swept_on_workers = None;
        }
        if self.draw.on_workers()
            && self.exchange.is_on()
            && self.sweeps_follow
            && version.is_some()
        {
            let before = self.workers.len();
            // A worker lost in the round is dropped, and the survivors
            // try again.
            let r = self.with_survivors(|ex| {
                ex.ensure_posed()?;
                if ex.workers.len() >= 2 && ex.posed == version {
                    ex.fill_exchanged(light, map, version.unwrap_or_default())
                        .map(Some)
                } else {
                    Ok(None)
                }
            });
            match r {
                Ok(Some(stats)) => return Ok(stats),
                Ok(None) => {}
                Err(e) if e.worker().is_none() => {
                    // This frame is summed and swept through the
                    // coordinator instead.
                    tracing::warn!(error = %e, "summing and sweeping on the workers failed; this frame's map goes through the coordinator");
                    self.clock(|t| t.exchange_fallbacks += 1);
                    if self.workers.len() == before && self.exchange.failed() {
                        tracing::warn!(
                            "the workers failed twice to sum and sweep together with none of them lost (can they reach each other at the addresses the coordinator dials? with TLS, do their certificates allow client use?); the coordinator sums and hands out the columns from now on"
                        );
                    }
                }
                Err(e) => return Err(engine_error(e)),
            }
        }
        // After a loss the survivors pose the lost worker's share again
        // (drawing on the workers), or are sent strands (drawing here).
        self.with_survivors(|ex| ex.fill_remote(light, map, hair, version))
            .map_err(engine_error)
    }

    fn transmittance(
        &mut self,
        light: usize,
        map: &DensityMap,
    ) -> Result<Transmittance, EngineError> {
        // Swept here (the coordinator's own copy) when the workers swept it
        // among themselves, or with one worker: its sweep runs beside nothing,
        // and sending it the map and taking its columns back costs more
        // than sweeping here (curly, one core a node: 7 ms a frame and 1
        // MB on the wire, against 1.5 ms here).
        let exchanged =
            self.posed.is_some() && self.lights.get(light).and_then(|l| l.exchanged) == self.posed;
        if exchanged || self.workers.len() == 1 {
            return self.sweep_here(light, map).map_err(engine_error);
        }
        self.with_survivors(|ex| ex.sweep_remote(light, map))
            .map_err(engine_error)
    }

    fn runs_elsewhere(&self) -> bool {
        true
    }

    /// Where the frame is drawn: the one place its scheme is decided
    /// (see `remote/choose.rs`).
    fn plan_frame(&mut self, needs: FrameNeeds) -> Site {
        self.plan(needs)
    }

    /// Whenever the workers may draw: frames are planned elsewhere only
    /// with two or more, but a frame planned so is finished (or drawn
    /// again) on the workers left, however few.
    fn drawing(&mut self) -> Option<&mut dyn Drawing> {
        self.draw.on_workers().then_some(self as &mut dyn Drawing)
    }
}

/// The workers hold the drawn hair (`--draw workers`).
impl Drawing for RemoteExecutor {
    fn pose(&mut self, plan: &PosePlan) -> Result<PoseReport, EngineError> {
        self.with_survivors(|ex| {
            if ex.shares.is_none() {
                ex.assign()?;
            }
            ex.pose_call(plan)
        })
        .map_err(engine_error)
    }

    fn composites(&self) -> bool {
        self.composites_now()
    }

    fn draw(&mut self, job: &DrawJob) -> Result<DrawReport, EngineError> {
        self.draw_with(job, false)
    }

    fn draw_ahead(&mut self, job: &DrawJob) -> Result<DrawReport, EngineError> {
        self.draw_with(job, true)
    }

    fn redraw(&mut self, job: &DrawJob) -> Result<DrawReport, EngineError> {
        let failed = self.failure.lock().ok().and_then(|mut f| f.take());
        let Some(then) = self.drawn.take().filter(|d| d.version == job.version) else {
            return self.draw(job);
        };
        // A worker the failure names is dropped (the last one cannot be).
        if let Some(e) = failed
            && e.worker()
                .is_some_and(|a| self.workers.iter().any(|w| w.addr == a))
        {
            self.lose_worker(e).map_err(engine_error)?;
        }
        // Back to the frame drawn: its wisps' states, pose and maps; the
        // workers are assigned and pose it again.
        let now = self.snapshot(self.posed.unwrap_or_default());
        self.restore(then);
        tracing::warn!(
            frame_version = job.version,
            "drawing the frame again, composited here"
        );
        let r = self.with_survivors(|ex| ex.draw_remote(job));
        // On to the frames after, as they stood.
        self.restore(now);
        r.map_err(engine_error)
    }
}

impl RemoteExecutor {
    fn addrs(&self) -> Vec<String> {
        self.workers.iter().map(|w| w.addr.clone()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::Collective;

    #[test]
    fn a_collective_step_turns_off_at_its_second_failure_and_stays_off() {
        let mut c = Collective::default();
        assert!(c.is_on());
        assert!(!c.failed(), "one failure leaves it on");
        assert!(c.is_on());
        assert!(c.failed(), "the second turns it off, and says so once");
        assert!(!c.is_on());
        assert!(!c.failed());
        assert_eq!(c, Collective::Off);
    }
}
