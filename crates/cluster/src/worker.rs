//! The worker: holds a share of a scene's hair (whole groups of strands,
//! with their wisps), steps and poses it, fills partial density maps,
//! sweeps column ranges, and filters, shades and rasterizes its strands
//! into partial pictures for a coordinator, behind the `wisplight.v1.Worker`
//! gRPC service, with grpc.health.v1 health and server reflection. The
//! stages are the engine's own ([`engine::Share`]).

use std::collections::HashMap;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use std::ops::Range;

use engine::{FrameStats, Scene, SceneSource, Share, StepPlan};
use prost::Message;
use shadow::{ColumnSlab, DensityMap, Fiber, FillStats, LightFrame};
use strands::Hair;
use tokio_stream::Stream;
use tonic::{Request, Response, Status, Streaming};

use crate::pb::worker_server::{Worker, WorkerServer};
use crate::{ClusterError, Tls, pb, wire};

type Chunks<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send>>;

/// Rows of a partial picture rasterized and sent at a time (whole bands
/// of the canvas's 16): 720 rows go as six stripes.
const STRIPE_ROWS: u32 = 128;

/// Chunks of a partial picture encoded ahead of the reply: the drawing
/// waits when the coordinator reads slower.
const STRIPES_IN_FLIGHT: usize = 8;

/// The most cells a map kept between calls (a session's pool) may have:
/// 2^22 (16 MiB of quanta); larger maps are dropped after their call.
const POOLED_CELLS: u64 = 1 << 22;

/// The most maps a session keeps between calls.
const POOLED_MAPS: usize = 4;

/// The most deposit scratch points a pooled map keeps (5 MiB).
const POOLED_SCRATCH_POINTS: usize = 1 << 18;

/// What a session's pool of maps may hold at most, outside the memory
/// budget: [`POOLED_MAPS`] maps of [`POOLED_CELLS`] cells (161 a side)
/// with their scratch (about 86 MiB).
pub const POOL_BYTES: u64 =
    POOLED_MAPS as u64 * (DensityMap::bytes_for(161) + POOLED_SCRATCH_POINTS as u64 * 20);

/// Memory is budgeted in granules of 64 KiB.
const GRANULE: u64 = 1 << 16;

/// Bytes a received point costs until its call ends: its coordinates, and
/// their copy in map coordinates while it is deposited.
const POINT_BYTES: u64 = 24;

/// Bytes a received strand costs until its call ends: its offset, and
/// its range along the light while it is deposited.
const STRAND_BYTES: u64 = 12;

/// A memory budget: the worker's (`--max-memory-mib`) or one session's
/// (`--max-session-memory-mib`). It counts every density map a call
/// holds, every strand and swept column a call receives, and each
/// session's scene, data files, wisp states and share of the hair. A map
/// waits for room (a call holding one finishes without asking for more);
/// received data that does not fit is refused with RESOURCE_EXHAUSTED.
#[derive(Debug, Clone)]
struct Memory {
    free: Arc<tokio::sync::Semaphore>,
    total: u64,
    /// Whose budget, as its messages say it.
    whose: &'static str,
    flag: &'static str,
}

type Held64k = tokio::sync::OwnedSemaphorePermit;

impl Memory {
    fn new(total: u64, whose: &'static str, flag: &'static str) -> Memory {
        let units = (total / GRANULE).min(tokio::sync::Semaphore::MAX_PERMITS as u64);
        Memory {
            free: Arc::new(tokio::sync::Semaphore::new(units as usize)),
            total: units * GRANULE,
            whose,
            flag,
        }
    }

    fn units(bytes: u64) -> u32 {
        bytes.div_ceil(GRANULE).min(u64::from(u32::MAX)) as u32
    }

    fn too_much(&self, bytes: u64, what: &str) -> Status {
        Status::resource_exhausted(format!(
            "{what} would take {} MiB of {} memory budget of {} MiB, \
             of which {} MiB are free ({})",
            bytes.div_ceil(1 << 20),
            self.whose,
            self.total >> 20,
            (self.free.available_permits() as u64 * GRANULE) >> 20,
            self.flag
        ))
    }

    /// Waits until `bytes` fit; held until dropped. More than the whole
    /// budget is refused.
    async fn wait_for(&self, bytes: u64, what: &str) -> Result<Held64k, Status> {
        if bytes > self.total {
            return Err(self.too_much(bytes, what));
        }
        self.free
            .clone()
            .acquire_many_owned(Memory::units(bytes))
            .await
            .map_err(|_| Status::unavailable("the worker is stopping"))
    }

    /// Takes `bytes` now, into `held`, or refuses.
    fn take(&self, held: &mut Option<Held64k>, bytes: u64, what: &str) -> Result<(), Status> {
        if bytes == 0 {
            return Ok(());
        }
        let p = self
            .free
            .clone()
            .try_acquire_many_owned(Memory::units(bytes))
            .map_err(|_| self.too_much(bytes, what))?;
        match held {
            Some(h) => h.merge(p),
            None => *held = Some(p),
        }
        Ok(())
    }
}

/// What a call may take: from its session's budget and the worker's.
#[derive(Debug, Clone)]
struct Budget {
    session: Memory,
    worker: Memory,
}

/// Memory a [`Budget`] granted, given back when dropped.
#[derive(Debug, Default)]
struct Grant {
    _session: Option<Held64k>,
    _worker: Option<Held64k>,
}

impl Budget {
    /// Takes `bytes` now, into `grant`, or refuses naming the budget.
    fn take(&self, grant: &mut Grant, bytes: u64, what: &str) -> Result<(), Status> {
        self.session.take(&mut grant._session, bytes, what)?;
        self.worker.take(&mut grant._worker, bytes, what)
    }

    /// A map in `frame`, once it fits both.
    async fn map(&self, frame: &LightFrame) -> Result<Grant, Status> {
        let what = format!("a density map of {}^3 cells", frame.n_cells);
        let bytes = DensityMap::bytes_for(frame.n_cells);
        let session = self.session.wait_for(bytes, &what).await?;
        let worker = self.worker.wait_for(bytes, &what).await?;
        Ok(Grant {
            _session: Some(session),
            _worker: Some(worker),
        })
    }
}

/// What a share of a scene may come to hold, estimated before it is built
/// from the scene's drawn segments and picture:
/// `SHARE_BYTES_PER_SEGMENT * segments + CANVAS_BYTES_PER_PIXEL * pixels`.
fn share_bytes(scene: &Scene) -> Result<u64, engine::EngineError> {
    let pixels = u64::from(scene.render.width) * u64::from(scene.render.height);
    Ok(engine::drawn_segments(scene)? * SHARE_BYTES_PER_SEGMENT + pixels * CANVAS_BYTES_PER_PIXEL)
}

/// Bytes a drawn segment of the scene costs a worker's share, at most:
/// the whole hair at rest and posed (every share keeps the scene's
/// animator), and the share's own vertices' transmittance, colours and
/// screen vertices. Measured: see the worker's memory test.
const SHARE_BYTES_PER_SEGMENT: u64 = 256;

/// Bytes a picture's pixel costs a worker's share: its partial picture's
/// sums and marks, the opaque depth and colour it draws behind.
const CANVAS_BYTES_PER_PIXEL: u64 = 48;

/// The default memory budget: 2 GiB.
pub const DEFAULT_MAX_MEMORY: u64 = 2 << 30;

/// The gRPC metadata key that names a call's session.
pub const SESSION_KEY: &str = "wisplight-session";

/// How many sessions a worker holds at once, and how long an unused one
/// lives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SessionLimits {
    pub max_sessions: usize,
    pub idle: Duration,
    /// The memory budget of all sessions and calls, bytes.
    pub max_memory: u64,
    /// The memory budget of each session and its calls, bytes (at most
    /// `max_memory` counts).
    pub max_session_memory: u64,
}

