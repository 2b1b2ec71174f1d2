//! The worker: holds a share of a scene's hair (whole groups of strands,
//! with their wisps), steps and poses it, fills partial density maps,
//! sweeps column ranges, and filters, shades and rasterizes its strands
//! into partial pictures for a coordinator, behind the `wisplight.v1.Worker`
//! gRPC service, with grpc.health.v1 health and server reflection. The
//! stages are the engine's own ([`engine::Share`]).

mod connections;
mod deposit;
mod draw;
mod exchange;
mod inbox;
mod listen;
mod memory;
mod session;
mod share;
mod status;
mod swept;

use inbox::*;
pub use listen::{Bound, Listen, run_worker, serve_worker};
use memory::*;
use session::*;
use share::*;
use status::*;

use std::collections::HashMap;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use engine::{FrameStats, SceneSource};
use prost::Message;
use shadow::{ColumnSlab, DensityMap, Fiber};
use tokio_stream::Stream;
use tonic::{Request, Response, Status, Streaming};

use crate::error::WorkerErrorKind as Kind;
use crate::pb::worker_server::Worker;
use crate::tls::{self, Caller};
use crate::{Tls, pb, wire};

type Chunks<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send>>;

/// Rows of a partial picture rasterized and sent at a time (whole bands
/// of the canvas's 16): 720 rows go as six stripes.
const STRIPE_ROWS: u32 = 128;

/// Chunks of a partial picture encoded ahead of the reply: the drawing
/// waits when the coordinator reads slower.
const STRIPES_IN_FLIGHT: usize = 8;

/// What a session's pool of maps may hold at most, outside the memory
/// budget: `POOLED_MAPS` (4) maps of `POOLED_CELLS` (2^22) cells (161 a side)
/// with their scratch (about 86 MiB).
pub const POOL_BYTES: u64 =
    POOLED_MAPS as u64 * (DensityMap::bytes_for(161) + POOLED_SCRATCH_POINTS as u64 * 20);

/// The default memory budget: 2 GiB.
pub const DEFAULT_MAX_MEMORY: u64 = 2 << 30;

/// How many sessions a worker holds at once, and how long an unused one
/// lives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SessionLimits {
    /// Sessions held at once.
    pub max_sessions: usize,
    /// How long an unused session lives.
    pub idle: Duration,
    /// The memory budget of all sessions and calls, bytes.
    pub max_memory: u64,
    /// The memory budget of each session and its calls, bytes (at most
    /// `max_memory` counts).
    pub max_session_memory: u64,
    /// How long a session lives unused once the connection its Hello came
    /// on has closed (its coordinator gone), at most `idle`.
    pub orphaned: Duration,
}

impl Default for SessionLimits {
    /// Four sessions; ten minutes idle; 2 GiB, any of it to one session.
    fn default() -> SessionLimits {
        SessionLimits {
            max_sessions: 4,
            idle: Duration::from_secs(600),
            max_memory: DEFAULT_MAX_MEMORY,
            max_session_memory: DEFAULT_MAX_MEMORY,
            orphaned: Duration::from_secs(10),
        }
    }
}

/// The worker: its sessions, one per coordinator it serves, each with its
/// own state, none seeing another's.
#[derive(Debug)]
pub struct WorkerService {
    sessions: Mutex<HashMap<String, Arc<Session>>>,
    limits: SessionLimits,
    memory: Memory,
    /// The credentials this worker serves with, to call other workers
    /// with when they composite a picture together.
    peer_tls: Option<Tls>,
    /// The token this worker shows its peers.
    peer_token: Option<crate::Token>,
    /// The connections clients hold open, to end the sessions of those
    /// gone.
    connections: Arc<connections::Connections>,
    /// Connections to other workers, by address and expected name.
    peers: Mutex<HashMap<(String, Option<String>), tonic::transport::Channel>>,
    /// The sessions last ended for going unused, and why, so that a call
    /// naming one says so ([`session::EXPIRED_KEPT`] of them).
    expired: Mutex<std::collections::VecDeque<(String, String)>>,
}

impl Default for WorkerService {
    fn default() -> WorkerService {
        WorkerService::new(SessionLimits::default())
    }
}

