//! The coordinator's side: an [`engine::Executor`] that runs every stage
//! that grows with the hair on workers over gRPC, with the same bytes as
//! one process.
//!
//! Each live worker owns a contiguous share of the hair's groups (whole
//! wisps, weighted by their drawn strands) and, per sweep, a contiguous
//! share of the columns (weighted by their occupied cells). With
//! [`DrawAt::Workers`] (the default) a worker also poses, filters, shades
//! and rasterizes its strands into a partial picture, and the workers
//! composite the picture among themselves, each resolving bands of rows
//! it owns from the others' stripes (one worker's, or a round that failed,
//! the coordinator composites); with [`DrawAt::Coordinator`] (the paper's scheme) the
//! coordinator poses and draws every strand from the wisps' states. When a
//! worker fails a call (it died, missed the deadline, or sent something
//! malformed) it is dropped: its share goes to the survivors with the
//! state the coordinator gathered last, they pose it again, and the stage
//! runs again, so the frame comes out the same.

use std::ops::Range;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use engine::{
    Animator, DrawJob, DrawReport, EngineError, Executor, FrameStats, PendingPicture, PosePlan,
    PoseReport, Scene, SceneSource, Stage, StepPlan, split_by,
};
use prost::Message;
use shadow::{ColumnSlab, DensityMap, Fiber, FillStats, LightFrame, Transmittance};
use sim::WispState;
use strands::Hair;

use crate::client::{Remote, call_error, collect, fan_out, fan_out_all, hello, malformed};
use crate::{ClusterError, Timing, Tls, Traffic, pb, wire};

/// Rows of each band the workers composite (whole canvas bands): bands
/// dealt to the workers in turn share the hair out evenly; 720 rows make
/// 15 bands.
const BAND_ROWS: u32 = 48;

/// Where the drawn hair is posed, filtered, shaded and rasterized.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DrawAt {
    /// On the workers, each its own strands; with two or more, they
    /// composite the picture among themselves (bands of rows dealt out),
    /// otherwise the coordinator composites their partial pictures.
    #[default]
    Workers,
    /// On the coordinator, every strand (the paper's scheme: workers
    /// simulate, fill and sweep).
    Coordinator,
}

impl DrawAt {
    pub fn name(self) -> &'static str {
        match self {
            DrawAt::Workers => "workers",
            DrawAt::Coordinator => "coordinator",
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
    /// Whether lookups filter (the workers' columns read depend on it).
    filter: bool,
    hair: Option<SharedHair>,
    /// Each live worker's groups, once assigned.
    shares: Option<Vec<Range<usize>>>,
    /// The hair version the workers posed last, that pose's plan and
    /// report.
    posed: Option<u64>,
    last_pose: Option<PosePlan>,
    report: Option<PoseReport>,
    /// Per light, the columns each live worker's lookups read (from its
    /// last posed Deposit), in worker order.
    reads: Vec<Option<Vec<Vec<u64>>>>,
    /// Per light, the frame and slabs of its last sweep.
    swept: Vec<Option<Swept>>,
    /// Whether the workers composite the picture among themselves (two
    /// or more drawing): on until they fail to twice with none lost.
    composite: bool,
    composite_failures: u32,
    /// Whether the workers sum and sweep each light's map among
    /// themselves (two or more drawing): on until they fail to twice with
    /// none lost.
    exchange: bool,
    exchange_failures: u32,
    /// Whether the maps filled are swept for the frame's shadows (the
    /// density-map method, self-shadowing on); otherwise a fill is the
    /// self-collisions' alone, and the workers need not sweep it.
    sweeps_follow: bool,
    /// Per light, the hair version whose map the live workers last summed
    /// and swept among themselves (each holding every column for its Draw).
    exchanged: Vec<Option<u64>>,
    /// Per light, the hair version whose map's transmittance came from the
    /// workers' own sweep (the frame's shadow map, not another map filled
    /// on the workers such as a separate self-collision map).
    swept_on_workers: Vec<Option<u64>>,
    /// Per light, each column's weight in the last map (its occupied
    /// cells), for cutting the next map's columns among the workers.
    column_weights: Vec<Option<Vec<u32>>>,
    /// Whether the head is shadowed by the hair (the workers resolving
    /// bands shade it: they get every swept column); also whether the
    /// head is in the maps, as an occluder.
    head_shadow: bool,
    /// The name expected in workers' certificates, for their calls to
    /// each other.
    tls_domain: Option<String>,
    /// The first failure of a picture left to finish (see
    /// [`Executor::draw_ahead`]), for [`Executor::redraw`].
    failure: Arc<Mutex<Option<ClusterError>>>,
    /// What the workers held when they drew the picture left to finish.
    drawn: Option<Drawn>,
}

/// A light's last sweep: its frame and slabs.
type Swept = Arc<SweptMap>;

/// A light's last sweep: its frame and slabs, or (when the workers summed
/// and swept it among themselves) the summed map, swept here only if a
/// frame must be drawn from it through the coordinator.
#[derive(Debug)]
struct SweptMap {
    frame: LightFrame,
    slabs: std::sync::OnceLock<Vec<ColumnSlab>>,
    map: Option<DensityMap>,
}

impl SweptMap {
    fn of_slabs(frame: LightFrame, slabs: Vec<ColumnSlab>) -> SweptMap {
        SweptMap {
            frame,
            slabs: std::sync::OnceLock::from(slabs),
            map: None,
        }
    }

    fn of_map(map: DensityMap) -> SweptMap {
        SweptMap {
            frame: *map.frame(),
            slabs: std::sync::OnceLock::new(),
            map: Some(map),
        }
    }