impl Default for SessionLimits {
    /// Four sessions; ten minutes idle; 2 GiB, any of it to one session.
    fn default() -> SessionLimits {
        SessionLimits {
            max_sessions: 4,
            idle: Duration::from_secs(600),
            max_memory: DEFAULT_MAX_MEMORY,
            max_session_memory: DEFAULT_MAX_MEMORY,
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
    /// Connections to other workers, by address and expected name.
    peers: Mutex<HashMap<(String, Option<String>), tonic::transport::Channel>>,
}

impl Default for WorkerService {
    fn default() -> WorkerService {
        WorkerService::new(SessionLimits::default())
    }
}

/// What one coordinator's calls share: the fiber it said Hello with, its
/// share of the scene's hair, and density maps kept between calls (their
/// memory, not their content).
#[derive(Debug)]
struct Session {
    fiber: Fiber,
    maps: Arc<Mutex<Vec<DensityMap>>>,
    held: Arc<Mutex<Option<Held>>>,
    last_used: Mutex<Instant>,
    /// The session's own memory budget.
    memory: Memory,
    /// Other workers' stripes of this worker's band, by Draw round.
    inbox: Arc<Inbox<raster::HairLayer>>,
    /// Other workers' columns, by Deposit round (twice the round for
    /// density, and one more for swept columns).
    exchange: Arc<Inbox<Exchanged>>,
    /// What the last Deposit rounds with a column plan swept.
    swept: Arc<SweptStore>,
}

/// The most stripes a session's inbox holds at once (each a whole
/// Composite call, counted against the memory budget).
const INBOX_LAYERS: usize = 64;

/// Bytes a received stripe pixel costs: its index and its sums.
const STRIPE_PIXEL_BYTES: u64 = 4 + std::mem::size_of::<raster::Sums>() as u64;

/// What other workers sent this worker for one of its rounds (their
/// stripes of its band, Composite calls; their columns, Exchange calls),
/// until the call of that round gathers them.
#[derive(Debug)]
struct Inbox<T> {
    state: Mutex<InboxState<T>>,
    ready: std::sync::Condvar,
}

impl<T> Default for Inbox<T> {
    fn default() -> Inbox<T> {
        Inbox {
            state: Mutex::new(InboxState {
                round: 0,
                items: Vec::new(),
            }),
            ready: std::sync::Condvar::new(),
        }
    }
}

#[derive(Debug)]
struct InboxState<T> {
    /// The latest round begun: items of earlier rounds are dropped.
    round: u64,
    /// Per delivered call: its round, its sender, what it carried and
    /// that memory.
    items: Vec<(u64, u32, T, Grant)>,
}

impl<T> Inbox<T> {
    /// A round begins: earlier rounds' items go.
    fn begin(&self, round: u64) {
        if let Ok(mut st) = self.state.lock() {
            st.round = st.round.max(round);
            let r = st.round;
            st.items.retain(|l| l.0 >= r);
        }
    }

    /// Keeps a sender's item of `round` (stale ones are dropped).
    fn deliver(&self, round: u64, from: u32, item: T, grant: Grant) -> Result<(), Status> {
        let mut st = self.state.lock().map_err(poisoned)?;
        if round < st.round {
            return Ok(());
        }
        if st.items.iter().any(|l| l.0 == round && l.1 == from) {
            return Err(Status::invalid_argument(format!(
                "worker {from}'s call of round {round} comes twice"
            )));
        }
        if st.items.len() >= INBOX_LAYERS {
            return Err(Status::resource_exhausted(format!(
                "{INBOX_LAYERS} calls of other workers already wait here"
            )));
        }
        st.items.push((round, from, item, grant));
        self.ready.notify_all();
        Ok(())
    }

    /// The items of `round` from every worker in `from`, in that order,
    /// with their memory, once all came; an error naming the workers
    /// missing after `wait`, or as soon as `go()` says stop.
    fn gather(
        &self,
        round: u64,
        from: &[u32],
        wait: Duration,
        go: impl Fn() -> Result<(), String>,
    ) -> Result<Vec<(T, Grant)>, engine::EngineError> {
        let fail = |m: String| engine::EngineError::Executor(m);
        let until = Instant::now() + wait;
        let mut st = self
            .state
            .lock()
            .map_err(|_| fail("worker state poisoned".into()))?;
        loop {
            let have = |b: &u32| st.items.iter().any(|l| l.0 == round && l.1 == *b);
            let missing: Vec<u32> = from.iter().copied().filter(|b| !have(b)).collect();
            if missing.is_empty() {
                let mut out = Vec::with_capacity(from.len());
                for b in from {
                    let i = st
                        .items
                        .iter()
                        .position(|l| l.0 == round && l.1 == *b)
                        .expect("found above");
                    let (_, _, item, grant) = st.items.swap_remove(i);
                    out.push((item, grant));
                }
                return Ok(out);
            }
            go().map_err(fail)?;
            let now = Instant::now();
            if now >= until {
                return Err(fail(format!(
                    "nothing from workers {missing:?} of the round within {} ms",
                    wait.as_millis()
                )));
            }
            let slice = (until - now).min(Duration::from_millis(20));
            st = self
                .ready
                .wait_timeout(st, slice)
                .map_err(|_| fail("worker state poisoned".into()))?
                .0;
        }
    }
}

/// What another worker sent in an Exchange call: its density of this
/// worker's columns, or its own swept columns.
#[derive(Debug)]
enum Exchanged {
    Density(LightFrame, Vec<pb::ColumnChunk>),
    Swept(Vec<pb::DrawChunk>),
}

/// The transmittance a session's workers swept among themselves for one
/// hair version, light by light, until its Draw takes it (with its memory).
#[derive(Debug, Default)]
struct SweptHere {
    version: u64,
    maps: Vec<Option<(shadow::Transmittance, Grant)>>,
    /// Per light, whether its round is still gathering.
    pending: Vec<bool>,
    /// The first round of the version that failed.
    failed: Option<String>,
}

/// A share of a scene's hair and the scene it came from (a new Assign of
/// the same scene and groups keeps it).
#[derive(Debug)]
struct Held {
    source: SceneSource,
    share: Share,
    /// The memory budget the scene, its files, the states and the share
    /// take, given back when the share is dropped.
    _memory: Grant,
}

fn invalid(e: wire::Malformed) -> Status {
    Status::invalid_argument(e.to_string())
}

/// An engine error of a call about the share (a hair version it does not
/// hold, say): the coordinator asked for something this worker lacks.
fn refused(e: engine::EngineError) -> Status {
    Status::failed_precondition(e.to_string())
}

fn stream_of<T: Send + 'static>(items: Vec<T>) -> Chunks<T> {
    Box::pin(tokio_stream::iter(items.into_iter().map(Ok)))
}

/// A new session id: 128 random bits, in hex (unguessable: only the
/// coordinator that opened a session can name it).
fn session_id() -> Result<String, Status> {
    let mut b = [0u8; 16];
    getrandom::fill(&mut b)
        .map_err(|e| Status::internal(format!("no randomness for a session id: {e}")))?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// Sets its flag when dropped: a call's work, running off the async
/// threads, learns that the call is gone.
struct StopOnDrop(Arc<AtomicBool>);

impl Drop for StopOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// A call's stop switch, kept by the call's future, and the question its
/// work asks between runs: go on? (No, once the call is dropped.)
fn stop_switch() -> (
    StopOnDrop,
    impl Fn() -> bool + Send + Sync + Clone + 'static,
) {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    (StopOnDrop(stop), move || !flag.load(Ordering::Relaxed))
}

/// What a call whose caller has gone answers (nobody reads it).
fn cancelled(call: &str) -> Status {
    Status::cancelled(format!("the {call} was cancelled"))
}

/// Logs a refused call at the default level, with its peer and the
/// reason, and passes the result on.
fn logged<T>(
    peer: Option<SocketAddr>,
    call: &'static str,
    r: Result<T, Status>,
) -> Result<T, Status> {
    if let Err(s) = &r {
        let peer = peer.map_or_else(|| "unknown".to_string(), |p| p.to_string());
        tracing::warn!(%peer, call, code = ?s.code(), reason = s.message(), "call refused");
    }
    r
}

/// The session id a call's metadata names.
fn named_session(meta: &tonic::metadata::MetadataMap) -> Result<&str, Status> {
    let id = meta.get(SESSION_KEY).ok_or_else(|| {
        Status::failed_precondition(
            "the call names no session: call Hello first and send its session id",
        )
    })?;
    Ok(id.to_str().unwrap_or_default())
}

fn not_open(id: &str) -> Status {
    Status::failed_precondition(format!(
        "session {id:.8}... is not open on this worker (ended, idle too long, or never opened)"
    ))
}

/// The first message of a client stream; a stream of none is refused.
async fn first_message<T>(s: &mut Streaming<T>, call: &str) -> Result<T, Status> {
    s.message()
        .await?
        .ok_or_else(|| Status::invalid_argument(format!("an empty {call} call")))
}

fn poisoned<T>(_: T) -> Status {
    Status::internal("worker state poisoned")
}

impl WorkerService {
    /// A worker holding at most `limits` sessions.
    pub fn new(limits: SessionLimits) -> WorkerService {
        WorkerService {
            sessions: Mutex::default(),
            memory: Memory::new(limits.max_memory, "this worker's", "--max-memory-mib"),
            limits,
            peer_tls: None,
            peers: Mutex::default(),
        }
    }

    /// A client of the worker at `addr`, naming session `session` there:
    /// one connection per worker, kept.
    fn peer(
        &self,
        addr: &str,
        session: &str,
        domain: Option<&str>,
        timeout: Duration,
    ) -> Result<crate::client::SessionClient, Status> {
        let header = crate::client::SessionHeader::new(session)
            .ok_or_else(|| Status::invalid_argument("a band's session is not a header value"))?;
        let key = (addr.to_string(), domain.map(str::to_string));
        let mut peers = self.peers.lock().map_err(poisoned)?;
        let channel = match peers.get(&key) {
            Some(c) => c.clone(),
            None => {
                let tls = match (&self.peer_tls, domain) {
                    (Some(t), Some(d)) => Some(t.clone().with_domain(d)),
                    (t, _) => t.clone(),
                };
                let c = crate::client::endpoint(addr, timeout, tls.as_ref())
                    .map_err(|e| Status::invalid_argument(e.to_string()))?
                    .connect_lazy();
                if peers.len() >= 4 * wire::MAX_WORKERS {
                    peers.clear();
                }
                peers.insert(key, c.clone());
                c
            }
        };
        Ok(
            crate::pb::worker_client::WorkerClient::with_interceptor(channel, header)
                .max_decoding_message_size(wire::MAX_MESSAGE_BYTES)
                .max_encoding_message_size(wire::MAX_MESSAGE_BYTES),
        )
    }

    /// What a call of `session` may take: from its budget and the worker's.
    fn budget(&self, session: &Session) -> Budget {
        Budget {
            session: session.memory.clone(),
            worker: self.memory.clone(),
        }
    }

    /// The session a call names in its metadata, marked used now.
    fn session(&self, meta: &tonic::metadata::MetadataMap) -> Result<Arc<Session>, Status> {
        let id = named_session(meta)?;
        let sessions = self.sessions.lock().map_err(poisoned)?;
        let s = sessions.get(id).cloned().ok_or_else(|| not_open(id))?;
        *s.last_used.lock().map_err(poisoned)? = Instant::now();
        Ok(s)
    }

    /// Ends the sessions unused for longer than the idle limit; how many.
    pub fn end_idle(&self) -> usize {
        let Ok(mut sessions) = self.sessions.lock() else {
            return 0;
        };
        let idle = self.limits.idle;
        let before = sessions.len();
        sessions.retain(|_, s| {
            s.last_used
                .lock()
                .map(|t| t.elapsed() < idle)
                .unwrap_or(false)
        });
        let ended = before - sessions.len();
        if ended > 0 {
            tracing::info!(ended, left = sessions.len(), "idle sessions ended");
        }
        ended
    }

    /// A map in `frame`, empty, from the pool when one is free.
    fn map_in(maps: &Mutex<Vec<DensityMap>>, frame: LightFrame) -> DensityMap {
        let pooled = maps.lock().ok().and_then(|mut m| m.pop());
        match pooled {
            Some(mut m) => {
                m.set_frame(frame);
                m
            }
            None => DensityMap::new(frame),
        }
    }

    fn give_back(maps: &Mutex<Vec<DensityMap>>, mut map: DensityMap) {
        if u64::from(map.frame().n_cells).pow(3) > POOLED_CELLS {
            return;
        }
        map.trim_scratch(POOLED_SCRATCH_POINTS);
        if let Ok(mut m) = maps.lock()
            && m.len() < POOLED_MAPS
        {
            m.push(map);
        }
    }
}

/// Runs `f` on one of the thread pool's threads, so that the parallel
/// stages inside it run there, not each handed from this thread to the
/// pool and back (with one thread a worker otherwise spends about a
/// tenth of its time switching between the two). `f` must not wait on
/// anything the pool would have to do.
fn on_pool<T: Send>(f: impl FnOnce() -> T + Send) -> T {
    let mut out = None;
    rayon::scope(|_| out = Some(f()));
    out.expect("the scope ran its closure")
}

/// Runs `f` on the held share off the async threads.
async fn with_share<T: Send + 'static>(
    held: &Arc<Mutex<Option<Held>>>,
    f: impl FnOnce(&mut Share) -> Result<T, Status> + Send + 'static,
) -> Result<T, Status> {
    let held = held.clone();
    tokio::task::spawn_blocking(move || {
        let mut slot = held.lock().map_err(poisoned)?;
        let h = slot.as_mut().ok_or_else(|| {
            Status::failed_precondition("no share of the hair here: call Assign first")
        })?;
        on_pool(|| f(&mut h.share))
    })
    .await
    .map_err(|e| Status::internal(format!("worker task failed: {e}")))?
}

#[tonic::async_trait]
impl Worker for WorkerService {
    async fn hello(
        &self,
        req: Request<pb::HelloRequest>,
    ) -> Result<Response<pb::HelloReply>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let r = req.into_inner();
            if r.protocol_version != wire::PROTOCOL_VERSION {
                return Err(Status::failed_precondition(format!(
                    "this worker speaks wisplight protocol version {}, the coordinator version {}",
                    wire::PROTOCOL_VERSION,
                    r.protocol_version
                )));
            }
            let fiber = Fiber::new(r.fiber_width, r.fiber_opacity)
                .map_err(|e| Status::invalid_argument(e.to_string()))?;
            self.end_idle();
            let id = session_id()?;
            {
                let mut sessions = self.sessions.lock().map_err(poisoned)?;
                if sessions.len() >= self.limits.max_sessions {
                    return Err(Status::resource_exhausted(format!(
                        "this worker already holds {} sessions, its limit (--max-sessions); \
                         one ends when its coordinator finishes or after {} s unused",
                        sessions.len(),
                        self.limits.idle.as_secs()
                    )));
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
            let mut sessions = self.sessions.lock().map_err(poisoned)?;
            sessions.remove(id).ok_or_else(|| not_open(id))?;
            tracing::info!(session = %&id[..id.len().min(8)], sessions = sessions.len(), "session ended");
            Ok(Response::new(pb::EndReply {}))
        };
        logged(peer, "End", served.await)
    }