#[tonic::async_trait]
impl Worker for WorkerService {
    async fn hello(
        &self,
        req: Request<pb::HelloRequest>,
    ) -> Result<Response<pb::HelloReply>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            tls::request_may_call(&req, Caller::Coordinator)?;
            let r = req.into_inner();
            if r.protocol_version != wire::PROTOCOL_VERSION {
                return Err(status(
                    Kind::Precondition,
                    format!(
                        "this worker speaks wisplight protocol version {}, the coordinator version {}",
                        wire::PROTOCOL_VERSION,
                        r.protocol_version
                    ),
                ));
            }
            let fiber = Fiber::new(r.fiber_width, r.fiber_opacity)
                .map_err(|e| status(Kind::Invalid, e.to_string()))?;
            self.end_idle();
            let id = session_id()?;
            {
                let mut sessions = self.sessions.lock().map_err(poisoned)?;
                if sessions.len() >= self.limits.max_sessions {
                    return Err(status(
                        Kind::Exhausted,
                        format!(
                            "this worker already holds {} sessions, its limit (--max-sessions); \
                         one ends when its coordinator finishes or after {} s unused",
                            sessions.len(),
                            self.limits.idle.as_secs()
                        ),
                    ));
                }
                sessions.insert(
                    id.clone(),
                    Arc::new(Session {
                        fiber,
                        maps: Arc::default(),
                        held: Arc::default(),
                        last_used: Mutex::new(Instant::now()),
                        memory: Memory::new(
                            self.limits.max_session_memory,
                            "this session's",
                            "--max-session-memory-mib",
                        ),
                        inbox: Arc::default(),
                        exchange: Arc::default(),
                        swept: Arc::default(),
                        peers: Mutex::default(),
                        picture: Mutex::default(),
                        origin: peer,
                    }),
                );
                tracing::info!(session = %&id[..8], sessions = sessions.len(), "session opened");
            }
            Ok(Response::new(pb::HelloReply {
                protocol_version: wire::PROTOCOL_VERSION,
                worker: format!("wisplight-worker {}", env!("CARGO_PKG_VERSION")),
                session: id,
            }))
        };
        logged(peer, "Hello", served.await)
    }

    async fn end(&self, req: Request<pb::EndRequest>) -> Result<Response<pb::EndReply>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let id = named_session(req.metadata())?;
            tls::request_may_call(&req, Caller::Coordinator)?;
            let mut sessions = self.sessions.lock().map_err(poisoned)?;
            sessions.remove(id).ok_or_else(|| self.not_open(id))?;
            tracing::info!(session = %&id[..id.len().min(8)], sessions = sessions.len(), "session ended");
            Ok(Response::new(pb::EndReply {}))
        };
        logged(peer, "End", served.await)
    }

    type DensityStream = Chunks<pb::ColumnChunk>;

    async fn density(
        &self,
        req: Request<Streaming<pb::DensityChunk>>,
    ) -> Result<Response<Self::DensityStream>, Status> {
        self.deposit_call(req).await
    }

    async fn assign(
        &self,
        req: Request<Streaming<pb::AssignChunk>>,
    ) -> Result<Response<pb::AssignReply>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Coordinator)?;
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Assign").await?;
            let groups = first.first_group as usize..first.end_group as usize;
            let path = first.scene_path.clone();
            if first.peers.len() > wire::MAX_WORKERS
                || first.peers.iter().any(|p| p.len() > wire::MAX_ADDR_BYTES)
            {
                return Err(status(
                    Kind::Invalid,
                    format!(
                        "at most {} peers of at most {} bytes each (wire::MAX_WORKERS)",
                        wire::MAX_WORKERS,
                        wire::MAX_ADDR_BYTES
                    ),
                ));
            }
            // The peers of the Assign before are forgotten, and this one's
            // are kept only once its share is made: a refused Assign names
            // no one this worker will call.
            session.peers.lock().map_err(poisoned)?.clear();
            *session.picture.lock().map_err(poisoned)? = None;
            let peers = first.peers.clone();
            let mut text = String::new();
            let mut states: Vec<pb::WispChunk> = Vec::new();
            let mut files: Vec<(String, Vec<u8>)> = Vec::new();
            // What the call has made this worker keep, checked before each
            // chunk is kept.
            let (mut file_bytes, mut state_floats) = (0usize, 0usize);
            // What the Assign received, in the memory budget; kept with the
            // share it makes.
            let mut received = Grant::default();
            let memory = self.budget(&session);
            let mut take = |c: pb::AssignChunk| -> Result<(), Status> {
                // The scene text may come in pieces, one a chunk.
                if text.len() + c.scene_toml.len() > wire::MAX_SCENE_TEXT {
                    return Err(status(
                        Kind::Exhausted,
                        format!(
                            "a scene of more than {} bytes (wire::MAX_SCENE_TEXT)",
                            wire::MAX_SCENE_TEXT
                        ),
                    ));
                }
                let bytes = c.scene_toml.len() + c.file_data.len() + c.file_path.len();
                let floats = c.state.as_ref().map_or(0, |w| w.pos.len() + w.prev.len());
                memory.take(
                    &mut received,
                    (bytes + 4 * floats) as u64,
                    "the Assign's scene, data files and wisp states",
                )?;
                text.push_str(&c.scene_toml);
                file_bytes += c.file_data.len() + c.file_path.len();
                if file_bytes > wire::MAX_FILE_BYTES {
                    return Err(status(
                        Kind::Exhausted,
                        format!(
                            "data files of more than {} bytes (wire::MAX_FILE_BYTES)",
                            wire::MAX_FILE_BYTES
                        ),
                    ));
                }
                state_floats += floats;
                if state_floats > wire::MAX_STATE_FLOATS {
                    return Err(status(
                        Kind::Exhausted,
                        format!(
                            "wisp states of more than {} values (wire::MAX_STATE_FLOATS)",
                            wire::MAX_STATE_FLOATS
                        ),
                    ));
                }
                states.extend(c.state);
                if !c.file_path.is_empty() {
                    files.push((c.file_path, Vec::new()));
                }
                if !c.file_data.is_empty() {
                    let (_, data) = files
                        .last_mut()
                        .ok_or_else(|| status(Kind::Invalid, "file data before any file's path"))?;
                    data.extend_from_slice(&c.file_data);
                }
                Ok(())
            };
            take(first)?;
            while let Some(c) = stream.message().await? {
                take(c)?;
            }
            let mut source = SceneSource {
                text: text.into(),
                path: path.into(),
                files: Default::default(),
            };
            for (path, data) in files {
                source.files.insert(path.into(), data.into());
            }
            let held = session.held.clone();
            let reply = tokio::task::spawn_blocking(move || {
                let mut slot = held.lock().map_err(poisoned)?;
                let h = build_share(slot.take(), source, groups, &states, &memory, received)?;
                let anim = h.share.animator();
                let wisps = h.share.wisps();
                let picture = h.share.picture_size();
                let reply = pb::AssignReply {
                    points_per_wisp: anim.points_per_wisp() as u32,
                    groups: anim.groups().count() as u32,
                    first_wisp: wisps.start as u32,
                    end_wisp: wisps.end as u32,
                };
                tracing::info!(groups = ?h.share.groups(), wisps = ?wisps, "share assigned");
                *slot = Some(h);
                Ok::<_, Status>((reply, picture))
            })
            .await
            .map_err(|e| status(Kind::Internal, format!("assign task failed: {e}")))??;
            let (reply, picture) = reply;
            *session.peers.lock().map_err(poisoned)? = peers;
            *session.picture.lock().map_err(poisoned)? = Some(picture);
            Ok(Response::new(reply))
        };
        logged(peer, "Assign", served.await)
    }

    type StepStream = Chunks<pb::WispChunk>;

    async fn step(
        &self,
        req: Request<pb::StepRequest>,
    ) -> Result<Response<Self::StepStream>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Coordinator)?;
            let r = req.into_inner();
            // Set when this call is dropped (cancelled, or past its deadline):
            // the steps stop at the next one and the share is free again.
            let (_stop_on_drop, go) = stop_switch();
            let chunks = with_share(&session.held, move |share| {
                let start = std::time::Instant::now();
                let (plan, accel) = step_plan(&r, share).map_err(invalid)?;
                let mut stats = FrameStats::new(r.frame_id, 0.0);
                if !share.step_while(&plan, accel.as_deref(), &mut stats, go) {
                    return Err(status(
                        Kind::Cancelled,
                        format!(
                            "the Step was cancelled after {} of {} time steps",
                            stats.steps,
                            plan.heads.len()
                        ),
                    ));
                }
                let report = share.pose(&plan.pose);
                let mut chunks = share_chunks(share)?;
                if let Some(c) = chunks.last_mut() {
                    c.compute_ms = start.elapsed().as_secs_f64() * 1e3;
                    c.report = Some(wire::report_to_pb(&report));
                }
                tracing::debug!(
                    frame_id = r.frame_id,
                    version = plan.pose.version,
                    steps = stats.steps,
                    "step done"
                );
                Ok(chunks)
            })
            .await?;
            Ok(Response::new(stream_of(chunks)))
        };
        logged(peer, "Step", served.await)
    }

    async fn pose(&self, req: Request<pb::PosePlan>) -> Result<Response<pb::PoseReport>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Coordinator)?;
            let plan = wire::pose_plan_from_pb(&req.into_inner()).map_err(invalid)?;
            let report = with_share(&session.held, move |share| Ok(share.pose(&plan))).await?;
            Ok(Response::new(wire::report_to_pb(&report)))
        };
        logged(peer, "Pose", served.await)
    }

    type TransmittanceStream = Chunks<pb::SlabChunk>;

    async fn transmittance(
        &self,
        req: Request<Streaming<pb::ColumnChunk>>,
    ) -> Result<Response<Self::TransmittanceStream>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Coordinator)?;
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Transmittance").await?;
            let frame = wire::frame_from_pb(first.map.as_ref()).map_err(invalid)?;
            let (lo, hi) = (first.first_column, first.end_column);
            if lo > hi || hi as usize > frame.columns() {
                return Err(status(
                    Kind::Invalid,
                    format!("columns {lo}..{hi} in a map of {} columns", frame.columns()),
                ));
            }
            let maps = session.maps.clone();
            let budget = self.budget(&session).map(&frame).await?;
            // On an error the map is dropped (the pool makes another).
            let mut map = WorkerService::map_in(&maps, frame);
            wire::merge_columns(&mut map, &first).map_err(invalid)?;
            while let Some(c) = stream.message().await? {
                wire::merge_columns(&mut map, &c).map_err(invalid)?;
            }
            // The sweep stops between runs of columns once the call is gone.
            let (_stop_on_drop, go) = stop_switch();
            let chunks = tokio::task::spawn_blocking(move || {
                let slab: Option<ColumnSlab> = shadow::sweep_while(&map, lo..hi, go);
                WorkerService::give_back(&maps, map);
                drop(budget);
                slab.map(|s| wire::slab_chunks(&s))
                    .ok_or_else(|| cancelled("Transmittance"))
            })
            .await
            .map_err(|e| status(Kind::Internal, format!("sweep task failed: {e}")))??;
            tracing::debug!(
                frame_id = first.frame_id,
                light = first.light,
                columns = hi - lo,
                "sweep done"
            );
            Ok(Response::new(stream_of(chunks)))
        };
        logged(peer, "Transmittance", served.await)
    }

    type DrawStream = Chunks<pb::LayerChunk>;

    async fn draw(
        &self,
        req: Request<Streaming<pb::DrawChunk>>,
    ) -> Result<Response<Self::DrawStream>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Coordinator)?;
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Draw").await?;
            let job = first.job.as_ref().ok_or_else(|| {
                status(Kind::Invalid, "a Draw call's first chunk carries the job")
            })?;
            let exchanged = job.exchanged;
            let job = wire::job_from_pb(job).map_err(invalid)?;
            // The picture's size follows from the session's own scene:
            // checked before anything is allocated for it.
            let asked = (job.camera.width(), job.camera.height());
            match *session.picture.lock().map_err(poisoned)? {
                Some(size) if size == asked => {}
                Some((w, h)) => {
                    return Err(status(
                        Kind::Invalid,
                        format!(
                            "a Draw of a {}x{} picture for a scene of {w}x{h}",
                            asked.0, asked.1
                        ),
                    ));
                }
                None => return Err(no_share()),
            }
            let bands = first
                .bands
                .as_ref()
                .map(|b| wire::Bands::from_pb(b, job.camera.height()))
                .transpose()
                .map_err(invalid)?;
            let mut reader =
                wire::ColumnsReader::new(if job.shadows { job.lights.len() } else { 0 });
            // The swept columns' memory, held until the picture is drawn.
            let mut received = Grant::default();
            let memory = self.budget(&session);
            let mut add = |c: &pb::DrawChunk| -> Result<(), Status> {
                let bytes = wire::ColumnsReader::bytes_to_add(c);
                memory.take(&mut received, bytes, "the Draw's swept columns")?;
                reader.add(c).map_err(invalid)
            };
            if exchanged && (first.map.is_some() || !first.column_steps.is_empty()) {
                return Err(status(
                    Kind::Invalid,
                    "a Draw with the exchanged columns carries none",
                ));
            }
            if first.map.is_some() || !first.column_steps.is_empty() {
                add(&first)?;
            }
            while let Some(c) = stream.message().await? {
                if c.job.is_some() {
                    return Err(status(Kind::Invalid, "a Draw call carries one job"));
                }
                if exchanged {
                    return Err(status(
                        Kind::Invalid,
                        "a Draw with the exchanged columns carries none",
                    ));
                }
                add(&c)?;
            }
            // The columns swept here, or those the call brought.
            let (maps, kept) = if exchanged && job.shadows {
                let (store, version, lights) =
                    (session.swept.clone(), job.version, job.lights.len());
                let wait = bands.as_ref().map_or(Duration::from_secs(30), |b| b.wait);
                tokio::task::spawn_blocking(move || store.take(version, lights, wait))
                    .await
                    .map_err(|e| status(Kind::Internal, format!("worker task failed: {e}")))?
                    .map_err(Status::aborted)?
            } else {
                (reader.finish().map_err(invalid)?, Vec::new())
            };
            let received = (received, kept);
            if let Some(bands) = bands {
                let stream = self.draw_band(&session, job, maps, received, bands)?;
                return Ok(Response::new(stream));
            }
            // The picture streams a stripe of rows at a time, each sent
            // (and decoded by the coordinator) while the next is rasterized.
            let (tx, mut rx) = tokio::sync::mpsc::channel(STRIPES_IN_FLIGHT);
            let held = session.held.clone();
            let (width, height) = (job.camera.width(), job.camera.height());
            tokio::task::spawn_blocking(move || {
                let _received = received;
                let send = |c: Result<pb::LayerChunk, Status>| tx.blocking_send(c).is_ok();
                let drawn = (|| {
                    let mut slot = held.lock().map_err(poisoned)?;
                    let h = slot.as_mut().ok_or_else(|| {
                        status(
                            Kind::Precondition,
                            "no share of the hair here: call Assign first",
                        )
                    })?;
                    let mut encoder = wire::StripeEncoder::new();
                    let times = h
                        .share
                        .draw_stripes(&job, &maps, STRIPE_ROWS, |stripe| {
                            for c in encoder.chunks(&stripe) {
                                if !send(Ok(c)) {
                                    return Err(engine::EngineError::executor(
                                        "the coordinator stopped reading the picture",
                                    ));
                                }
                            }
                            Ok(())
                        })
                        .map_err(refused)?;
                    Ok(encoder.last(width, height, &times))
                })();
                send(drawn);
            });
            // A refusal before any pixel is the call's own status.
            let first = match rx.recv().await {
                Some(Ok(c)) => c,
                Some(Err(s)) => return Err(s),
                None => {
                    return Err(status(
                        Kind::Internal,
                        "the Draw's task ended without a picture",
                    ));
                }
            };
            let rest = tokio_stream::wrappers::ReceiverStream::new(rx);
            let stream: Chunks<pb::LayerChunk> = Box::pin(tokio_stream::StreamExt::chain(
                tokio_stream::once(Ok::<_, Status>(first)),
                rest,
            ));
            Ok(Response::new(stream))
        };
        logged(peer, "Draw", served.await)
    }

    async fn composite(
        &self,
        req: Request<Streaming<pb::LayerChunk>>,
    ) -> Result<Response<pb::CompositeReply>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Peer)?;
            let memory = self.budget(&session);
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Composite").await?;
            let (round, from) = (first.round, first.from);
            let (w, h) = (first.width, first.height);
            if from as usize >= wire::MAX_WORKERS
                || w == 0
                || h == 0
                || u64::from(w) * u64::from(h) > raster::MAX_PIXELS
            {
                return Err(status(
                    Kind::Invalid,
                    format!(
                        "stripes from worker {from} of a {w}x{h} picture (at most {} workers, {} pixels)",
                        wire::MAX_WORKERS,
                        raster::MAX_PIXELS
                    ),
                ));
            }
            let mut grant = Grant::default();
            let stripes = if first.sort_middle {
                // Shaded segments of this worker's bands (sort-middle).
                let mut reader = wire::SegmentReader::new(w, h);
                let mut add = |c: &pb::LayerChunk| -> Result<(), Status> {
                    // The piece, and the band decoded from it.
                    let bytes = 2 * c.segments.len() as u64;
                    memory.take(&mut grant, bytes, "a Composite call's segments")?;
                    reader.add(c).map_err(invalid)
                };
                add(&first)?;
                while let Some(c) = stream.message().await? {
                    add(&c)?;
                }
                let bands = reader.finish().map_err(invalid)?;
                bands.into_iter().map(engine::Stripe::Segments).collect()
            } else {
                let mut reader = wire::LayerReader::new(w, h);
                let mut add = |c: &pb::LayerChunk| -> Result<(), Status> {
                    // The fragments take their own bytes again once read.
                    let bytes = u64::from(c.count) * STRIPE_PIXEL_BYTES + 2 * c.fronts.len() as u64;
                    memory.take(&mut grant, bytes, "a Composite call's stripes")?;
                    reader.add(c).map_err(invalid)
                };
                add(&first)?;
                while let Some(c) = stream.message().await? {
                    add(&c)?;
                }
                vec![engine::Stripe::Layer(reader.finish().map_err(invalid)?)]
            };
            session.inbox.deliver(round, from, stripes, grant)?;
            Ok(Response::new(pb::CompositeReply {}))
        };
        logged(peer, "Composite", served.await)
    }

    async fn exchange(
        &self,
        req: Request<Streaming<pb::ExchangeChunk>>,
    ) -> Result<Response<pb::ExchangeReply>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Peer)?;
            let memory = self.budget(&session);
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Exchange").await?;
            let (round, from, swept) = (first.round, first.from, first.swept);
            if from as usize >= wire::MAX_WORKERS || round >= u64::MAX / 2 {
                return Err(status(
                    Kind::Invalid,
                    format!(
                        "columns from worker {from} of round {round} (at most {} workers)",
                        wire::MAX_WORKERS
                    ),
                ));
            }
            let frame = if swept {
                None
            } else {
                Some(wire::frame_from_pb(first.map.as_ref()).map_err(invalid)?)
            };
            let mut grant = Grant::default();
            let (mut density, mut columns) = (Vec::new(), Vec::new());
            let mut add = |c: pb::ExchangeChunk| -> Result<(), Status> {
                match (swept, c.density, c.columns) {
                    (false, Some(d), None) => {
                        // The cells unpacked, and the chunk as it came.
                        let cells: u64 =
                            d.lo.iter()
                                .zip(&d.hi)
                                .map(|(&lo, &hi)| u64::from(hi.saturating_sub(lo)) + 1)
                                .sum();
                        let bytes = cells * 4 + d.encoded_len() as u64;
                        memory.take(&mut grant, bytes, "an Exchange call's density")?;
                        density.push(d);
                    }
                    (true, None, Some(col)) => {
                        let bytes =
                            wire::ColumnsReader::bytes_to_add(&col) + col.encoded_len() as u64;
                        memory.take(&mut grant, bytes, "an Exchange call's swept columns")?;
                        columns.push(col);
                    }
                    (_, None, None) => {}
                    _ => {
                        return Err(status(
                            Kind::Invalid,
                            "an Exchange chunk carries what its call does not (density in a call of swept columns, or the reverse, or both)",
                        ));
                    }
                }
                Ok(())
            };
            add(first)?;
            while let Some(c) = stream.message().await? {
                add(c)?;
            }
            let item = match frame {
                Some(f) => Exchanged::Density(f, density),
                None => Exchanged::Swept(columns),
            };
            session
                .exchange
                .deliver(2 * round + u64::from(swept), from, item, grant)?;
            Ok(Response::new(pb::ExchangeReply {}))
        };
        logged(peer, "Exchange", served.await)
    }
}

/// A call that needs the session's share before any Assign made one.
pub(super) fn no_share() -> Status {
    status(
        Kind::Precondition,
        "no share of the hair here: call Assign first",
    )
}