    /// The frame and its slabs (of every column).
    fn get(&self) -> (&LightFrame, &[ColumnSlab]) {
        let slabs = self.slabs.get_or_init(|| {
            let map = self.map.as_ref().expect("a sweep has its slabs or its map");
            vec![shadow::sweep(map, 0..self.frame.columns() as u32)]
        });
        (&self.frame, slabs)
    }
}

/// What drawing a frame again takes, kept while its picture is finished
/// on the workers and the next frame's stages run.
#[derive(Debug)]
struct Drawn {
    version: u64,
    states: Vec<WispState>,
    pose: Option<PosePlan>,
    swept: Vec<Option<Swept>>,
    reads: Vec<Option<Vec<Vec<u64>>>>,
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
                    tokio::spawn(async move {
                        let greet = hello(&addr, &fiber, connect, tls.as_ref());
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
        // A worker that cannot be reached or does not answer is left out,
        // as one lost mid-run would be; one that refuses (another protocol
        // version, no room for another session) stops the run: it is set
        // up wrong.
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
            filter: scene.shadow.method.filter(),
            reads: vec![None; scene.lights.len()],
            swept: vec![None; scene.lights.len()],
            composite: true,
            composite_failures: 0,
            exchange: true,
            exchange_failures: 0,
            sweeps_follow: scene.effects.self_shadow
                && matches!(scene.shadow.method, shadow::MethodConfig::DensityMap { .. }),
            exchanged: vec![None; scene.lights.len()],
            swept_on_workers: vec![None; scene.lights.len()],
            column_weights: vec![None; scene.lights.len()],
            head_shadow: scene.head.is_some() && scene.effects.head_shadow,
            tls_domain: options
                .tls
                .as_ref()
                .and_then(|t| t.domain().map(str::to_string)),
            failure: Arc::default(),
            drawn: None,
            source: scene.source,
            hair: None,
            shares: None,
            posed: None,
            last_pose: None,
            report: None,
        })
    }

    /// A handle on where the remote stages' time went.
    pub fn timing(&self) -> Arc<Mutex<Timing>> {
        self.timing.clone()
    }

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
        self.shares = None;
        self.posed = None;
        self.reads.iter_mut().for_each(|r| *r = None);
        self.exchanged.iter_mut().for_each(|x| *x = None);
        self.swept_on_workers.iter_mut().for_each(|x| *x = None);
        self.clock(|t| t.workers_lost += 1);
        tracing::warn!(
            error = %e,
            survivors = self.workers.len(),
            "worker lost; its share of the hair and its columns go to the survivors"
        );
        Ok(())
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

    /// Shares the groups out over the live workers, with the scene and
    /// the wisps' state gathered last.
    fn assign(&mut self) -> Result<(), ClusterError> {
        let hair = self.hair()?;
        let weights = &hair.strands;
        let shares = split_by(weights.len(), self.workers.len(), |g| weights[g] + 1);
        let wisp_range = |g: &Range<usize>| match &hair.wisps {
            Some(w) => w[g.start] as usize..w[g.end] as usize,
            None => 0..0,
        };
        let files: Vec<(String, &[u8])> = self
            .source
            .files
            .iter()
            .map(|(p, b)| (p.to_string_lossy().into_owned(), &b[..]))
            .collect();
        let mut requests = Vec::with_capacity(shares.len());
        let mut sent = 0u64;
        for (w, share) in self.workers.iter().zip(&shares) {
            let wisps = wisp_range(share);
            let mut text = wire::text_pieces(&self.source.text, wire::TEXT_PIECE_BYTES);
            let mut chunks = vec![pb::AssignChunk {
                scene_toml: text.next().unwrap_or_default().to_string(),
                scene_path: self.source.path.to_string_lossy().into_owned(),
                first_group: share.start as u32,
                end_group: share.end as u32,
                ..Default::default()
            }];
            chunks.extend(text.map(|t| pb::AssignChunk {
                scene_toml: t.to_string(),
                ..Default::default()
            }));
            if !wisps.is_empty() {
                let states = &hair.states[wisps.clone()];
                chunks.extend(wire::wisp_chunks(wisps.start, states).into_iter().map(|s| {
                    pb::AssignChunk {
                        state: Some(s),
                        ..Default::default()
                    }
                }));
            }
            for (path, bytes) in &files {
                for (i, piece) in bytes.chunks(1 << 20).enumerate() {
                    chunks.push(pb::AssignChunk {
                        file_path: if i == 0 { path.clone() } else { String::new() },
                        file_data: piece.to_vec(),
                        ..Default::default()
                    });
                }
            }
            sent += chunks.iter().map(|c| c.encoded_len() as u64).sum::<u64>();
            requests.push((w.clone(), (chunks, wisps)));
        }
        let (per, groups) = (hair.points_per_wisp as u32, weights.len() as u32);
        fan_out(
            &self.rt,
            requests,
            "assign",
            self.deadline,
            move |mut w, (chunks, wisps)| async move {
                let reply = w
                    .client
                    .assign(tokio_stream::iter(chunks))
                    .await
                    .map_err(|s| call_error(&w.addr, "assign", s))?
                    .into_inner();
                let theirs = reply.first_wisp as usize..reply.end_wisp as usize;
                if reply.groups != groups
                    || (!wisps.is_empty() && (reply.points_per_wisp != per || theirs != wisps))
                {
                    return Err(malformed(
                        &w.addr,
                        format!(
                            "the worker made {} groups, wisps {theirs:?} of {} guide points; the coordinator {groups} groups, wisps {wisps:?} of {per}",
                            reply.groups, reply.points_per_wisp
                        ),
                    ));
                }
                Ok(())
            },
        )?;
        tracing::info!(shares = ?shares, "groups assigned");
        self.count(|t| t.assign_sent += sent);
        self.shares = Some(shares);
        Ok(())
    }

    /// Assigns the shares after a loss and poses them again as last posed:
    /// the survivors then hold every strand as the lost worker held it.
    fn ensure_posed(&mut self) -> Result<(), ClusterError> {
        if self.shares.is_none() {
            self.assign()?;
        }
        if self.posed.is_none()
            && let Some(plan) = self.last_pose.clone()
        {
            self.pose_call(&plan)?;
        }
        Ok(())
    }