    type DepositStream = Chunks<pb::ColumnChunk>;

    async fn deposit(
        &self,
        req: Request<Streaming<pb::DepositChunk>>,
    ) -> Result<Response<Self::DepositStream>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(req.metadata())?;
            let fiber = session.fiber;
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Deposit").await?;
            let frame = wire::frame_from_pb(first.map.as_ref()).map_err(invalid)?;
            let (frame_id, light) = (first.frame_id, first.light);
            let mut hair = Hair::new();
            // The strands' memory, held until the call ends.
            let mut received = Grant::default();
            let memory = self.budget(&session);
            let mut add = |c: &pb::DepositChunk| -> Result<(), Status> {
                let bytes = c.points.len() as u64 / 3 * POINT_BYTES
                    + c.strand_lengths.len() as u64 * STRAND_BYTES;
                memory.take(&mut received, bytes, "the Deposit's strands")?;
                wire::add_strands(&mut hair, c).map_err(invalid)
            };
            add(&first)?;
            while let Some(c) = stream.message().await? {
                add(&c)?;
            }
            let maps = session.maps.clone();
            // Held until the map is back in the pool or dropped.
            let budget = (memory.map(&frame).await?, received);
            // The deposit stops between runs of strands once the call is gone.
            let (_stop_on_drop, go) = stop_switch();
            let plan = first
                .columns
                .as_ref()
                .map(|p| wire::ColumnPlan::from_pb(p, frame.columns()))
                .transpose()
                .map_err(invalid)?;
            let chunks = if let Some(plan) = plan {
                if !first.posed || hair.strand_count() > 0 {
                    return Err(Status::invalid_argument(
                        "a Deposit with a column plan is of posed strands, and carries none",
                    ));
                }
                if light as usize >= wire::MAX_LIGHTS {
                    return Err(Status::invalid_argument(format!(
                        "light {light} (at most {} lights)",
                        wire::MAX_LIGHTS
                    )));
                }
                let (version, light) = (first.version, light as usize);
                let round = ExchangeRound {
                    version,
                    frame,
                    sends: self.exchange_calls(&session, &plan)?,
                    plan,
                };
                let (inbox, store, memory) = (
                    session.exchange.clone(),
                    session.swept.clone(),
                    memory.clone(),
                );
                store.begin(version, light);
                // The summed columns go back as soon as they are, while the
                // swept columns are gathered for the Draw.
                let (tx, mut rx) = tokio::sync::mpsc::channel(STRIPES_IN_FLIGHT);
                let held = session.held.clone();
                tokio::task::spawn_blocking(move || {
                    let go = || !tx.is_closed();
                    let summed = (|| {
                        let mut slot = held.lock().map_err(poisoned)?;
                        let h = slot.as_mut().ok_or_else(|| {
                            Status::failed_precondition(
                                "no share of the hair here: call Assign first",
                            )
                        })?;
                        round.sum(&mut h.share, &maps, &fiber, &inbox, go)
                    })();
                    drop(budget);
                    match summed {
                        Err(s) => {
                            store.end(version, light, Err(s.message().to_string()));
                            let _ = tx.blocking_send(Err(s));
                        }
                        Ok((mut reply, rest)) => {
                            if let Some(c) = reply.first_mut() {
                                c.frame_id = frame_id;
                                c.light = light as u32;
                            }
                            for c in reply {
                                if tx.blocking_send(Ok(c)).is_err() {
                                    store.end(
                                        version,
                                        light,
                                        Err("the coordinator left the Deposit".into()),
                                    );
                                    return;
                                }
                            }
                            drop(tx);
                            store.end(version, light, rest.finish(&inbox, &memory));
                        }
                    }
                });
                // A refusal before any column is the call's own status.
                let first = match rx.recv().await {
                    Some(Ok(c)) => c,
                    Some(Err(s)) => return Err(s),
                    None => {
                        return Err(Status::internal("the Deposit's task ended without a reply"));
                    }
                };
                let rest = tokio_stream::wrappers::ReceiverStream::new(rx);
                let stream: Chunks<pb::ColumnChunk> = Box::pin(tokio_stream::StreamExt::chain(
                    tokio_stream::once(Ok::<_, Status>(first)),
                    rest,
                ));
                return Ok(Response::new(stream));
            } else if first.posed {
                if hair.strand_count() > 0 {
                    return Err(Status::invalid_argument(
                        "a posed Deposit carries no strands",
                    ));
                }
                let (version, filter) = (first.version, first.filter);
                with_share(&session.held, move |share| {
                    let _budget = budget;
                    deposit_reply(&maps, frame, |map| {
                        let stats = share
                            .deposit_while(version, map, &fiber, go)
                            .map_err(refused)?
                            .ok_or_else(|| cancelled("Deposit"))?;
                        let read = share
                            .columns_read(version, &frame, filter)
                            .map_err(refused)?;
                        Ok((stats, Some(read)))
                    })
                })
                .await?
            } else {
                tokio::task::spawn_blocking(move || {
                    let _budget = budget;
                    deposit_reply(&maps, frame, |map| {
                        let stats = map
                            .deposit_while(&hair, 0..hair.strand_count(), &fiber, go)
                            .ok_or_else(|| cancelled("Deposit"))?;
                        Ok((stats, None))
                    })
                })
                .await
                .map_err(|e| Status::internal(format!("deposit task failed: {e}")))??
            };
            let mut chunks = chunks;
            if let Some(c) = chunks.first_mut() {
                c.frame_id = frame_id;
                c.light = light;
            }
            tracing::debug!(frame_id, light, chunks = chunks.len(), "deposit done");
            Ok(Response::new(stream_of(chunks)))
        };
        logged(peer, "Deposit", served.await)
    }

    async fn assign(
        &self,
        req: Request<Streaming<pb::AssignChunk>>,
    ) -> Result<Response<pb::AssignReply>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(req.metadata())?;
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Assign").await?;
            let groups = first.first_group as usize..first.end_group as usize;
            let path = first.scene_path.clone();
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
                    return Err(Status::resource_exhausted(format!(
                        "a scene of more than {} bytes (wire::MAX_SCENE_TEXT)",
                        wire::MAX_SCENE_TEXT
                    )));
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
                    return Err(Status::resource_exhausted(format!(
                        "data files of more than {} bytes (wire::MAX_FILE_BYTES)",
                        wire::MAX_FILE_BYTES
                    )));
                }
                state_floats += floats;
                if state_floats > wire::MAX_STATE_FLOATS {
                    return Err(Status::resource_exhausted(format!(
                        "wisp states of more than {} values (wire::MAX_STATE_FLOATS)",
                        wire::MAX_STATE_FLOATS
                    )));
                }
                states.extend(c.state);
                if !c.file_path.is_empty() {
                    files.push((c.file_path, Vec::new()));
                }
                if !c.file_data.is_empty() {
                    let (_, data) = files.last_mut().ok_or_else(|| {
                        Status::invalid_argument("file data before any file's path")
                    })?;
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
                let reply = pb::AssignReply {
                    points_per_wisp: anim.points_per_wisp() as u32,
                    groups: anim.groups().count() as u32,
                    first_wisp: wisps.start as u32,
                    end_wisp: wisps.end as u32,
                };
                tracing::info!(groups = ?h.share.groups(), wisps = ?wisps, "share assigned");
                *slot = Some(h);
                Ok::<_, Status>(reply)
            })
            .await
            .map_err(|e| Status::internal(format!("assign task failed: {e}")))??;
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
            let session = self.session(req.metadata())?;
            let r = req.into_inner();
            // Set when this call is dropped (cancelled, or past its deadline):
            // the steps stop at the next one and the share is free again.
            let (_stop_on_drop, go) = stop_switch();
            let chunks = with_share(&session.held, move |share| {
                let start = std::time::Instant::now();
                let (plan, accel) = step_plan(&r, share).map_err(invalid)?;
                let mut stats = FrameStats::new(r.frame_id, 0.0);
                if !share.step_while(&plan, accel.as_deref(), &mut stats, go) {
                    return Err(Status::cancelled(format!(
                        "the Step was cancelled after {} of {} time steps",
                        stats.steps,
                        plan.heads.len()
                    )));
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
            let session = self.session(req.metadata())?;
            let plan = wire::pose_plan_from_pb(&req.into_inner()).map_err(invalid)?;
            let report = with_share(&session.held, move |share| Ok(share.pose(&plan))).await?;
            Ok(Response::new(wire::report_to_pb(&report)))
        };
        logged(peer, "Pose", served.await)
    }

    type SweepStream = Chunks<pb::SlabChunk>;

    async fn sweep(
        &self,
        req: Request<Streaming<pb::ColumnChunk>>,
    ) -> Result<Response<Self::SweepStream>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(req.metadata())?;
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Sweep").await?;
            let frame = wire::frame_from_pb(first.map.as_ref()).map_err(invalid)?;
            let (lo, hi) = (first.first_column, first.end_column);
            if lo > hi || hi as usize > frame.columns() {
                return Err(Status::invalid_argument(format!(
                    "columns {lo}..{hi} in a map of {} columns",
                    frame.columns()
                )));
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
                    .ok_or_else(|| cancelled("Sweep"))
            })
            .await
            .map_err(|e| Status::internal(format!("sweep task failed: {e}")))??;
            tracing::debug!(
                frame_id = first.frame_id,
                light = first.light,
                columns = hi - lo,
                "sweep done"
            );
            Ok(Response::new(stream_of(chunks)))
        };
        logged(peer, "Sweep", served.await)
    }

    type DrawStream = Chunks<pb::LayerChunk>;

    async fn draw(
        &self,
        req: Request<Streaming<pb::DrawChunk>>,
    ) -> Result<Response<Self::DrawStream>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(req.metadata())?;
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Draw").await?;
            let job = first.job.as_ref().ok_or_else(|| {
                Status::invalid_argument("a Draw call's first chunk carries the job")
            })?;
            let exchanged = job.exchanged;
            let job = wire::job_from_pb(job).map_err(invalid)?;
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
                return Err(Status::invalid_argument(
                    "a Draw with the exchanged columns carries none",
                ));
            }
            if first.map.is_some() || !first.column_steps.is_empty() {
                add(&first)?;
            }
            while let Some(c) = stream.message().await? {
                if c.job.is_some() {
                    return Err(Status::invalid_argument("a Draw call carries one job"));
                }
                if exchanged {
                    return Err(Status::invalid_argument(
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
                    .map_err(|e| Status::internal(format!("worker task failed: {e}")))?
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
                        Status::failed_precondition("no share of the hair here: call Assign first")
                    })?;
                    let mut encoder = wire::StripeEncoder::new();
                    let times = h
                        .share
                        .draw_stripes(&job, &maps, STRIPE_ROWS, |stripe| {
                            for c in encoder.chunks(&stripe) {
                                if !send(Ok(c)) {
                                    return Err(engine::EngineError::Executor(
                                        "the coordinator stopped reading the picture".into(),
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
                None => return Err(Status::internal("the Draw's task ended without a picture")),
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
            let session = self.session(req.metadata())?;
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
                return Err(Status::invalid_argument(format!(
                    "stripes from worker {from} of a {w}x{h} picture (at most {} workers, {} pixels)",
                    wire::MAX_WORKERS,
                    raster::MAX_PIXELS
                )));
            }
            let mut reader = wire::LayerReader::new(w, h);
            let mut grant = Grant::default();
            let mut add = |c: &pb::LayerChunk| -> Result<(), Status> {
                let bytes = u64::from(c.count) * STRIPE_PIXEL_BYTES;
                memory.take(&mut grant, bytes, "a Composite call's stripes")?;
                reader.add(c).map_err(invalid)
            };
            add(&first)?;
            while let Some(c) = stream.message().await? {
                add(&c)?;
            }
            let layer = reader.finish().map_err(invalid)?;
            session.inbox.deliver(round, from, layer, grant)?;
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
            let session = self.session(req.metadata())?;
            let memory = self.budget(&session);
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Exchange").await?;
            let (round, from, swept) = (first.round, first.from, first.swept);
            if from as usize >= wire::MAX_WORKERS || round >= u64::MAX / 2 {
                return Err(Status::invalid_argument(format!(
                    "columns from worker {from} of round {round} (at most {} workers)",
                    wire::MAX_WORKERS
                )));
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
                        return Err(Status::invalid_argument(
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

impl WorkerService {
    /// A Draw composited on the workers (see [`wire::Bands`]): one
    /// Composite call to each other band's worker carries this worker's
    /// stripes of that band while it rasterizes; then the others' stripes
    /// of its own band are gathered, and the band's finished rows are the
    /// reply.
    fn draw_band(
        &self,
        session: &Session,
        job: engine::DrawJob,
        maps: Vec<shadow::Transmittance>,
        received: (Grant, Vec<Grant>),
        bands: wire::Bands,
    ) -> Result<Chunks<pb::LayerChunk>, Status> {
        let n = bands.plan.workers;
        let own = bands.plan.own;
        session.inbox.begin(bands.round);
        let (width, height) = (job.camera.width(), job.camera.height());
        let failed: Arc<Mutex<Option<String>>> = Arc::default();
        let mut senders: Vec<Option<tokio::sync::mpsc::Sender<pb::LayerChunk>>> = vec![None; n];
        for (b, slot) in senders.iter_mut().enumerate() {
            if b == own {
                continue;
            }
            let (addr, sid) = &bands.peers[b];
            let mut client = self.peer(addr, sid, bands.tls_domain.as_deref(), bands.wait)?;
            let (tx, rx) = tokio::sync::mpsc::channel(STRIPES_IN_FLIGHT);
            let header = pb::LayerChunk {
                width,
                height,
                round: bands.round,
                from: own as u32,
                ..Default::default()
            };
            tx.try_send(header)
                .map_err(|_| Status::internal("a new channel refused its first chunk"))?;
            *slot = Some(tx);
            let (failed, addr) = (failed.clone(), addr.clone());
            tokio::spawn(async move {
                let stream = tokio_stream::wrappers::ReceiverStream::new(rx);
                if let Err(s) = client.composite(stream).await
                    && let Ok(mut f) = failed.lock()
                {
                    f.get_or_insert(format!(
                        "the worker of band {b} ({addr}) did not take this worker's stripes: {:?}: {}",
                        s.code(),
                        s.message()
                    ));
                }
            });
        }
        let (tx, rx) = tokio::sync::mpsc::channel(STRIPES_IN_FLIGHT);
        let (held, inbox) = (session.held.clone(), session.inbox.clone());
        tokio::task::spawn_blocking(move || {
            let _received = received;
            let peer_failed = || failed.lock().ok().and_then(|f| f.clone());
            let mut canvas = None;
            let drawn = (|| {
                let others: Vec<u32> = (0..n as u32).filter(|&b| b != own as u32).collect();
                let mut stripes_sent = 0u64;
                // Rasterized and sent under the share's lock, which is then
                // free for the next frame's calls while this one composites.
                let (work, background) = {
                    let mut slot = held.lock().map_err(poisoned)?;
                    let h = slot.as_mut().ok_or_else(|| {
                        Status::failed_precondition("no share of the hair here: call Assign first")
                    })?;
                    let background = raster::to_srgb8(h.share.background());
                    let mut encoders: Vec<wire::StripeEncoder> =
                        (0..n).map(|_| wire::StripeEncoder::new()).collect();
                    let work = on_pool(|| {
                        h.share.draw_band(&job, &maps, &bands.plan, |b, stripe| {
                            let to = senders[b].as_ref().expect("a call for each other worker");
                            for c in encoders[b].chunks(&stripe) {
                                stripes_sent += c.encoded_len() as u64;
                                if to.blocking_send(c).is_err() {
                                    return Err(engine::EngineError::Executor(
                                        peer_failed().unwrap_or_else(|| {
                                            format!("the call to worker {b} of the round ended")
                                        }),
                                    ));
                                }
                            }
                            Ok(())
                        })
                    })
                    .map_err(|e| Status::aborted(e.to_string()))?;
                    (work, background)
                };
                // The calls' streams end: the others can finish.
                drop(senders);
                let mut marker = wire::StripeEncoder::new().last(width, height, &work.times);
                marker.drawn = true;
                if tx.blocking_send(Ok(marker)).is_err() {
                    return Err(cancelled("Draw"));
                }
                let t = Instant::now();
                let gathered = inbox.gather(bands.round, &others, bands.wait, || {
                    if tx.is_closed() {
                        return Err("the coordinator left the Draw".into());
                    }
                    peer_failed().map_or(Ok(()), Err)
                });
                let wait_ms = t.elapsed().as_secs_f64() * 1e3;
                let gathered = match gathered {
                    // Their memory goes as it did: the resolve copies them.
                    Ok(g) => g.into_iter().map(|(layer, _)| layer).collect(),
                    Err(e) => {
                        canvas = Some(work.into_canvas());
                        return Err(Status::aborted(e.to_string()));
                    }
                };
                let (bands_drawn, mut times, done) = work.resolve(gathered);
                canvas = Some(done);
                times.wait_ms = wait_ms;
                let mut chunks = Vec::new();
                for (rows, rgb) in &bands_drawn {
                    chunks.extend(wire::band_chunks(
                        width, height, rows.start, rgb, background,
                    ));
                }
                let mut last = wire::StripeEncoder::new().last(width, height, &times);
                last.stripes_sent = stripes_sent;
                chunks.push(last);
                Ok(chunks)
            })();
            match drawn {
                Ok(chunks) => {
                    for c in chunks {
                        if tx.blocking_send(Ok(c)).is_err() {
                            break;
                        }
                    }
                }
                Err(s) => {
                    let _ = tx.blocking_send(Err(s));
                }
            }
            // The canvas back to the share, for the next frame's draw.
            if let Some(c) = canvas
                && let Ok(mut slot) = held.lock()
                && let Some(h) = slot.as_mut()
            {
                h.share.put_canvas(c);
            }
        });
        // The band's rows (or the refusal, as the stream's status) come
        // once it is resolved.
        Ok(Box::pin(tokio_stream::wrappers::ReceiverStream::new(rx)))
    }
}

/// The calls carrying this worker's columns to each other worker of a
/// column plan: per worker (none for this one), a sender of the density
/// call and one of the swept columns' call; and the first failure of any.
struct ExchangeSends {
    density: Vec<Option<tokio::sync::mpsc::Sender<pb::ExchangeChunk>>>,
    swept: Vec<Option<tokio::sync::mpsc::Sender<pb::ExchangeChunk>>>,
    failed: Arc<Mutex<Option<String>>>,
}

impl WorkerService {
    /// Opens the Exchange calls of a Deposit round with column plan
    /// `plan`: two to each other worker, fed as the round goes.
    fn exchange_calls(
        &self,
        session: &Session,
        plan: &wire::ColumnPlan,
    ) -> Result<ExchangeSends, Status> {
        let n = plan.workers();
        // Earlier rounds' columns go, but for those of the rounds just
        // before (another light's, whose swept columns may still be
        // gathered).
        session
            .exchange
            .begin((2 * plan.round).saturating_sub(4 * wire::MAX_LIGHTS as u64));
        let failed: Arc<Mutex<Option<String>>> = Arc::default();
        let mut sends = ExchangeSends {
            density: vec![None; n],
            swept: vec![None; n],
            failed: failed.clone(),
        };
        for b in (0..n).filter(|&b| b != plan.own) {
            let (addr, sid) = &plan.peers[b];
            let client = self.peer(addr, sid, plan.tls_domain.as_deref(), plan.wait)?;
            for swept in [false, true] {
                let (tx, rx) = tokio::sync::mpsc::channel(STRIPES_IN_FLIGHT);
                let (failed, addr, mut client) = (failed.clone(), addr.clone(), client.clone());
                tokio::spawn(async move {
                    let stream = tokio_stream::wrappers::ReceiverStream::new(rx);
                    if let Err(s) = client.exchange(stream).await
                        && let Ok(mut f) = failed.lock()
                    {
                        f.get_or_insert(format!(
                            "worker {b} ({addr}) did not take this worker's columns: {:?}: {}",
                            s.code(),
                            s.message()
                        ));
                    }
                });
                if swept {
                    sends.swept[b] = Some(tx);
                } else {
                    sends.density[b] = Some(tx);
                }
            }
        }
        Ok(sends)
    }
}

/// One worker's part of a Deposit round with a column plan (see
/// [`wire::ColumnPlan`]).
struct ExchangeRound {
    version: u64,
    frame: LightFrame,
    plan: wire::ColumnPlan,
    sends: ExchangeSends,
}

/// What is left of a round once the worker's columns are summed and
/// swept: the all-gather of the swept columns.
struct SweptRound {
    round: ExchangeRound,
    /// This worker's swept columns, as the Exchange chunks that carry them.
    own: Vec<pb::ExchangeChunk>,
}

impl ExchangeRound {
    /// Deposits the share's strands, sends each other worker its columns,
    /// sums the others' density of this worker's columns, adds the head
    /// and sweeps them. The reply: the summed density of this worker's
    /// columns, the last chunk with the fill's counts and the bytes this
    /// worker sends the others; and the rest of the round.
    fn sum(
        mut self,
        share: &mut Share,
        maps: &Mutex<Vec<DensityMap>>,
        fiber: &Fiber,
        inbox: &Inbox<Exchanged>,
        go: impl Fn() -> bool + Clone + Send + Sync,
    ) -> Result<(Vec<pb::ColumnChunk>, SweptRound), Status> {
        let (frame, plan) = (self.frame, &self.plan);
        let (n, own) = (plan.workers(), plan.own);
        let others: Vec<u32> = (0..n as u32).filter(|&b| b != own as u32).collect();
        let mine = plan.range(own);
        let failed = self.sends.failed.clone();
        let go_on = || {
            if !go() {
                return Err("the coordinator left the Deposit".to_string());
            }
            failed
                .lock()
                .ok()
                .and_then(|f| f.clone())
                .map_or(Ok(()), Err)
        };
        let mut map = WorkerService::map_in(maps, frame);
        let stats = on_pool(|| share.deposit_while(self.version, &mut map, fiber, go.clone()))
            .map_err(refused)?
            .ok_or_else(|| cancelled("Deposit"))?;
        // Reduce-scatter: each other worker's columns to it.
        let mut density_sent = 0u64;
        for b in 0..n {
            let Some(to) = self.sends.density[b].take() else {
                continue;
            };
            for (i, c) in wire::column_chunks(&map, plan.range(b))
                .into_iter()
                .enumerate()
            {
                density_sent += self.sends.send(
                    &to,
                    pb::ExchangeChunk {
                        round: plan.round,
                        from: own as u32,
                        map: (i == 0).then(|| wire::frame_to_pb(&frame)),
                        density: Some(c),
                        ..Default::default()
                    },
                )?;
            }
        }
        let got = inbox
            .gather(2 * plan.round, &others, plan.wait, go_on)
            .map_err(|e| Status::aborted(e.to_string()))?;
        for (b, (item, _)) in others.iter().zip(got) {
            let Exchanged::Density(f, chunks) = item else {
                return Err(Status::aborted(format!(
                    "worker {b} sent swept columns for density"
                )));
            };
            if f != frame {
                return Err(Status::aborted(format!(
                    "worker {b}'s density is of another map"
                )));
            }
            for c in &chunks {
                let d = wire::decode_columns(&frame, c)
                    .map_err(|e| Status::aborted(format!("worker {b}'s density: {e}")))?;
                if !d.within(mine.clone()) {
                    return Err(Status::aborted(format!(
                        "worker {b}'s density reaches past this worker's columns {mine:?}"
                    )));
                }
                wire::add_columns(&mut map, &d);
            }
        }
        let mut reply = wire::column_chunks(&map, mine.clone());
        // The head, then the sweep of this worker's columns.
        if let Some(h) = plan.head {
            share.deposit_head(&mut map, h);
        }
        let slab = on_pool(|| shadow::sweep_while(&map, mine.start as u32..mine.end as u32, go));
        WorkerService::give_back(maps, map);
        let slab = slab.ok_or_else(|| cancelled("Deposit"))?;
        let own_swept: Vec<pb::ExchangeChunk> = wire::swept_chunks(&frame, &slab)
            .into_iter()
            .map(|c| pb::ExchangeChunk {
                round: plan.round,
                from: own as u32,
                swept: true,
                columns: Some(c),
                ..Default::default()
            })
            .collect();
        // Each other worker gets them all.
        let swept_sent = (n as u64 - 1)
            * own_swept
                .iter()
                .map(|c| c.encoded_len() as u64)
                .sum::<u64>();
        if let Some(c) = reply.last_mut() {
            c.samples = stats.samples;
            c.out_of_map = stats.out_of_map;
            c.exchanged_density = density_sent;
            c.exchanged_swept = swept_sent;
        }
        Ok((
            reply,
            SweptRound {
                round: self,
                own: own_swept,
            },
        ))
    }
}

impl ExchangeSends {
    /// Sends `c` on `to`: its bytes, or the round's failure.
    fn send(
        &self,
        to: &tokio::sync::mpsc::Sender<pb::ExchangeChunk>,
        c: pb::ExchangeChunk,
    ) -> Result<u64, Status> {
        let bytes = c.encoded_len() as u64;
        to.blocking_send(c).map_err(|_| {
            Status::aborted(
                self.failed
                    .lock()
                    .ok()
                    .and_then(|f| f.clone())
                    .unwrap_or_else(|| "a call to another worker ended".to_string()),
            )
        })?;
        Ok(bytes)
    }
}

impl SweptRound {
    /// Sends this worker's swept columns to every other worker, gathers
    /// theirs, and assembles the light's transmittance, in the budget.
    fn finish(
        self,
        inbox: &Inbox<Exchanged>,
        memory: &Budget,
    ) -> Result<(shadow::Transmittance, Grant), String> {
        let SweptRound { mut round, own } = self;
        let plan = &round.plan;
        let n = plan.workers();
        let others: Vec<u32> = (0..n as u32).filter(|&b| b != plan.own as u32).collect();
        for b in 0..n {
            let Some(to) = round.sends.swept[b].take() else {
                continue;
            };
            for c in &own {
                round
                    .sends
                    .send(&to, c.clone())
                    .map_err(|s| s.message().to_string())?;
            }
        }
        let failed = round.sends.failed.clone();
        let go_on = || {
            failed
                .lock()
                .ok()
                .and_then(|f| f.clone())
                .map_or(Ok(()), Err)
        };
        let got = inbox
            .gather(2 * plan.round + 1, &others, plan.wait, go_on)
            .map_err(|e| e.to_string())?;
        let mut owners: Vec<Vec<pb::DrawChunk>> = vec![Vec::new(); n];
        owners[plan.own] = own.into_iter().filter_map(|c| c.columns).collect();
        let mut grants = Vec::with_capacity(n);
        for (&b, (item, grant)) in others.iter().zip(got) {
            let Exchanged::Swept(chunks) = item else {
                return Err(format!("worker {b} sent density for swept columns"));
            };
            owners[b as usize] = chunks;
            grants.push(grant);
        }
        let trans = wire::assemble_swept(round.frame, plan, &owners)
            .map_err(|e| format!("the swept columns: {e}"))?;
        drop(owners);
        drop(grants);
        // Kept until the Draw, in the budget.
        let mut kept = Grant::default();
        memory
            .take(
                &mut kept,
                trans.bytes() as u64,
                "the swept columns kept for the Draw",
            )
            .map_err(|s| s.message().to_string())?;
        Ok((trans, kept))
    }
}

/// The transmittance each Deposit round with a column plan leaves for the
/// Draw of its hair version, light by light, as the rounds finish.
#[derive(Debug, Default)]
struct SweptStore {
    state: Mutex<SweptHere>,
    ready: std::sync::Condvar,
}

impl SweptStore {
    /// A round of hair `version`, light `light`, begins.
    fn begin(&self, version: u64, light: usize) {
        if let Ok(mut st) = self.state.lock() {
            if st.version != version {
                *st = SweptHere {
                    version,
                    ..Default::default()
                };
            }
            if st.maps.len() <= light {
                st.maps.resize_with(light + 1, || None);
                st.pending.resize(light + 1, false);
            }
            st.maps[light] = None;
            st.pending[light] = true;
        }
    }

    /// The round of `version`, `light` ended with `result`.
    fn end(
        &self,
        version: u64,
        light: usize,
        result: Result<(shadow::Transmittance, Grant), String>,
    ) {
        if let Ok(mut st) = self.state.lock()
            && st.version == version
            && light < st.maps.len()
        {
            st.pending[light] = false;
            match result {
                Ok(m) => st.maps[light] = Some(m),
                Err(e) => {
                    tracing::warn!(version, light, error = %e, "the swept columns were not gathered");
                    st.failed.get_or_insert(e);
                }
            }
            self.ready.notify_all();
        }
    }

    /// Every light's transmittance of hair `version`, `lights` of them,
    /// once the rounds gathered them (waiting at most `wait`), and their
    /// memory; why not otherwise.
    #[allow(clippy::type_complexity)]
    fn take(
        &self,
        version: u64,
        lights: usize,
        wait: Duration,
    ) -> Result<(Vec<shadow::Transmittance>, Vec<Grant>), String> {
        let until = Instant::now() + wait;
        let mut st = self.state.lock().map_err(|_| "worker state poisoned")?;
        loop {
            if st.version != version || st.maps.len() != lights {
                return Err(format!(
                    "no columns of all {lights} lights summed here for hair version {version}"
                ));
            }
            if let Some(e) = &st.failed {
                return Err(e.clone());
            }
            if st.maps.iter().all(Option::is_some) {
                st.pending.clear();
                return Ok(st.maps.drain(..).map(|m| m.expect("checked")).unzip());
            }
            if !st.pending.iter().any(|&p| p) {
                return Err("a light's columns were not summed here".into());
            }
            let now = Instant::now();
            if now >= until {
                return Err(format!(
                    "the other workers' swept columns did not come within {} ms",
                    wait.as_millis()
                ));
            }
            st = self
                .ready
                .wait_timeout(st, (until - now).min(Duration::from_millis(50)))
                .map_err(|_| "worker state poisoned")?
                .0;
        }
    }
}

/// A Deposit's reply: a pooled map in `frame`, filled by `fill`, as
/// column chunks, the last one carrying the fill's counts and, for posed
/// strands, the columns their lookups read.
fn deposit_reply(
    maps: &Mutex<Vec<DensityMap>>,
    frame: LightFrame,
    fill: impl FnOnce(&mut DensityMap) -> Result<(FillStats, Option<Vec<u64>>), Status>,
) -> Result<Vec<pb::ColumnChunk>, Status> {
    let mut map = WorkerService::map_in(maps, frame);
    let (stats, read) = fill(&mut map)?;
    let mut chunks = wire::column_chunks(&map, 0..frame.columns());
    WorkerService::give_back(maps, map);
    if let Some(c) = chunks.last_mut() {
        c.samples = stats.samples;
        c.out_of_map = stats.out_of_map;
        if let Some(read) = read {
            c.columns_read = wire::columns_to_pb(&read);
        }
    }
    Ok(chunks)
}

/// The state of the share's wisps, as chunks.
fn share_chunks(share: &Share) -> Result<Vec<pb::WispChunk>, Status> {
    let wisps = share.wisps();
    let states: Option<Vec<_>> = wisps
        .clone()
        .map(|w| share.animator().wisp_state(w))
        .collect();
    let states = states.ok_or_else(|| Status::internal("a wisp of the share is missing"))?;
    Ok(wire::wisp_chunks(wisps.start, states))
}

/// Builds the share an Assign call asks for (off the async threads: the
/// scene's hair is generated here), keeping the old one's hair when the
/// scene and groups are the same.
/// The share of `groups` of the scene `source` says, with wisp `states`:
/// `old` when it is of the same scene and groups, else a new one, whose
/// memory (estimated before it is built) joins `received` in the budget.
fn build_share(
    old: Option<Held>,
    source: SceneSource,
    groups: Range<usize>,
    states: &[pb::WispChunk],
    memory: &Budget,
    mut received: Grant,
) -> Result<Held, Status> {
    let mut held = match old {
        Some(h) if h.source == source && h.share.groups() == groups => h,
        old => {
            drop(old);
            let scene = Scene::from_source(&source)
                .map_err(|e| Status::invalid_argument(format!("the scene: {e}")))?;
            let bytes = share_bytes(&scene)
                .map_err(|e| Status::invalid_argument(format!("the scene's hair: {e}")))?;
            memory.take(&mut received, bytes, "the scene's hair and picture")?;
            let share = Share::new(&scene, groups)
                .map_err(|e| Status::invalid_argument(format!("the scene's hair: {e}")))?;
            Held {
                source,
                share,
                _memory: received,
            }
        }
    };
    let share = &mut held.share;
    let wisps = share.wisps();
    let per = share.animator().points_per_wisp();
    let mut seen = vec![false; wisps.len()];
    for c in states {
        for (w, state) in wire::wisps_from_chunk(c, per, &wisps).map_err(invalid)? {
            share
                .animator_mut()
                .set_wisp_state(w, state)
                .map_err(|e| Status::invalid_argument(e.to_string()))?;
            seen[w - wisps.start] = true;
        }
    }
    if let Some(i) = seen.iter().position(|s| !s) {
        return Err(Status::invalid_argument(format!(
            "no state for wisp {}",
            wisps.start + i
        )));
    }
    Ok(held)
}

/// A Step request as a plan for `share`: the worker's accelerations apart.
fn step_plan(
    r: &pb::StepRequest,
    share: &Share,
) -> Result<(StepPlan, Option<Vec<glam::Vec3>>), wire::Malformed> {
    let heads = wire::affines_from_floats(&r.heads)?;
    if r.body_counts.len() != heads.len() {
        return Err(wire::Malformed(format!(
            "{} steps with {} body counts",
            heads.len(),
            r.body_counts.len()
        )));
    }
    let all = wire::bodies_from_floats(&r.bodies)?;
    let total: u64 = r.body_counts.iter().map(|&c| u64::from(c)).sum();
    if total != all.len() as u64 {
        return Err(wire::Malformed(format!(
            "body counts add up to {total}, {} bodies came",
            all.len()
        )));
    }
    let mut at = 0;
    let bodies = r
        .body_counts
        .iter()
        .map(|&c| {
            let b = all[at..at + c as usize].to_vec();
            at += c as usize;
            b
        })
        .collect();
    let points = share.wisps().len() * share.animator().points_per_wisp();
    let accel = if r.has_accel {
        Some(wire::accel_from_pb(&r.accel_skip, &r.accel, points)?)
    } else {
        None
    };
    let pose = r
        .pose
        .as_ref()
        .ok_or_else(|| wire::Malformed("a Step without its pose".into()))?;
    let plan = StepPlan {
        heads,
        bodies,
        accel: None,
        pose: wire::pose_plan_from_pb(pose)?,
    };
    Ok((plan, accel))
}

/// How a worker listens, besides its address.
#[derive(Debug, Clone, Default)]
pub struct Listen {
    /// Mutual TLS: only clients presenting a certificate signed by its CA
    /// get through the handshake.
    pub tls: Option<Tls>,
    /// A second address serving grpc.health.v1 alone, without TLS, for
    /// probes that cannot present a certificate (Kubernetes, Docker).
    pub health: Option<SocketAddr>,
}

/// The addresses a worker serves on, once bound (port 0 picked free
/// ones): the worker's, and its plain health port's, if any.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bound {
    pub addr: SocketAddr,
    pub health: Option<SocketAddr>,
}

/// Serves a worker on `addr` (port 0 picks a free port) until `shutdown`
/// completes; `bound` is called with the address actually bound, before
/// the first request is served.
pub async fn serve(
    service: WorkerService,
    addr: SocketAddr,
    listen: &Listen,
    bound: impl FnOnce(Bound),
    shutdown: impl std::future::Future<Output = ()> + Send,
) -> Result<(), ClusterError> {
    let incoming = tonic::transport::server::TcpIncoming::bind(addr)
        .map_err(|e| ClusterError::Bind(addr, e))?
        .with_nodelay(Some(true));
    let local = incoming
        .local_addr()
        .map_err(|e| ClusterError::Bind(addr, e))?;
    let (health, health_service) = tonic_health::server::health_reporter();
    health.set_serving::<WorkerServer<WorkerService>>().await;
    health
        .set_service_status("", tonic_health::ServingStatus::Serving)
        .await;
    let reflection_v1 = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(pb::DESCRIPTOR)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1()
        .map_err(|e| ClusterError::Setup(e.to_string()))?;
    let reflection_v1alpha = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(pb::DESCRIPTOR)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1alpha()
        .map_err(|e| ClusterError::Setup(e.to_string()))?;
    // Workers compositing a picture together call each other with the
    // credentials they serve with.
    let mut service = service;
    service.peer_tls = listen.tls.clone();
    // Idle sessions end even when no Hello comes to notice them.
    let service = Arc::new(service);
    let sweeper = {
        let service = service.clone();
        let every =
            (service.limits.idle / 4).clamp(Duration::from_millis(50), Duration::from_secs(30));
        tokio::spawn(async move {
            loop {
                tokio::time::sleep(every).await;
                service.end_idle();
            }
        })
    };
    let worker = WorkerServer::from_arc(service)
        .max_decoding_message_size(wire::MAX_MESSAGE_BYTES)
        .max_encoding_message_size(wire::MAX_MESSAGE_BYTES);
    let mut server = tonic::transport::Server::builder();
    if let Some(t) = &listen.tls {
        server = server
            .tls_config(t.server_config())
            .map_err(|e| t.refused(&e))?;
    }
    // The health port stops when the worker has.
    let (stop, stopped) = tokio::sync::watch::channel(false);
    let mut health_addr = None;
    let health_server = match listen.health {
        Some(h) => {
            let incoming = tonic::transport::server::TcpIncoming::bind(h)
                .map_err(|e| ClusterError::Bind(h, e))?;
            health_addr = Some(
                incoming
                    .local_addr()
                    .map_err(|e| ClusterError::Bind(h, e))?,
            );
            let mut stopped = stopped.clone();
            let probe = health_service.clone();
            Some(tokio::spawn(async move {
                tonic::transport::Server::builder()
                    .add_service(probe)
                    .serve_with_incoming_shutdown(incoming, async move {
                        let _ = stopped.changed().await;
                    })
                    .await
            }))
        }
        None => None,
    };
    bound(Bound {
        addr: local,
        health: health_addr,
    });
    let served = server
        .add_service(health_service)
        .add_service(reflection_v1)
        .add_service(reflection_v1alpha)
        .add_service(worker)
        .serve_with_incoming_shutdown(incoming, shutdown)
        .await
        .map_err(|e| ClusterError::Serve(e.to_string()));
    sweeper.abort();
    let _ = stop.send(true);
    if let Some(h) = health_server {
        match h.await {
            Ok(Err(e)) => tracing::warn!(error = %e, "the health port stopped with an error"),
            Err(e) => tracing::warn!(error = %e, "the health port's task failed"),
            Ok(Ok(())) => {}
        }
    }
    served
}

/// Runs a worker on `addr` until SIGTERM or SIGINT (Ctrl-C), then finishes
/// the calls in flight and returns. `bound` gets the bound address.
pub fn run(
    service: WorkerService,
    addr: SocketAddr,
    listen: &Listen,
    bound: impl FnOnce(Bound),
) -> Result<(), ClusterError> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| ClusterError::Setup(format!("cannot start the network runtime: {e}")))?;
    rt.block_on(serve(service, addr, listen, bound, shutdown_signal()))
}

/// Completes on SIGTERM or SIGINT.
async fn shutdown_signal() {
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    tokio::select! {
        _ = tokio::signal::ctrl_c() => {},
        _ = term => {},
    }
    tracing::info!("shutting down");
}
