//! Cluster mode, in the paper's parallel scheme (section 5.2): workers fill
//! the density of a share of the strands and sweep a share of the map's
//! columns; a coordinator sums, gathers and draws. The only crate that
//! knows protobuf, tonic and tokio.

pub mod pb {
    //! Code generated from `proto/wisplight/v1/worker.proto`.
    #![allow(missing_debug_implementations, clippy::all)]
    tonic::include_proto!("wisplight.v1");

    /// The encoded descriptor set, for server reflection.
    pub const DESCRIPTOR: &[u8] = tonic::include_file_descriptor_set!("wisplight_descriptor");
}

pub mod remote;
pub mod wire;
pub mod worker;

pub use remote::{RemoteExecutor, Timing, Traffic};

use std::net::SocketAddr;

/// What went wrong in cluster mode, naming the worker.
#[derive(Debug, thiserror::Error)]
pub enum ClusterError {
    #[error("cannot listen on {0}: {1}")]
    Bind(SocketAddr, std::io::Error),
    #[error("{0}")]
    Setup(String),
    #[error("the worker server stopped: {0}")]
    Serve(String),
    #[error("cannot reach worker {addr}: {msg}")]
    Connect { addr: String, msg: String },
    #[error("worker {addr} refused: {msg}")]
    Version { addr: String, msg: String },
    #[error("worker {addr} failed the {stage} stage: {msg}")]
    Call {
        addr: String,
        stage: &'static str,
        msg: String,
    },
    #[error("worker {addr} did not finish the {stage} stage within {secs} s")]
    Deadline {
        addr: String,
        stage: &'static str,
        secs: f64,
    },
    #[error("worker {addr} sent a malformed reply: {msg}")]
    Malformed { addr: String, msg: String },
}

impl ClusterError {
    /// The worker an error is about, when it is about one.
    pub fn worker(&self) -> Option<&str> {
        match self {
            ClusterError::Connect { addr, .. }
            | ClusterError::Version { addr, .. }
            | ClusterError::Call { addr, .. }
            | ClusterError::Deadline { addr, .. }
            | ClusterError::Malformed { addr, .. } => Some(addr),
            _ => None,
        }
    }
}