    /// One Step on every worker; the new states go into `anim` only when
    /// every worker answered.
    fn step(&mut self, anim: &mut Animator, plan: &StepPlan) -> Result<(), ClusterError> {
        if self.shares.is_none() {
            self.assign()?;
        }
        let shares = self.shares.clone().expect("assigned above");
        let hair = self.hair()?;
        let (per, lights) = (hair.points_per_wisp, plan.pose.lights.len());
        let wisps: Vec<Range<usize>> = shares
            .iter()
            .map(|g| match &hair.wisps {
                Some(w) => w[g.start] as usize..w[g.end] as usize,
                None => 0..0,
            })
            .collect();
        let mut base = pb::StepRequest {
            frame_id: plan.pose.version,
            has_accel: plan.accel.is_some(),
            pose: Some(wire::pose_plan_to_pb(&plan.pose)),
            ..Default::default()
        };
        for (h, b) in plan.heads.iter().zip(&plan.bodies) {
            wire::affine_to_floats(h, &mut base.heads);
            base.body_counts.push(b.len() as u32);
            wire::bodies_to_floats(b, &mut base.bodies);
        }
        let mut requests = Vec::with_capacity(shares.len());
        let mut sent = 0u64;
        for (w, share) in self.workers.iter().zip(&wisps) {
            let mut r = base.clone();
            if let Some(a) = &plan.accel {
                (r.accel_skip, r.accel) = wire::accel_to_pb(&a[share.start * per..share.end * per]);
            }
            sent += r.encoded_len() as u64;
            requests.push((w.clone(), (r, share.clone())));
        }
        let t = Instant::now();
        let replies = fan_out(
            &self.rt,
            requests,
            "step",
            self.deadline,
            move |mut w, (r, share)| async move {
                let s = w
                    .client
                    .step(r)
                    .await
                    .map_err(|s| call_error(&w.addr, "step", s))?
                    .into_inner();
                let chunks = collect(&w.addr, "step", s).await?;
                let mut states = Vec::with_capacity(share.len());
                let (mut bytes, mut compute, mut report) = (0u64, 0.0f64, None);
                for c in &chunks {
                    bytes += c.encoded_len() as u64;
                    compute += c.compute_ms;
                    states.extend(
                        wire::wisps_from_chunk(c, per, &share)
                            .map_err(|e| malformed(&w.addr, e))?,
                    );
                    if let Some(r) = &c.report {
                        report = Some(
                            wire::report_from_pb(r, lights).map_err(|e| malformed(&w.addr, e))?,
                        );
                    }
                }
                let in_order = states.iter().map(|(i, _)| *i).eq(share.clone());
                if !in_order {
                    return Err(malformed(
                        &w.addr,
                        format!("the states of wisps {share:?} did not come whole and in order"),
                    ));
                }
                let report = report
                    .ok_or_else(|| malformed(&w.addr, "a Step reply without its pose's report"))?;
                Ok((w.addr, states, report, bytes, compute))
            },
        )?;
        let wall = t.elapsed().as_secs_f64() * 1e3;
        let mut received = 0u64;
        let mut slowest = 0.0f64;
        let mut reports = Vec::with_capacity(replies.len());
        for (addr, states, report, bytes, compute) in replies {
            received += bytes;
            slowest = slowest.max(compute);
            for (i, state) in states {
                anim.set_wisp_state(i, state.clone())
                    .map_err(|e| malformed(&addr, e))?;
                if let Some(h) = &mut self.hair {
                    h.states[i] = state;
                }
            }
            reports.push(report);
        }
        self.count(|t| {
            t.step_sent += sent;
            t.wisps_received += received;
        });
        self.clock(|t| {
            t.step_wall_ms += wall;
            t.step_compute_ms += slowest;
        });
        self.posed_as(&plan.pose, reports);
        Ok(())
    }

    /// Notes that the workers posed the hair as `plan` says.
    fn posed_as(&mut self, plan: &PosePlan, reports: Vec<PoseReport>) {
        let mut reports = reports.into_iter();
        let first = reports.next();
        self.report = first.map(|f| reports.fold(f, |a, b| a.union(&b)));
        self.posed = Some(plan.version);
        self.last_pose = Some(plan.clone());
    }

    /// One Pose on every worker.
    fn pose_call(&mut self, plan: &PosePlan) -> Result<(), ClusterError> {
        let request = wire::pose_plan_to_pb(plan);
        let lights = plan.lights.len();
        let sent = request.encoded_len() as u64 * self.workers.len() as u64;
        let requests: Vec<_> = self
            .workers
            .iter()
            .map(|w| (w.clone(), request.clone()))
            .collect();
        let t = Instant::now();
        let replies = fan_out(
            &self.rt,
            requests,
            "pose",
            self.deadline,
            move |mut w, r| async move {
                let reply = w
                    .client
                    .pose(r)
                    .await
                    .map_err(|s| call_error(&w.addr, "pose", s))?
                    .into_inner();
                let bytes = reply.encoded_len() as u64;
                let report =
                    wire::report_from_pb(&reply, lights).map_err(|e| malformed(&w.addr, e))?;
                Ok((report, bytes))
            },
        )?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let received: u64 = replies.iter().map(|(_, b)| b).sum();
        self.count(|t| t.pose += sent + received);
        self.clock(|t| t.pose_ms += ms);
        self.posed_as(plan, replies.into_iter().map(|(r, _)| r).collect());
        Ok(())
    }

    /// The Deposit requests of one fill: the workers' posed strands when
    /// they hold hair `version`, else shares of `hair`'s strands.
    fn deposit_requests(
        &self,
        id: u64,
        light: u32,
        frame: &LightFrame,
        hair: &Hair,
        version: Option<u64>,
    ) -> Vec<(Remote, Vec<pb::DepositChunk>)> {
        if version.is_some() && version == self.posed && self.shares.is_some() {
            return self
                .workers
                .iter()
                .map(|w| {
                    let c = pb::DepositChunk {
                        frame_id: id,
                        light,
                        map: Some(wire::frame_to_pb(frame)),
                        posed: true,
                        version: version.unwrap_or_default(),
                        filter: self.filter,
                        ..Default::default()
                    };
                    (w.clone(), vec![c])
                })
                .collect();
        }
        let offsets = hair.offsets();
        let shares = split_by(hair.strand_count(), self.workers.len(), |s| {
            u64::from(offsets[s + 1] - offsets[s]) + 1
        });
        self.workers
            .iter()
            .zip(shares)
            .map(|(w, share)| {
                (
                    w.clone(),
                    wire::deposit_chunks(id, light, frame, hair, share),
                )
            })
            .collect()
    }

