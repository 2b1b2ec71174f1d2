//! The coordinator's side: an [`engine::Executor`] that runs the wisps'
//! simulation, the density map's fill and its sweep on workers over gRPC,
//! with the same bytes as one process.
//!
//! Each live worker owns a contiguous share of the wisps (weighted by their
//! drawn strands) and, per sweep, a contiguous share of the columns
//! (weighted by their occupied cells). When a worker fails a call (it died,
//! missed the deadline, or sent something malformed) it is dropped: its
//! wisps go to the survivors with the state the coordinator gathered last,
//! and the stage is run again, so the frame comes out the same.

use std::ops::Range;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use engine::{Animator, EngineError, Executor, FrameStats, Stage, StepPlan};
use prost::Message;
use shadow::{ColumnSlab, DensityMap, Fiber, FillStats, Transmittance};
use strands::Hair;
use tonic::transport::{Channel, Endpoint};

use crate::pb::worker_client::WorkerClient;
use crate::{ClusterError, Tls, pb, tls, wire};

/// Bytes on the wire, by stage and direction (protobuf message bytes;
/// HTTP/2 framing adds a little).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Traffic {
    /// Wisp shares and their state sent (Assign), at the start and after
    /// a worker is lost.
    pub assign_sent: u64,
    /// Step requests (head transforms, bodies, accelerations).
    pub step_sent: u64,
    /// Wisp states received (Step replies).
    pub wisps_received: u64,
    /// Strands sent to workers (Deposit requests).
    pub strands_sent: u64,
    /// Partial density columns received.
    pub density_received: u64,
    /// Summed density columns sent for sweeping.
    pub density_sent: u64,
    /// Transmittance slabs received.
    pub slabs_received: u64,
}

impl Traffic {
    pub fn total(&self) -> u64 {
        self.assign_sent
            + self.step_sent
            + self.wisps_received
            + self.strands_sent
            + self.density_received
            + self.density_sent
            + self.slabs_received
    }

    /// The bytes counted since `earlier`.
    pub fn since(&self, earlier: &Traffic) -> Traffic {
        Traffic {
            assign_sent: self.assign_sent - earlier.assign_sent,
            step_sent: self.step_sent - earlier.step_sent,
            wisps_received: self.wisps_received - earlier.wisps_received,
            strands_sent: self.strands_sent - earlier.strands_sent,
            density_received: self.density_received - earlier.density_received,
            density_sent: self.density_sent - earlier.density_sent,
            slabs_received: self.slabs_received - earlier.slabs_received,
        }
    }

    /// One line: the total and each part, in MB.
    pub fn summary(&self) -> String {
        let mb = |b: u64| b as f64 / 1e6;
        format!(
            "{:.3} MB (wisps: assign {:.3}, steps {:.3}, states in {:.3}; strands out {:.3}; density in {:.3}, out {:.3}; slabs in {:.3})",
            mb(self.total()),
            mb(self.assign_sent),
            mb(self.step_sent),
            mb(self.wisps_received),
            mb(self.strands_sent),
            mb(self.density_received),
            mb(self.density_sent),
            mb(self.slabs_received),
        )
    }
}

/// Where the time of the remote stages went, summed over frames (for the
/// scaling benchmark's critical path).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Timing {
    /// Wall time of Step calls, as the coordinator waited for them.
    pub step_wall_ms: f64,
    /// The slowest worker's own compute time in each Step, summed.
    pub step_compute_ms: f64,
    /// Wall time of Deposit calls plus merging their partial densities.
    pub fill_ms: f64,
    /// Wall time of Sweep calls plus assembling their slabs.
    pub sweep_ms: f64,
    /// Workers lost and their work handed to the survivors.
    pub workers_lost: u32,
}

#[derive(Debug, Clone)]
struct Remote {
    addr: String,
    client: WorkerClient<Channel>,
}

/// Workers that simulate wisps and fill and sweep the density map (see
/// the module docs).
#[derive(Debug)]
pub struct RemoteExecutor {
    rt: tokio::runtime::Runtime,
    /// The live workers, in order.
    workers: Vec<Remote>,
    deadline: Duration,
    /// Counts calls, for the ids of those not about a posed hair version.
    calls: u64,
    traffic: Arc<Mutex<Traffic>>,
    timing: Arc<Mutex<Timing>>,
    /// The scene's TOML text, for Assign (simulated hair only).
    scene_toml: Option<String>,
    /// Each live worker's wisps, once assigned.
    shares: Option<Vec<Range<usize>>>,
    /// The hair version the workers posed at their last Step.
    posed: Option<u64>,
}

