//! The worker: holds a share of a scene's hair (whole groups of strands,
//! with their wisps), steps and poses it, fills partial density maps,
//! sweeps column ranges, and filters, shades and rasterizes its strands
//! into partial pictures for a coordinator, behind the `wisplight.v1.Worker`
//! gRPC service, with grpc.health.v1 health and server reflection. The
//! stages are the engine's own ([`engine::Share`]).
//!
//! The service's impl below only dispatches; each call lives with its
//! concept: Hello and End in `session.rs`, Assign in `assign.rs`, Simulate
//! and Pose in `step.rs`, Density in `density.rs` (and its rounds among
//! the workers in `exchange.rs`, with Exchange), Transmittance in
//! `transmittance.rs`, Draw and Composite in `draw.rs`.

mod assign;
mod connections;
mod density;
mod draw;
mod exchange;
mod inbox;
mod listen;
mod memory;
mod proof;
mod session;
mod share;
mod simulate;
mod status;
mod swept;
mod transmittance;

pub use listen::{Bound, Listen, run_worker, serve_worker};
use memory::*;
use session::*;

use std::collections::HashMap;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use shadow::DensityMap;
use tokio_stream::Stream;
use tonic::{Request, Response, Status, Streaming};

use crate::pb::worker_server::Worker;
use crate::{Tls, pb};

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
    /// The cluster's token, when the worker was given one: what a Hello
    /// proves, and what this worker proves to its peers and asks them to.
    token: Option<crate::Token>,
    /// Challenges given for a Hello to prove the token over.
    challenges: proof::Challenges,
    /// Fellow workers' sessions that proved they belong to the cluster.
    proven: std::sync::Arc<proof::Proven>,
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
    async fn challenge(
        &self,
        req: Request<pb::ChallengeRequest>,
    ) -> Result<Response<pb::ChallengeReply>, Status> {
        self.challenge_call(req).await
    }

    async fn hello(
        &self,
        req: Request<pb::HelloRequest>,
    ) -> Result<Response<pb::HelloReply>, Status> {
        self.hello_call(req).await
    }

    async fn prove(
        &self,
        req: Request<pb::ProveRequest>,
    ) -> Result<Response<pb::ProveReply>, Status> {
        self.prove_call(req).await
    }

    async fn end(&self, req: Request<pb::EndRequest>) -> Result<Response<pb::EndReply>, Status> {
        self.end_call(req).await
    }

    type DensityStream = Chunks<pb::ColumnChunk>;

    async fn density(
        &self,
        req: Request<Streaming<pb::DensityChunk>>,
    ) -> Result<Response<Self::DensityStream>, Status> {
        self.density_call(req).await
    }

    async fn assign(
        &self,
        req: Request<Streaming<pb::AssignChunk>>,
    ) -> Result<Response<pb::AssignReply>, Status> {
        self.assign_call(req).await
    }

    type SimulateStream = Chunks<pb::WispChunk>;

    async fn simulate(
        &self,
        req: Request<pb::SimulateRequest>,
    ) -> Result<Response<Self::SimulateStream>, Status> {
        self.simulate_call(req).await
    }

    async fn pose(&self, req: Request<pb::PosePlan>) -> Result<Response<pb::PoseReport>, Status> {
        self.pose_call(req).await
    }

    type TransmittanceStream = Chunks<pb::SlabChunk>;

    async fn transmittance(
        &self,
        req: Request<Streaming<pb::ColumnChunk>>,
    ) -> Result<Response<Self::TransmittanceStream>, Status> {
        self.transmittance_call(req).await
    }

    type DrawStream = Chunks<pb::LayerChunk>;

    async fn draw(
        &self,
        req: Request<Streaming<pb::DrawChunk>>,
    ) -> Result<Response<Self::DrawStream>, Status> {
        self.draw_call(req).await
    }

    async fn composite(
        &self,
        req: Request<Streaming<pb::LayerChunk>>,
    ) -> Result<Response<pb::CompositeReply>, Status> {
        self.composite_call(req).await
    }

    async fn exchange(
        &self,
        req: Request<Streaming<pb::ExchangeChunk>>,
    ) -> Result<Response<pb::ExchangeReply>, Status> {
        self.exchange_call(req).await
    }
}