    /// One Deposit round in which the workers sum and sweep light
    /// `light`'s map among themselves (see [`wire::ColumnPlan`]): `map`
    /// gets the sum of every worker's columns, each as its owner summed
    /// it. Any failure of the round is the round's ([`ClusterError::Exchange`]),
    /// but for a worker that failed its own call, which is named.
    fn fill_exchanged(
        &mut self,
        light: usize,
        map: &mut DensityMap,
        version: u64,
    ) -> Result<FillStats, ClusterError> {
        let frame = *map.frame();
        let n = self.workers.len();
        let columns = frame.columns();
        let weights = self
            .column_weights
            .get(light)
            .and_then(|w| w.as_ref())
            .filter(|w| w.len() == columns);
        let cuts = wire::ColumnPlan::cuts(columns, n, |c| weights.map_or(1, |w| u64::from(w[c])));
        let head = if self.head_shadow {
            match &self.last_pose {
                Some(p) if p.version == version => Some(p.head),
                _ => {
                    return Err(ClusterError::Exchange(format!(
                        "the head's pose for hair version {version} is not known here"
                    )));
                }
            }
        } else {
            None
        };
        self.calls += 1;
        let round = self.calls;
        let peers: Vec<(String, String)> = self
            .workers
            .iter()
            .map(|w| (w.addr.clone(), w.session.clone()))
            .collect();
        let mut requests = Vec::with_capacity(n);
        let mut sent = 0u64;
        for (i, w) in self.workers.iter().enumerate() {
            let plan = wire::ColumnPlan {
                round,
                cuts: cuts.clone(),
                own: i,
                peers: peers.clone(),
                wait: self.deadline / 2,
                tls_domain: self.tls_domain.clone(),
                head,
            };
            let c = pb::DepositChunk {
                frame_id: version,
                light: light as u32,
                map: Some(wire::frame_to_pb(&frame)),
                posed: true,
                version,
                filter: self.filter,
                columns: Some(plan.to_pb()),
                ..Default::default()
            };
            sent += c.encoded_len() as u64;
            requests.push((w.clone(), (c, plan.range(i))));
        }
        let t = Instant::now();
        let replies = fan_out_all(
            &self.rt,
            requests,
            "deposit",
            self.deadline,
            move |mut w, (chunk, range)| async move {
                // A worker that gave up for another's sake names no
                // worker to drop: the one at fault fails on its own.
                let failed = |e: tonic::Status| match e.code() {
                    tonic::Code::Aborted => {
                        ClusterError::Exchange(format!("worker {}: {}", w.addr, e.message()))
                    }
                    _ => call_error(&w.addr, "deposit", e),
                };
                let mut s = w
                    .client
                    .deposit(tokio_stream::iter([chunk]))
                    .await
                    .map_err(failed)?
                    .into_inner();
                let mut got = Gathered::default();
                let mut between = (0u64, 0u64);
                while let Some(c) = s.message().await.map_err(failed)? {
                    let d = wire::decode_columns(&frame, &c).map_err(|e| malformed(&w.addr, e))?;
                    if !d.within(range.clone()) {
                        return Err(malformed(
                            &w.addr,
                            format!("summed columns past its own, {range:?}"),
                        ));
                    }
                    got.columns.push(d);
                    got.bytes += c.encoded_len() as u64;
                    got.samples += c.samples;
                    got.out_of_map += c.out_of_map;
                    between.0 += c.exchanged_density;
                    between.1 += c.exchanged_swept;
                }
                Ok((got, between))
            },
        );
        // A worker at fault is named before a round given up for its sake.
        let mut gathered = Vec::with_capacity(n);
        let mut first_error: Option<ClusterError> = None;
        for r in replies {
            match r {
                Ok(g) => gathered.push(g),
                Err(e) => {
                    if first_error
                        .as_ref()
                        .is_none_or(|f| f.worker().is_none() && e.worker().is_some())
                    {
                        first_error = Some(e);
                    }
                }
            }
        }
        if let Some(e) = first_error {
            return Err(e);
        }
        let mut stats = FillStats::default();
        let (mut received, mut density_between, mut swept_between) = (0u64, 0u64, 0u64);
        for (got, between) in &gathered {
            received += got.bytes;
            stats.samples += got.samples;
            stats.out_of_map += got.out_of_map;
            density_between += between.0;
            swept_between += between.1;
            for d in &got.columns {
                wire::add_columns(map, d);
            }
        }
        // The next map's columns are cut by this one's.
        if let Some(w) = self.column_weights.get_mut(light) {
            *w = Some(
                (0..columns)
                    .map(|c| {
                        let m = map.meta(c);
                        if m.is_empty() {
                            1
                        } else {
                            u32::from(m.hi - m.lo) + 2
                        }
                    })
                    .collect(),
            );
        }
        if let Some(x) = self.exchanged.get_mut(light) {
            *x = Some(version);
        }
        if let Some(r) = self.reads.get_mut(light) {
            *r = None;
        }
        tracing::debug!(
            frame_id = version,
            light,
            "density summed and swept on the workers"
        );
        self.count(|t| {
            t.strands_sent += sent;
            t.density_received += received;
            t.density_between_workers += density_between;
            t.swept_between_workers += swept_between;
        });
        let ms = t.elapsed().as_secs_f64() * 1e3;
        self.clock(|x| x.fill_ms += ms);
        Ok(stats)
    }

    /// The transmittance of a map the workers summed and swept among
    /// themselves, swept again here: for the head drawn here; the map is
    /// kept, to sweep into slabs if a frame must be drawn again after a
    /// failure.
    fn sweep_here(
        &mut self,
        light: usize,
        map: &DensityMap,
    ) -> Result<Transmittance, ClusterError> {
        let t = Instant::now();
        let trans = Transmittance::compute(map);
        if let Some(s) = self.swept.get_mut(light) {
            *s = Some(Arc::new(SweptMap::of_map(map.clone())));
        }
        if let Some(x) = self.swept_on_workers.get_mut(light) {
            *x = self.exchanged.get(light).copied().flatten();
        }
        let ms = t.elapsed().as_secs_f64() * 1e3;
        self.clock(|x| x.sweep_ms += ms);
        Ok(trans)
    }

