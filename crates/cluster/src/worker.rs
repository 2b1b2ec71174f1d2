//! The worker: fills partial density maps and sweeps column ranges for a
//! coordinator, behind the `wisplight.v1.Worker` gRPC service, with
//! grpc.health.v1 health and server reflection.

use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::{Arc, Mutex};

use shadow::{ColumnSlab, DensityMap, Fiber, LightFrame};
use strands::Hair;
use tokio_stream::Stream;
use tonic::{Request, Response, Status, Streaming};

use crate::pb::worker_server::{Worker, WorkerServer};
use crate::{ClusterError, pb, wire};

type Chunks<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send>>;

/// The worker's state: the fiber of the coordinator it serves, and density
/// maps kept between calls (their memory, not their content).
#[derive(Debug, Default)]
pub struct WorkerService {
    fiber: Mutex<Option<Fiber>>,
    maps: Arc<Mutex<Vec<DensityMap>>>,
}

fn invalid(e: wire::Malformed) -> Status {
    Status::invalid_argument(e.to_string())
}

fn stream_of<T: Send + 'static>(items: Vec<T>) -> Chunks<T> {
    Box::pin(tokio_stream::iter(items.into_iter().map(Ok)))
}

impl WorkerService {
    fn fiber(&self) -> Result<Fiber, Status> {
        self.fiber
            .lock()
            .map_err(|_| Status::internal("worker state poisoned"))?
            .ok_or_else(|| Status::failed_precondition("call Hello first (protocol version check)"))
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

    fn give_back(maps: &Mutex<Vec<DensityMap>>, map: DensityMap) {
        if let Ok(mut m) = maps.lock()
            && m.len() < 4
        {
            m.push(map);
        }
    }
}

#[tonic::async_trait]
impl Worker for WorkerService {
    async fn hello(
        &self,
        req: Request<pb::HelloRequest>,
    ) -> Result<Response<pb::HelloReply>, Status> {
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
        *self
            .fiber
            .lock()
            .map_err(|_| Status::internal("worker state poisoned"))? = Some(fiber);
        Ok(Response::new(pb::HelloReply {
            protocol_version: wire::PROTOCOL_VERSION,
            worker: format!("wisplight-worker {}", env!("CARGO_PKG_VERSION")),
        }))
    }

    type DepositStream = Chunks<pb::ColumnChunk>;

    async fn deposit(
        &self,
        req: Request<Streaming<pb::DepositChunk>>,
    ) -> Result<Response<Self::DepositStream>, Status> {
        let fiber = self.fiber()?;
        let mut stream = req.into_inner();
        let first = stream
            .message()
            .await?
            .ok_or_else(|| Status::invalid_argument("an empty Deposit call"))?;
        let frame = wire::frame_from_pb(first.map.as_ref()).map_err(invalid)?;
        let (frame_id, light) = (first.frame_id, first.light);
        let mut hair = Hair::new();
        wire::add_strands(&mut hair, &first).map_err(invalid)?;
        while let Some(c) = stream.message().await? {
            wire::add_strands(&mut hair, &c).map_err(invalid)?;
        }
        let maps = self.maps.clone();
        let chunks = tokio::task::spawn_blocking(move || {
            let mut map = WorkerService::map_in(&maps, frame);
            let stats = map.deposit(&hair, 0..hair.strand_count(), &fiber);
            let mut chunks = wire::column_chunks(&map, 0..frame.columns());
            WorkerService::give_back(&maps, map);
            if let Some(c) = chunks.first_mut() {
                c.frame_id = frame_id;
                c.light = light;
            }
            if let Some(c) = chunks.last_mut() {
                c.samples = stats.samples;
                c.out_of_map = stats.out_of_map;
            }
            chunks
        })
        .await
        .map_err(|e| Status::internal(format!("deposit task failed: {e}")))?;
        tracing::debug!(frame_id, light, chunks = chunks.len(), "deposit done");
        Ok(Response::new(stream_of(chunks)))
    }

    type SweepStream = Chunks<pb::SlabChunk>;

    async fn sweep(
        &self,
        req: Request<Streaming<pb::ColumnChunk>>,
    ) -> Result<Response<Self::SweepStream>, Status> {
        self.fiber()?;
        let mut stream = req.into_inner();
        let first = stream
            .message()
            .await?
            .ok_or_else(|| Status::invalid_argument("an empty Sweep call"))?;
        let frame = wire::frame_from_pb(first.map.as_ref()).map_err(invalid)?;
        let (lo, hi) = (first.first_column, first.end_column);
        if lo > hi || hi as usize > frame.columns() {
            return Err(Status::invalid_argument(format!(
                "columns {lo}..{hi} in a map of {} columns",
                frame.columns()
            )));
        }
        let maps = self.maps.clone();
        // On an error the map is dropped (the pool makes another).
        let mut map = WorkerService::map_in(&maps, frame);
        wire::merge_columns(&mut map, &first).map_err(invalid)?;
        while let Some(c) = stream.message().await? {
            wire::merge_columns(&mut map, &c).map_err(invalid)?;
        }
        let chunks = tokio::task::spawn_blocking(move || {
            let slab: ColumnSlab = shadow::sweep(&map, lo..hi);
            WorkerService::give_back(&maps, map);
            wire::slab_chunks(&slab)
        })
        .await
        .map_err(|e| Status::internal(format!("sweep task failed: {e}")))?;
        tracing::debug!(
            frame_id = first.frame_id,
            light = first.light,
            columns = hi - lo,
            "sweep done"
        );
        Ok(Response::new(stream_of(chunks)))
    }
}

/// Serves a worker on `addr` (port 0 picks a free port) until `shutdown`
/// completes; `bound` is called with the address actually bound, before
/// the first request is served.
pub async fn serve(
    addr: SocketAddr,
    bound: impl FnOnce(SocketAddr),
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
    let worker = WorkerServer::new(WorkerService::default())
        .max_decoding_message_size(wire::MAX_MESSAGE_BYTES)
        .max_encoding_message_size(wire::MAX_MESSAGE_BYTES);
    bound(local);
    tonic::transport::Server::builder()
        .add_service(health_service)
        .add_service(reflection_v1)
        .add_service(reflection_v1alpha)
        .add_service(worker)
        .serve_with_incoming_shutdown(incoming, shutdown)
        .await
        .map_err(|e| ClusterError::Serve(e.to_string()))
}

/// Runs a worker on `addr` until SIGTERM or SIGINT (Ctrl-C), then finishes
/// the calls in flight and returns. `bound` gets the bound address.
pub fn run(addr: SocketAddr, bound: impl FnOnce(SocketAddr)) -> Result<(), ClusterError> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| ClusterError::Setup(format!("cannot start the network runtime: {e}")))?;
    rt.block_on(serve(addr, bound, shutdown_signal()))
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
