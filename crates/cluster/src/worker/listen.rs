//! Serving: the listening socket, TLS, health, reflection and shutdown.

use crate::pb::worker_server::WorkerServer;
use crate::{ClusterError, Tls, WorkerService, pb, wire};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

/// How a worker listens, besides its address.
#[derive(Debug, Clone, Default)]
pub struct Listen {
    /// Mutual TLS: only clients presenting a certificate signed by its CA
    /// get through the handshake.
    pub tls: Option<Tls>,
    /// A second address serving grpc.health.v1 alone, without TLS, for
    /// probes that cannot present a certificate (Kubernetes, Docker).
    pub health: Option<SocketAddr>,
    /// The cluster's token: a Hello must prove it, and this worker proves
    /// it to its peers and asks them to (see `crate::token`). `None`: a
    /// Hello needs no proof.
    pub token: Option<crate::Token>,
}

/// The addresses a worker serves on, once bound (port 0 picked free
/// ones): the worker's, and its plain health port's, if any.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bound {
    /// The worker's address.
    pub addr: SocketAddr,
    /// Its plain health port, if any.
    pub health: Option<SocketAddr>,
}

/// Serves a worker on `addr` (port 0 picks a free port) until `shutdown`
/// completes; `bound` is called with the address actually bound, before
/// the first request is served.
pub async fn serve_worker(
    service: WorkerService,
    addr: SocketAddr,
    listen: &Listen,
    bound: impl FnOnce(Bound),
    shutdown: impl std::future::Future<Output = ()> + Send,
) -> Result<(), ClusterError> {
    let incoming = tonic::transport::server::TcpIncoming::bind(addr)
        .map_err(|e| ClusterError::Bind(addr, e.into()))?
        .with_nodelay(Some(true));
    let local = incoming
        .local_addr()
        .map_err(|e| ClusterError::Bind(addr, e.into()))?;
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
    service.token = listen.token.clone();
    // Each accepted connection counted while open, for the sessions whose
    // coordinator went away.
    let incoming = {
        use tokio_stream::StreamExt;
        let connections = service.connections.clone();
        incoming.map(move |r| r.map(|s| connections.track(s)))
    };
    // Idle sessions end even when no Hello comes to notice them.
    let service = Arc::new(service);
    let sweeper = {
        let service = service.clone();
        let every = (service.limits.idle.min(service.limits.orphaned) / 4)
            .clamp(Duration::from_millis(50), Duration::from_secs(30));
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
                .map_err(|e| ClusterError::Bind(h, e.into()))?;
            health_addr = Some(
                incoming
                    .local_addr()
                    .map_err(|e| ClusterError::Bind(h, e.into()))?,
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
pub fn run_worker(
    service: WorkerService,
    addr: SocketAddr,
    listen: &Listen,
    bound: impl FnOnce(Bound),
) -> Result<(), ClusterError> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| ClusterError::Setup(format!("cannot start the network runtime: {e}")))?;
    rt.block_on(serve_worker(
        service,
        addr,
        listen,
        bound,
        shutdown_signal(),
    ))
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