    fn fill_remote(
        &mut self,
        light: usize,
        map: &mut DensityMap,
        hair: &Hair,
        version: Option<u64>,
    ) -> Result<FillStats, ClusterError> {
        if self.draw == DrawAt::Workers {
            self.ensure_posed()?;
        }
        let id = version.unwrap_or_else(|| {
            self.calls += 1;
            self.calls
        });
        let frame = *map.frame();
        let requests = self.deposit_requests(id, light as u32, &frame, hair, version);
        let posed = requests.first().is_some_and(|(_, c)| c[0].posed);
        if !posed && hair.strand_count() == 0 {
            return Err(ClusterError::Setup(format!(
                "the workers hold hair version {:?}, not {version:?}, and no strands were given",
                self.posed
            )));
        }
        let sent: u64 = requests
            .iter()
            .flat_map(|(_, c)| c)
            .map(|c| c.encoded_len() as u64)
            .sum();
        let t = Instant::now();
        let replies = fan_out(
            &self.rt,
            requests,
            "deposit",
            self.deadline,
            move |mut w, chunks| async move {
                let mut s = w
                    .client
                    .deposit(tokio_stream::iter(chunks))
                    .await
                    .map_err(|s| call_error(&w.addr, "deposit", s))?
                    .into_inner();
                // Each chunk is decoded as it comes (the other workers'
                // replies still travel), and checked before the map changes.
                let mut got = Gathered::default();
                let mut last = None;
                while let Some(c) = s
                    .message()
                    .await
                    .map_err(|e| call_error(&w.addr, "deposit", e))?
                {
                    let d = wire::decode_columns(&frame, &c).map_err(|e| malformed(&w.addr, e))?;
                    got.columns.push(d);
                    got.bytes += c.encoded_len() as u64;
                    got.samples += c.samples;
                    got.out_of_map += c.out_of_map;
                    last = Some(c.columns_read);
                }
                if posed {
                    let last = last.ok_or_else(|| malformed(&w.addr, "an empty Deposit reply"))?;
                    got.read = Some(
                        wire::columns_from_pb(&last, frame.columns())
                            .map_err(|e| malformed(&w.addr, e))?,
                    );
                }
                Ok(got)
            },
        )?;
        // Merge in worker order (integer sums: any order gives the same
        // map).
        let mut stats = FillStats::default();
        let mut received = 0u64;
        let mut decoded = Vec::with_capacity(replies.len());
        let mut reads = Vec::with_capacity(replies.len());
        for got in replies {
            received += got.bytes;
            stats.samples += got.samples;
            stats.out_of_map += got.out_of_map;
            decoded.extend(got.columns);
            reads.extend(got.read);
        }
        for d in &decoded {
            wire::add_columns(map, d);
        }
        if let Some(r) = self.reads.get_mut(light) {
            *r = posed.then_some(reads);
        }
        tracing::debug!(frame_id = id, light, posed, "density gathered");
        self.count(|t| {
            t.strands_sent += sent;
            t.density_received += received;
        });
        let ms = t.elapsed().as_secs_f64() * 1e3;
        self.clock(|x| x.fill_ms += ms);
        Ok(stats)
    }

    fn sweep_remote(
        &mut self,
        light: usize,
        map: &DensityMap,
    ) -> Result<Transmittance, ClusterError> {
        let frame = *map.frame();
        let n = frame.columns();
        let shares = split_by(n, self.workers.len(), |c| {
            let m = map.meta(c);
            if m.is_empty() {
                1
            } else {
                u64::from(m.hi - m.lo) + 2
            }
        });
        self.calls += 1;
        let id = self.calls;
        let mut requests = Vec::with_capacity(shares.len());
        let mut sent = 0u64;
        for (w, share) in self.workers.iter().zip(&shares) {
            let mut chunks = wire::column_chunks(map, share.clone());
            let first = &mut chunks[0];
            first.frame_id = id;
            first.light = light as u32;
            first.map = Some(wire::frame_to_pb(&frame));
            first.first_column = share.start as u32;
            first.end_column = share.end as u32;
            sent += chunks.iter().map(|c| c.encoded_len() as u64).sum::<u64>();
            // The spans the slab will have: those of the density sent.
            let range = share.start as u32..share.end as u32;
            requests.push((w.clone(), (chunks, ColumnSlab::layout(map, range))));
        }
        let t = Instant::now();
        let replies = fan_out(
            &self.rt,
            requests,
            "sweep",
            self.deadline,
            move |mut w, (chunks, layout)| async move {
                let s = w
                    .client
                    .sweep(tokio_stream::iter(chunks))
                    .await
                    .map_err(|s| call_error(&w.addr, "sweep", s))?
                    .into_inner();
                let mut reader = wire::SlabReader::new(layout);
                let mut bytes = 0u64;
                for c in collect(&w.addr, "sweep", s).await? {
                    bytes += c.encoded_len() as u64;
                    reader.add(&c).map_err(|e| malformed(&w.addr, e))?;
                }
                let slab = reader.finish().map_err(|e| malformed(&w.addr, e))?;
                Ok((w.addr, slab, bytes))
            },
        )?;
        let received: u64 = replies.iter().map(|(_, _, b)| b).sum();
        let slabs: Vec<ColumnSlab> = replies.into_iter().map(|(_, s, _)| s).collect();
        // Each reader already refused, naming its worker, whatever does not
        // fit the spans the coordinator sent; `assemble` checks once more.
        let trans = Transmittance::assemble(frame, slabs.iter().cloned())
            .map_err(|e| malformed("workers", e))?;
        if self.draw == DrawAt::Workers
            && let Some(s) = self.swept.get_mut(light)
        {
            *s = Some(Arc::new(SweptMap::of_slabs(frame, slabs)));
        }
        let ms = t.elapsed().as_secs_f64() * 1e3;
        self.count(|x| {
            x.density_sent += sent;
            x.slabs_received += received;
        });
        self.clock(|x| x.sweep_ms += ms);
        tracing::debug!(frame_id = id, light, "transmittance gathered");
        Ok(trans)
    }