impl RemoteExecutor {
    /// Connects to every worker and checks its protocol version. `deadline`
    /// bounds every call, from its first byte sent to its last received.
    /// With `tls`, every connection is mutual TLS.
    pub fn connect(
        addrs: &[String],
        fiber: &Fiber,
        deadline: Duration,
        tls: Option<&Tls>,
    ) -> Result<RemoteExecutor, ClusterError> {
        if addrs.is_empty() {
            return Err(ClusterError::Setup("no workers given".into()));
        }
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .map_err(|e| ClusterError::Setup(format!("cannot start the network runtime: {e}")))?;
        let workers = rt.block_on(async {
            let mut out = Vec::with_capacity(addrs.len());
            for addr in addrs {
                out.push(hello(addr, fiber, deadline, tls).await?);
            }
            Ok::<_, ClusterError>(out)
        })?;
        Ok(RemoteExecutor {
            rt,
            workers,
            deadline,
            calls: 0,
            traffic: Arc::new(Mutex::new(Traffic::default())),
            timing: Arc::new(Mutex::new(Timing::default())),
            scene_toml: None,
            shares: None,
            posed: None,
        })
    }

    /// The scene's TOML text: with it, simulated wisps are stepped on the
    /// workers (each builds the same wisps from it); without it, the
    /// coordinator simulates and sends the drawn strands.
    pub fn set_scene(&mut self, toml: String) {
        self.scene_toml = Some(toml);
        self.shares = None;
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
        self.clock(|t| t.workers_lost += 1);
        tracing::warn!(
            error = %e,
            survivors = self.workers.len(),
            "worker lost; its wisps and columns go to the survivors"
        );
        Ok(())
    }
}

/// The endpoint of the worker at `addr`: connect and call timeouts of
/// `deadline`, TLS when `tls` is given.
pub(crate) fn endpoint(
    addr: &str,
    deadline: Duration,
    tls: Option<&Tls>,
) -> Result<Endpoint, ClusterError> {
    let err = |msg: String| ClusterError::Connect {
        addr: addr.to_string(),
        msg,
    };
    let endpoint = Endpoint::from_shared(format!("{}://{addr}", tls::scheme(tls)))
        .map_err(|e| err(e.to_string()))?
        .connect_timeout(deadline)
        .timeout(deadline)
        .tcp_nodelay(true);
    match tls {
        Some(t) => endpoint
            .tls_config(t.client_config(addr))
            .map_err(|e| t.refused(&e)),
        None => Ok(endpoint),
    }
}

async fn hello(
    addr: &str,
    fiber: &Fiber,
    deadline: Duration,
    tls: Option<&Tls>,
) -> Result<Remote, ClusterError> {
    let err = |msg: String| ClusterError::Connect {
        addr: addr.to_string(),
        msg: tls::explain(tls, msg),
    };
    let channel = endpoint(addr, deadline, tls)?
        .connect()
        .await
        .map_err(|e| err(root_cause(&e)))?;
    let mut client = WorkerClient::new(channel)
        .max_decoding_message_size(wire::MAX_MESSAGE_BYTES)
        .max_encoding_message_size(wire::MAX_MESSAGE_BYTES);
    let reply = client
        .hello(pb::HelloRequest {
            protocol_version: wire::PROTOCOL_VERSION,
            fiber_width: fiber.width(),
            fiber_opacity: fiber.opacity(),
        })
        .await
        .map_err(|s| match s.code() {
            tonic::Code::FailedPrecondition => ClusterError::Version {
                addr: addr.to_string(),
                msg: s.message().to_string(),
            },
            tonic::Code::Unimplemented => ClusterError::Connect {
                addr: addr.to_string(),
                msg: "this address serves no wisplight worker (unimplemented: a health port?)"
                    .into(),
            },
            _ if s.message().is_empty() => err(s.code().description().to_string()),
            _ => err(s.message().to_string()),
        })?
        .into_inner();
    if reply.protocol_version != wire::PROTOCOL_VERSION {
        return Err(ClusterError::Version {
            addr: addr.to_string(),
            msg: format!(
                "the worker speaks protocol version {}, this coordinator {}",
                reply.protocol_version,
                wire::PROTOCOL_VERSION
            ),
        });
    }
    tracing::info!(addr, worker = reply.worker, "worker ready");
    Ok(Remote {
        addr: addr.to_string(),
        client,
    })
}

/// The innermost cause: "Connection refused (os error 111)" rather than
/// three layers of "transport error".
pub(crate) fn root_cause(e: &dyn std::error::Error) -> String {
    let mut last = e.to_string();
    let mut s = e.source();
    while let Some(x) = s {
        last = x.to_string();
        s = x.source();
    }
    last
}

