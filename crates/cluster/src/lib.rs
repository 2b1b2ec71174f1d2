//! Cluster mode, in the paper's parallel scheme (section 5.2), extended:
//! workers simulate a share of the wisps, fill their density and sweep a
//! share of the map's columns, and (by default) pose, filter, shade and
//! rasterize their strands into partial pictures; a coordinator sums the
//! densities, hands out columns and slabs, and composites. The only crate
//! that knows protobuf, tonic and tokio.

pub mod pb {
    //! Code generated from `proto/wisplight/v1/worker.proto`.
    #![allow(missing_debug_implementations, missing_docs, clippy::all)]
    tonic::include_proto!("wisplight.v1");

    /// The encoded descriptor set, for server reflection.
    pub const DESCRIPTOR: &[u8] = tonic::include_file_descriptor_set!("wisplight_descriptor");
}

mod client;
mod codec;
mod error;
mod remote;
mod tls;
mod token;
mod wire;
mod worker;

pub mod protocol {
    //! What a client that speaks to workers itself needs beside [`crate::pb`]:
    //! the protocol's version, its limits, and the encoders of the messages
    //! that carry engine values (a load generator, a fuzzer, a conformance
    //! test). The coordinator ([`crate::RemoteExecutor`]) does all of this
    //! for the renderer.
    pub use crate::wire::{
        MAX_FILE_BYTES, MAX_MESSAGE_BYTES, MAX_SCENE_TEXT, MAX_STEP_WORK, MAX_STEPS, Malformed,
        PROTOCOL_VERSION, TEXT_PIECE_BYTES, density_chunks, frame_to_pb, job_to_pb, pack,
        report_from_pb, step_work, text_pieces, wisp_chunks,
    };
}

pub use client::{SessionClient, SessionHeader, Timing, Traffic};
pub use error::{ClusterError, WorkerError, WorkerErrorKind};
pub use remote::{DrawAt, Options, RemoteExecutor, Scheme};
pub use tls::{COORDINATOR_NAME, Pki, Tls, WORKER_NAME};
pub use token::{MIN_TOKEN_LEN, Token};
pub use worker::{
    Bound, DEFAULT_MAX_MEMORY, Listen, POOL_BYTES, SessionLimits, WorkerService, run_worker,
    serve_worker,
};

/// What went wrong in cluster mode, naming the worker.
/// Asks the worker at `addr` for its grpc.health.v1 status (the overall
/// server, service ""): Ok(true) when it is SERVING. With `tls`, over
/// mutual TLS.
pub fn check_health(
    addr: &str,
    deadline: std::time::Duration,
    tls: Option<&Tls>,
) -> Result<bool, ClusterError> {
    use tonic_health::pb::health_check_response::ServingStatus;
    use tonic_health::pb::{HealthCheckRequest, health_client::HealthClient};
    let err = |msg: String| ClusterError::Connect {
        addr: addr.to_string(),
        msg: tls::explain(tls, msg),
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| ClusterError::Setup(format!("cannot start the network runtime: {e}")))?;
    rt.block_on(async {
        let channel = client::Dial::new(addr, deadline, tls)?
            .connect()
            .await
            .map_err(|e| err(error::root_cause(&e)))?;
        let reply = HealthClient::new(channel)
            .check(HealthCheckRequest {
                service: String::new(),
            })
            .await
            .map_err(|s| err(s.message().to_string()))?
            .into_inner();
        Ok(reply.status == ServingStatus::Serving as i32)
    })
}