    fn draw_remote(&mut self, job: &DrawJob) -> Result<DrawReport, ClusterError> {
        self.ensure_posed()?;
        if self.posed != Some(job.version) {
            return Err(ClusterError::Setup(format!(
                "the workers hold hair version {:?}, not {}",
                self.posed, job.version
            )));
        }
        let first = pb::DrawChunk {
            job: Some(wire::job_to_pb(job)),
            ..Default::default()
        };
        let mut requests = Vec::with_capacity(self.workers.len());
        let mut sent = 0u64;
        for (i, w) in self.workers.iter().enumerate() {
            let mut chunks = vec![first.clone()];
            if job.shadows {
                for (l, swept) in self.swept.iter().enumerate() {
                    let (frame, slabs) = swept
                        .as_ref()
                        .ok_or_else(|| {
                            ClusterError::Setup(format!("light {l} was not swept before drawing"))
                        })?
                        .get();
                    // The columns this worker reads; all of them after a loss.
                    let keep = self.reads[l].as_ref().and_then(|r| r.get(i));
                    chunks.extend(wire::draw_columns(
                        l as u32,
                        frame,
                        slabs,
                        keep.map(|k| &k[..]),
                    ));
                }
            }
            sent += chunks.iter().map(|c| c.encoded_len() as u64).sum::<u64>();
            requests.push((w.clone(), chunks));
        }
        let (width, height) = (job.camera.width(), job.camera.height());
        let t = Instant::now();
        let replies = fan_out(
            &self.rt,
            requests,
            "draw",
            self.deadline,
            move |mut w, chunks| async move {
                let mut s = w
                    .client
                    .draw(tokio_stream::iter(chunks))
                    .await
                    .map_err(|s| call_error(&w.addr, "draw", s))?
                    .into_inner();
                let mut reader = wire::LayerReader::new(width, height);
                let mut bytes = 0u64;
                // Each chunk is decoded as it comes, while the rest travel.
                while let Some(c) = s
                    .message()
                    .await
                    .map_err(|e| call_error(&w.addr, "draw", e))?
                {
                    bytes += c.encoded_len() as u64;
                    reader.add(&c).map_err(|e| malformed(&w.addr, e))?;
                }
                let times = reader.times;
                let layer = reader.finish().map_err(|e| malformed(&w.addr, e))?;
                Ok((layer, times, bytes))
            },
        )?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let mut report = DrawReport::default();
        let mut received = 0u64;
        let mut slowest = 0.0f64;
        for (layer, times, bytes) in replies {
            received += bytes;
            report.filter_ms = report.filter_ms.max(times.filter_ms);
            report.shade_ms = report.shade_ms.max(times.shade_ms);
            report.raster_ms = report.raster_ms.max(times.raster_ms);
            slowest = slowest.max(times.filter_ms + times.shade_ms + times.raster_ms);
            report.layers.push(layer);
        }
        self.count(|x| {
            x.draw_sent += sent;
            x.layers_received += received;
        });
        self.clock(|x| {
            x.draw_ms += ms;
            x.draw_compute_ms += slowest;
        });
        Ok(report)
    }
}

impl RemoteExecutor {
    /// Whether the next Draw is composited on the workers.
    fn composites_now(&self) -> bool {
        self.draw == DrawAt::Workers && self.composite && self.workers.len() >= 2
    }