/// Cuts `0..len` into `parts` contiguous ranges whose `weight` sums are
/// about equal (a range may be empty).
fn split_by(
    len: usize,
    parts: usize,
    weight: impl Fn(usize) -> u64,
) -> Vec<std::ops::Range<usize>> {
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

/// Runs `call` on every worker at once, each bounded by `deadline`, and
/// returns the results in worker order: the first error, if any, names
/// its worker.
fn fan_out<R, T, F, Fut>(
    rt: &tokio::runtime::Runtime,
    requests: Vec<(Remote, R)>,
    stage: &'static str,
    deadline: Duration,
    call: F,
) -> Result<Vec<T>, ClusterError>
where
    R: Send + 'static,
    T: Send + 'static,
    F: Fn(Remote, R) -> Fut,
    Fut: std::future::Future<Output = Result<T, ClusterError>> + Send + 'static,
{
    rt.block_on(async {
        let tasks: Vec<_> = requests
            .into_iter()
            .map(|(w, r)| {
                let addr = w.addr.clone();
                let fut = call(w, r);
                tokio::spawn(async move {
                    match tokio::time::timeout(deadline, fut).await {
                        Ok(r) => r,
                        Err(_) => Err(ClusterError::Deadline {
                            addr,
                            stage,
                            secs: deadline.as_secs_f64(),
                        }),
                    }
                })
            })
            .collect();
        let mut out = Vec::with_capacity(tasks.len());
        for t in tasks {
            out.push(t.await.map_err(|e| ClusterError::Setup(e.to_string()))??);
        }
        Ok(out)
    })
}

fn call_error(addr: &str, stage: &'static str, s: tonic::Status) -> ClusterError {
    ClusterError::Call {
        addr: addr.to_string(),
        stage,
        msg: format!("{:?}: {}", s.code(), s.message()),
    }
}

/// Collects a server stream's messages.
async fn collect<T>(
    addr: &str,
    stage: &'static str,
    mut s: tonic::Streaming<T>,
) -> Result<Vec<T>, ClusterError> {
    let mut out = Vec::new();
    while let Some(c) = s.message().await.map_err(|e| call_error(addr, stage, e))? {
        out.push(c);
    }
    Ok(out)
}

fn malformed(addr: &str, e: impl ToString) -> ClusterError {
    ClusterError::Malformed {
        addr: addr.to_string(),
        msg: e.to_string(),
    }
}

impl RemoteExecutor {
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

    /// Shares the wisps out over the live workers, with their state in
    /// `anim` (the state gathered last).
    fn assign(&mut self, anim: &Animator) -> Result<(), ClusterError> {
        let toml = self
            .scene_toml
            .clone()
            .ok_or_else(|| ClusterError::Setup("no scene to simulate".into()))?;
        let weights = anim.strands_per_wisp();
        let shares = split_by(weights.len(), self.workers.len(), |w| weights[w] + 1);
        let mut requests = Vec::with_capacity(shares.len());
        let mut sent = 0u64;
        for (w, share) in self.workers.iter().zip(&shares) {
            let states: Vec<_> = share
                .clone()
                .map(|i| anim.wisp_state(i).expect("simulated wisps"))
                .collect();
            let chunks: Vec<pb::AssignChunk> = wire::wisp_chunks(share.start, states)
                .into_iter()
                .enumerate()
                .map(|(i, state)| pb::AssignChunk {
                    scene_toml: if i == 0 { toml.clone() } else { String::new() },
                    first_wisp: share.start as u32,
                    end_wisp: share.end as u32,
                    state: Some(state),
                })
                .collect();
            sent += chunks.iter().map(|c| c.encoded_len() as u64).sum::<u64>();
            requests.push((w.clone(), chunks));
        }
        let per = anim.points_per_wisp() as u32;
        fan_out(
            &self.rt,
            requests,
            "assign",
            self.deadline,
            move |mut w, chunks| async move {
                let reply = w
                    .client
                    .assign(tokio_stream::iter(chunks))
                    .await
                    .map_err(|s| call_error(&w.addr, "assign", s))?
                    .into_inner();
                if reply.points_per_wisp != per {
                    return Err(malformed(
                        &w.addr,
                        format!(
                            "the worker's wisps have {} guide points, the coordinator's {per}",
                            reply.points_per_wisp
                        ),
                    ));
                }
                Ok(())
            },
        )?;
        tracing::info!(shares = ?shares, "wisps assigned");
        self.count(|t| t.assign_sent += sent);
        self.shares = Some(shares);
        Ok(())
    }

    /// One Step on every worker; the new states go into `anim` only when
    /// every worker answered.
    fn step(&mut self, anim: &mut Animator, plan: &StepPlan) -> Result<(), ClusterError> {
        if self.shares.is_none() {
            self.assign(anim)?;
        }
        let shares = self.shares.clone().expect("assigned above");
        let per = anim.points_per_wisp();
        let mut base = pb::StepRequest {
            frame_id: plan.version,
            version: plan.version,
            has_accel: plan.accel.is_some(),
            ..Default::default()
        };
        for (h, b) in plan.heads.iter().zip(&plan.bodies) {
            wire::affine_to_floats(h, &mut base.heads);
            base.body_counts.push(b.len() as u32);
            wire::bodies_to_floats(b, &mut base.bodies);
        }
        wire::bodies_to_floats(&plan.drawn_bodies, &mut base.drawn_bodies);
        let mut requests = Vec::with_capacity(shares.len());
        let mut sent = 0u64;
        for (w, share) in self.workers.iter().zip(&shares) {
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
                let (mut bytes, mut compute) = (0u64, 0.0f64);
                for c in &chunks {
                    bytes += c.encoded_len() as u64;
                    compute += c.compute_ms;
                    states.extend(
                        wire::wisps_from_chunk(c, per, &share)
                            .map_err(|e| malformed(&w.addr, e))?,
                    );
                }
                let in_order = states.iter().map(|(i, _)| *i).eq(share.clone());
                if !in_order {
                    return Err(malformed(
                        &w.addr,
                        format!("the states of wisps {share:?} did not come whole and in order"),
                    ));
                }
                Ok((w.addr, states, bytes, compute))
            },
        )?;
        let wall = t.elapsed().as_secs_f64() * 1e3;
        let mut received = 0u64;
        let mut slowest = 0.0f64;
        for (addr, states, bytes, compute) in replies {
            received += bytes;
            slowest = slowest.max(compute);
            for (i, state) in states {
                anim.set_wisp_state(i, state)
                    .map_err(|e| malformed(&addr, e))?;
            }
        }
        self.count(|t| {
            t.step_sent += sent;
            t.wisps_received += received;
        });
        self.clock(|t| {
            t.step_wall_ms += wall;
            t.step_compute_ms += slowest;
        });
        self.posed = Some(plan.version);
        Ok(())
    }

    /// The Deposit requests of one fill: the workers' posed strands when
    /// they hold hair `version`, else shares of `hair`'s strands.
    fn deposit_requests(
        &self,
        id: u64,
        light: u32,
        frame: &shadow::LightFrame,
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

    fn fill_remote(
        &mut self,
        light: usize,
        map: &mut DensityMap,
        hair: &Hair,
        version: Option<u64>,
    ) -> Result<FillStats, ClusterError> {
        let id = version.unwrap_or_else(|| {
            self.calls += 1;
            self.calls
        });
        let frame = *map.frame();
        let requests = self.deposit_requests(id, light as u32, &frame, hair, version);
        let posed = requests.first().is_some_and(|(_, c)| c[0].posed);
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
            |mut w, chunks| async move {
                let s = w
                    .client
                    .deposit(tokio_stream::iter(chunks))
                    .await
                    .map_err(|s| call_error(&w.addr, "deposit", s))?
                    .into_inner();
                let got = collect(&w.addr, "deposit", s).await?;
                Ok((w.addr, got))
            },
        )?;
        // Merge in worker order (integer sums: any order gives the same
        // map). Every reply is checked before the map changes.
        let mut stats = FillStats::default();
        let mut received = 0u64;
        let mut decoded = Vec::with_capacity(replies.len());
        for (addr, chunks) in &replies {
            for c in chunks {
                decoded.push(wire::decode_columns(&frame, c).map_err(|e| malformed(addr, e))?);
                received += c.encoded_len() as u64;
                stats.samples += c.samples;
                stats.out_of_map += c.out_of_map;
            }
        }
        for d in &decoded {
            wire::add_columns(map, d);
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
        // Each reader already refused, naming its worker, whatever does not
        // fit the spans the coordinator sent; `assemble` checks once more.
        let trans = Transmittance::assemble(frame, replies.into_iter().map(|(_, s, _)| s))
            .map_err(|e| malformed("workers", e))?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        self.count(|x| {
            x.density_sent += sent;
            x.slabs_received += received;
        });
        self.clock(|x| x.sweep_ms += ms);
        tracing::debug!(frame_id = id, light, "transmittance gathered");
        Ok(trans)
    }
}

fn engine_error(e: ClusterError) -> EngineError {
    EngineError::Executor(e.to_string())
}

impl Executor for RemoteExecutor {
    fn simulate(
        &mut self,
        anim: &mut Animator,
        plan: &StepPlan,
        stats: &mut FrameStats,
    ) -> Result<(), EngineError> {
        if self.scene_toml.is_none() {
            // No scene to build wisps from: simulate here.
            return engine::LocalExecutor.simulate(anim, plan, stats);
        }
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
        // After a loss the survivors lack the lost worker's posed strands:
        // the retry sends strands (`posed` was cleared).
        self.with_survivors(|ex| ex.fill_remote(light, map, hair, version))
            .map_err(engine_error)
    }

    fn sweep(&mut self, light: usize, map: &DensityMap) -> Result<Transmittance, EngineError> {
        self.with_survivors(|ex| ex.sweep_remote(light, map))
            .map_err(engine_error)
    }
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