    /// One Draw round composited on the workers (see [`wire::Bands`]): each
    /// resolves a band of rows and sends it finished. Any failure fails the
    /// round (the caller composites the frame here instead); no worker is
    /// dropped for it.
    fn draw_composited(&mut self, job: &DrawJob, ahead: bool) -> Result<DrawReport, ClusterError> {
        self.ensure_posed()?;
        if self.posed != Some(job.version) {
            return Err(ClusterError::Setup(format!(
                "the workers hold hair version {:?}, not {}",
                self.posed, job.version
            )));
        }
        let n = self.workers.len();
        let (width, height) = (job.camera.width(), job.camera.height());
        self.calls += 1;
        let round = self.calls;
        let peers: Vec<(String, String)> = self
            .workers
            .iter()
            .map(|w| (w.addr.clone(), w.session.clone()))
            .collect();
        // The workers hold every column when they swept them together.
        let exchanged = job.shadows
            && self.posed == Some(job.version)
            && self
                .swept_on_workers
                .iter()
                .all(|x| *x == Some(job.version));
        // The workers' columns go with this Draw.
        self.swept_on_workers.iter_mut().for_each(|x| *x = None);
        // Band owners shade the head under the hair's shadow: every column.
        let all_columns = job.shadows && self.head_shadow;
        let mut shared = Vec::new();
        let columns = |ex: &Self, i: usize, out: &mut Vec<pb::DrawChunk>| {
            for (l, swept) in ex.swept.iter().enumerate() {
                let (frame, slabs) = swept
                    .as_ref()
                    .ok_or_else(|| {
                        ClusterError::Setup(format!("light {l} was not swept before drawing"))
                    })?
                    .get();
                let keep = if all_columns {
                    None
                } else {
                    ex.reads[l].as_ref().and_then(|r| r.get(i))
                };
                out.extend(wire::draw_columns(
                    l as u32,
                    frame,
                    slabs,
                    keep.map(|k| &k[..]),
                ));
            }
            Ok::<_, ClusterError>(())
        };
        if job.shadows && all_columns && !exchanged {
            columns(self, 0, &mut shared)?;
        }
        let mut pb_job = wire::job_to_pb(job);
        pb_job.exchanged = exchanged;
        let mut requests = Vec::with_capacity(n);
        let mut sent = 0u64;
        for (i, w) in self.workers.iter().enumerate() {
            let bands = wire::Bands {
                round,
                plan: engine::BandPlan::dealt(height, BAND_ROWS, n, i),
                peers: peers.clone(),
                wait: self.deadline / 2,
                tls_domain: self.tls_domain.clone(),
            };
            let rows = bands.plan.rows_of(i);
            let mut chunks = vec![pb::DrawChunk {
                job: Some(pb_job.clone()),
                bands: Some(bands.to_pb()),
                ..Default::default()
            }];
            if job.shadows && !exchanged {
                if all_columns {
                    chunks.extend(shared.iter().cloned());
                } else {
                    columns(self, i, &mut chunks)?;
                }
            }
            sent += chunks.iter().map(|c| c.encoded_len() as u64).sum::<u64>();
            requests.push((w.clone(), (chunks, rows)));
        }
        let deadline = self.deadline;
        let t = Instant::now();
        // Each worker's reply: first the word that it rasterized and sent
        // its stripes (with its times), then its bands once composited.
        let (mut drawn, mut tasks) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for (mut w, (chunks, rows)) in requests {
            let (said, hear) = tokio::sync::oneshot::channel();
            drawn.push(hear);
            tasks.push(self.rt.spawn(async move {
                let addr = w.addr.clone();
                let call = async move {
                    let mut s = w
                        .client
                        .draw(tokio_stream::iter(chunks))
                        .await
                        .map_err(|s| call_error(&w.addr, "draw", s))?
                        .into_inner();
                    let first = s
                        .message()
                        .await
                        .map_err(|e| call_error(&w.addr, "draw", e))?
                        .filter(|c| c.drawn)
                        .ok_or_else(|| malformed(&w.addr, "a band reply without its first word"))?;
                    let mut bytes = first.encoded_len() as u64;
                    let _ = said.send(first);
                    let mut reader = wire::BandReader::new(width, height, rows);
                    // A worker that gave up for another's sake names no
                    // worker to drop: the one at fault fails on its own.
                    let failed = |e: tonic::Status| match e.code() {
                        tonic::Code::Aborted => {
                            ClusterError::Composite(format!("worker {}: {}", w.addr, e.message()))
                        }
                        _ => call_error(&w.addr, "draw", e),
                    };
                    while let Some(c) = s.message().await.map_err(failed)? {
                        bytes += c.encoded_len() as u64;
                        reader.add(&c).map_err(|e| malformed(&w.addr, e))?;
                    }
                    let (times, stripes) = (reader.times, reader.stripes_sent);
                    let bands = reader.finish().map_err(|e| malformed(&w.addr, e))?;
                    Ok(BandReply {
                        bands,
                        times,
                        bytes,
                        stripes,
                    })
                };
                match tokio::time::timeout(deadline, call).await {
                    Ok(r) => r,
                    Err(_) => Err(ClusterError::Deadline {
                        addr,
                        stage: "draw",
                        secs: deadline.as_secs_f64(),
                    }),
                }
            }));
        }
        self.count(|x| x.draw_sent += sent);
        // Until every worker has rasterized: a failure before is this
        // round's, and the frame is composited here at once.
        let words = self.rt.block_on(async {
            let mut out = Vec::with_capacity(n);
            for hear in drawn {
                out.push(hear.await.ok());
            }
            out
        });
        let mut report = DrawReport::default();
        let mut slowest = 0.0f64;
        for w in &words {
            let Some(c) = w else { continue };
            report.filter_ms = report.filter_ms.max(c.filter_ms);
            report.shade_ms = report.shade_ms.max(c.shade_ms);
            report.raster_ms = report.raster_ms.max(c.raster_ms);
            slowest = slowest.max(c.filter_ms + c.shade_ms + c.raster_ms);
        }
        let round = BandRound {
            rt: self.rt.handle().clone(),
            tasks,
            width,
            height,
            traffic: self.traffic.clone(),
            timing: self.timing.clone(),
        };
        if words.iter().any(Option::is_none) {
            let e = round.finish().err().unwrap_or_else(|| {
                ClusterError::Composite("a worker's reply ended before its first word".into())
            });
            return Err(ClusterError::Composite(e.to_string()));
        }
        let ms = t.elapsed().as_secs_f64() * 1e3;
        self.clock(|x| {
            x.draw_ms += ms;
            x.draw_compute_ms += slowest;
        });
        if ahead {
            let failure = self.failure.clone();
            report.pending = Some(PendingPicture::new(move || {
                round.finish().map_err(|e| {
                    let msg = e.to_string();
                    if let Ok(mut f) = failure.lock() {
                        *f = Some(e);
                    }
                    EngineError::Executor(msg)
                })
            }));
        } else {
            report.picture = Some(
                round
                    .finish()
                    .map_err(|e| ClusterError::Composite(e.to_string()))?,
            );
        }
        Ok(report)
    }
}

/// One worker's bands of a Draw round composited on the workers.
struct BandReply {
    bands: Vec<(Range<u32>, Vec<u8>)>,
    times: engine::DrawTimes,
    bytes: u64,
    stripes: u64,
}

/// A Draw round composited on the workers, past their rasterization: the
/// calls still bringing the finished bands.
struct BandRound {
    rt: tokio::runtime::Handle,
    tasks: Vec<tokio::task::JoinHandle<Result<BandReply, ClusterError>>>,
    width: u32,
    height: u32,
    traffic: Arc<Mutex<Traffic>>,
    timing: Arc<Mutex<Timing>>,
}

impl BandRound {
    /// The finished picture, once every worker's bands came: the first
    /// failure otherwise (the other calls are stopped).
    fn finish(self) -> Result<image::RgbImage, ClusterError> {
        let aborts: Vec<_> = self.tasks.iter().map(|t| t.abort_handle()).collect();
        let replies = self.rt.block_on(async {
            let mut out = Vec::with_capacity(self.tasks.len());
            for t in self.tasks {
                let r = t
                    .await
                    .map_err(|e| ClusterError::Setup(e.to_string()))
                    .and_then(|r| r);
                if r.is_err() {
                    aborts.iter().for_each(|a| a.abort());
                }
                out.push(r);
            }
            out
        });
        let mut img = image::RgbImage::new(self.width, self.height);
        let (mut received, mut stripes) = (0u64, 0u64);
        let (mut wait, mut composite) = (0.0f64, 0.0f64);
        let mut first_error = None;
        for r in replies {
            match r {
                Ok(reply) => {
                    let row = 3 * self.width as usize;
                    let buf: &mut [u8] = &mut img;
                    for (rows, rgb) in reply.bands {
                        let at = rows.start as usize * row;
                        buf[at..at + rgb.len()].copy_from_slice(&rgb);
                    }
                    received += reply.bytes;
                    stripes += reply.stripes;
                    wait = wait.max(reply.times.wait_ms);
                    composite = composite.max(reply.times.composite_ms);
                }
                Err(e) => {
                    if first_error
                        .as_ref()
                        .is_none_or(|f: &ClusterError| f.worker().is_none() && e.worker().is_some())
                    {
                        first_error = Some(e);
                    }
                }
            }
        }
        if let Ok(mut t) = self.traffic.lock() {
            t.bands_received += received;
            t.stripes_between_workers += stripes;
        }
        if let Some(e) = first_error {
            return Err(e);
        }
        if let Ok(mut t) = self.timing.lock() {
            t.band_wait_ms += wait;
            t.band_composite_ms += composite;
        }
        Ok(img)
    }
}

/// What one worker's Deposit reply held, decoded and checked.
#[derive(Default)]
struct Gathered {
    columns: Vec<wire::Columns>,
    bytes: u64,
    samples: u64,
    out_of_map: u64,
    /// The columns its strands' lookups read, for posed strands.
    read: Option<Vec<u64>>,
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
    EngineError::Executor(e.to_string())
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
            .ok_or_else(|| EngineError::Executor("a wisp without a state".into()))?;
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
    ) -> Result<(), EngineError> {
        stats
            .time(Stage::Simulate, || {
                self.with_survivors(|ex| ex.step(anim, plan))
            })
            .map_err(engine_error)?;
        stats.steps += plan.heads.len() as u32;
        Ok(())
    }

    fn fill(
        &mut self,
        light: usize,
        map: &mut DensityMap,
        hair: &Hair,
        _fiber: &Fiber,
        version: Option<u64>,
    ) -> Result<FillStats, EngineError> {
        for x in [&mut self.exchanged, &mut self.swept_on_workers] {
            if let Some(x) = x.get_mut(light) {
                *x = None;
            }
        }
        if self.draw == DrawAt::Workers && self.exchange && self.sweeps_follow && version.is_some()
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
                    if self.workers.len() == before {
                        self.exchange_failures += 1;
                        if self.exchange_failures >= 2 {
                            self.exchange = false;
                            tracing::warn!(
                                "the workers failed twice to sum and sweep together with none of them lost (can they reach each other at the addresses the coordinator dials? with TLS, do their certificates allow client use?); the coordinator sums and hands out the columns from now on"
                            );
                        }
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

    fn sweep(&mut self, light: usize, map: &DensityMap) -> Result<Transmittance, EngineError> {
        if self.posed.is_some() && self.exchanged.get(light).copied().flatten() == self.posed {
            return self.sweep_here(light, map).map_err(engine_error);
        }
        self.with_survivors(|ex| ex.sweep_remote(light, map))
            .map_err(engine_error)
    }

    fn draws(&self) -> bool {
        self.draw == DrawAt::Workers
    }

    fn pose(&mut self, plan: &PosePlan) -> Result<PoseReport, EngineError> {
        if self.posed != Some(plan.version) {
            self.with_survivors(|ex| {
                if ex.shares.is_none() {
                    ex.assign()?;
                }
                ex.pose_call(plan)
            })
            .map_err(engine_error)?;
        }
        self.report
            .clone()
            .ok_or_else(|| EngineError::Executor("no worker reported its pose".into()))
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
        let report = self.report.clone();
        self.restore(then);
        tracing::warn!(
            frame_version = job.version,
            "drawing the frame again, composited here"
        );
        let r = self.with_survivors(|ex| ex.draw_remote(job));
        // On to the frames after, as they stood.
        self.restore(now);
        self.report = report;
        r.map_err(engine_error)
    }
}

impl RemoteExecutor {
    fn addrs(&self) -> Vec<String> {
        self.workers.iter().map(|w| w.addr.clone()).collect()
    }

    /// What drawing hair version `version` again takes, as things stand.
    fn snapshot(&self, version: u64) -> Drawn {
        Drawn {
            version,
            states: self
                .hair
                .as_ref()
                .map(|h| h.states.clone())
                .unwrap_or_default(),
            pose: self.last_pose.clone(),
            swept: self.swept.clone(),
            reads: self.reads.clone(),
            workers: self.addrs(),
        }
    }

    /// Back to `to`: the workers are assigned its states and pose it again
    /// before their next stage (reading every column when they changed).
    fn restore(&mut self, to: Drawn) {
        if let Some(h) = &mut self.hair {
            h.states = to.states;
        }
        self.last_pose = to.pose;
        self.swept = to.swept;
        self.exchanged.iter_mut().for_each(|x| *x = None);
        self.swept_on_workers.iter_mut().for_each(|x| *x = None);
        self.reads = if self.addrs() == to.workers {
            to.reads
        } else {
            vec![None; self.swept.len()]
        };
        self.shares = None;
        self.posed = None;
    }

    /// A Draw, composited on the workers when they can (and, `ahead`, its
    /// picture left to finish while the next frame's stages run),
    /// otherwise here.
    fn draw_with(&mut self, job: &DrawJob, ahead: bool) -> Result<DrawReport, EngineError> {
        self.drawn = None;
        if self.composites_now() {
            match self.draw_composited(job, ahead) {
                Ok(r) => {
                    if ahead {
                        self.drawn = Some(self.snapshot(job.version));
                    }
                    return Ok(r);
                }
                Err(e) => {
                    // The frame is composited here instead, with whichever
                    // workers answer; a worker that fails that is dropped.
                    tracing::warn!(error = %e, "compositing on the workers failed; this frame is composited on the coordinator");
                    self.clock(|t| t.composite_fallbacks += 1);
                    let before = self.workers.len();
                    let r = self
                        .with_survivors(|ex| ex.draw_remote(job))
                        .map_err(engine_error);
                    if r.is_ok() && self.workers.len() == before {
                        self.composite_failures += 1;
                        if self.composite_failures >= 2 {
                            self.composite = false;
                            tracing::warn!(
                                "the workers failed twice to composite together with none of them lost (can they reach each other at the addresses the coordinator dials? with TLS, do their certificates allow client use?); the coordinator composites from now on"
                            );
                        }
                    }
                    return r;
                }
            }
        }
        self.with_survivors(|ex| ex.draw_remote(job))
            .map_err(engine_error)
    }
}
