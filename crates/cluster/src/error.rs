//! The cluster's errors.

use std::net::SocketAddr;

/// A failure of the cluster: of a worker, of the network, or of the setup.
#[derive(Debug, Clone, thiserror::Error)]
pub enum ClusterError {
    /// An address the worker cannot listen on.
    #[error("cannot listen on {0}: {1}{hint}", hint = busy_hint(.1))]
    Bind(SocketAddr, std::sync::Arc<std::io::Error>),
    /// The runtime or a server cannot be set up.
    #[error("{0}")]
    Setup(String),
    /// Credentials that cannot be read or used.
    #[error("TLS: {0}")]
    Tls(String),
    /// The worker's server stopped with an error.
    #[error("the worker server stopped: {0}")]
    Serve(String),
    /// A worker that cannot be reached or is not a wisplight worker.
    #[error("cannot reach worker {addr}: {msg}")]
    Connect {
        /// The worker.
        addr: String,
        /// Why.
        msg: String,
    },
    /// A worker that refused this coordinator (another protocol version, the fiber, its limits).
    #[error("worker {addr} refused: {msg}")]
    Refused {
        /// The worker.
        addr: String,
        /// Its reason.
        msg: String,
    },
    /// A worker that refused or failed a stage's call.
    #[error("worker {addr} failed the {stage} stage: {error}")]
    Call {
        /// The worker.
        addr: String,
        /// The stage.
        stage: &'static str,
        /// Its answer, by kind.
        error: WorkerError,
    },
    /// A call past its deadline.
    #[error("worker {addr} did not finish the {stage} stage within {secs} s")]
    Deadline {
        /// The worker.
        addr: String,
        /// The stage.
        stage: &'static str,
        /// The deadline, seconds.
        secs: f64,
    },
    /// A reply that does not check.
    #[error("worker {addr} sent a malformed reply: {msg}")]
    Malformed {
        /// The worker.
        addr: String,
        /// What is wrong with it.
        msg: String,
    },
    /// A worker ended this coordinator's session for going unused longer
    /// than it allows: the coordinator was stopped or stalled, not the
    /// worker.
    #[error(
        "worker {addr} ended this coordinator's session ({msg}): this coordinator went \
         unused longer than the workers allow (worker --session-idle); render again"
    )]
    Expired {
        /// The worker.
        addr: String,
        /// Its reason.
        msg: String,
    },
    /// A round of compositing on the workers that failed as a whole.
    #[error("compositing on the workers failed: {0}")]
    Composite(String),
    /// A round of summing and sweeping on the workers that failed as a whole.
    #[error("summing and sweeping on the workers failed: {0}")]
    Exchange(String),
}

impl ClusterError {
    /// The worker an error is about, when it is about one.
    pub fn worker(&self) -> Option<&str> {
        match self {
            ClusterError::Connect { addr, .. }
            | ClusterError::Refused { addr, .. }
            | ClusterError::Call { addr, .. }
            | ClusterError::Deadline { addr, .. }
            | ClusterError::Malformed { addr, .. }
            | ClusterError::Expired { addr, .. } => Some(addr),
            _ => None,
        }
    }
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

/// What kind of failure a worker's answer is: the one mapping between a
/// worker's errors and gRPC status codes. The worker answers with
/// [`WorkerError::code`]; the coordinator reads an answer back with
/// [`WorkerError::from`] a status.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WorkerErrorKind {
    /// The request is malformed or out of range: `INVALID_ARGUMENT`.
    Invalid,
    /// The worker lacks what the call needs (no open session, another
    /// protocol, a hair version it does not hold): `FAILED_PRECONDITION`.
    Precondition,
    /// The call gave way: another session took the worker, or the call
    /// gave up for another worker's failure: `ABORTED`.
    Aborted,
    /// Over the worker's memory budget or limits: `RESOURCE_EXHAUSTED`.
    Exhausted,
    /// The caller went away: `CANCELLED`.
    Cancelled,
    /// The worker cannot serve now (stopping, a peer unreachable):
    /// `UNAVAILABLE`.
    Unavailable,
    /// A fault inside the worker: `INTERNAL`.
    Internal,
    /// Any other status, from something that is not a wisplight worker
    /// (`UNIMPLEMENTED` from another server) or from the transport.
    Other(tonic::Code),
}

impl WorkerErrorKind {
    /// Every kind a worker answers with.
    pub const ALL: [WorkerErrorKind; 7] = [
        WorkerErrorKind::Invalid,
        WorkerErrorKind::Precondition,
        WorkerErrorKind::Aborted,
        WorkerErrorKind::Exhausted,
        WorkerErrorKind::Cancelled,
        WorkerErrorKind::Unavailable,
        WorkerErrorKind::Internal,
    ];

    /// The status code of this kind.
    pub fn code(self) -> tonic::Code {
        use tonic::Code as C;
        match self {
            WorkerErrorKind::Invalid => C::InvalidArgument,
            WorkerErrorKind::Precondition => C::FailedPrecondition,
            WorkerErrorKind::Aborted => C::Aborted,
            WorkerErrorKind::Exhausted => C::ResourceExhausted,
            WorkerErrorKind::Cancelled => C::Cancelled,
            WorkerErrorKind::Unavailable => C::Unavailable,
            WorkerErrorKind::Internal => C::Internal,
            WorkerErrorKind::Other(c) => c,
        }
    }

    /// The kind of a status code.
    pub fn of(code: tonic::Code) -> WorkerErrorKind {
        Self::ALL
            .into_iter()
            .find(|k| k.code() == code)
            .unwrap_or(WorkerErrorKind::Other(code))
    }
}

/// A worker's refusal or failure of a call: its kind and the worker's
/// reason.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{:?}: {message}", self.kind.code())]
pub struct WorkerError {
    /// What kind of failure, by status code.
    pub kind: WorkerErrorKind,
    /// The worker's reason.
    pub message: String,
    /// The peer the worker waited for in vain (its index in the call's
    /// plan), when that is why the call failed: the worker at fault is
    /// that one (the `wisplight-waited-for` metadata).
    pub waited_for: Option<u32>,
    /// The call named a session the worker ended for going unused (the
    /// `wisplight-session-expired` metadata): the coordinator, not the
    /// worker, stopped.
    pub expired: bool,
}

/// The metadata key of [`WorkerError::waited_for`].
const WAITED_FOR_KEY: &str = "wisplight-waited-for";
/// The metadata key of [`WorkerError::expired`].
const EXPIRED_KEY: &str = "wisplight-session-expired";

impl WorkerError {
    /// A failure of `kind` for `message`.
    pub fn new(kind: WorkerErrorKind, message: impl Into<String>) -> WorkerError {
        WorkerError {
            kind,
            message: message.into(),
            waited_for: None,
            expired: false,
        }
    }

    /// The status code the worker answers with.
    pub fn code(&self) -> tonic::Code {
        self.kind.code()
    }
}

impl From<WorkerError> for tonic::Status {
    fn from(e: WorkerError) -> tonic::Status {
        let mut s = tonic::Status::new(e.kind.code(), e.message);
        if let Some(b) = e.waited_for {
            s.metadata_mut()
                .insert(WAITED_FOR_KEY, b.to_string().parse().expect("digits"));
        }
        if e.expired {
            s.metadata_mut()
                .insert(EXPIRED_KEY, "1".parse().expect("a digit"));
        }
        s
    }
}

impl From<tonic::Status> for WorkerError {
    fn from(s: tonic::Status) -> WorkerError {
        let message = if s.message().is_empty() {
            s.code().description().to_string()
        } else {
            s.message().to_string()
        };
        let mut e = WorkerError::new(WorkerErrorKind::of(s.code()), message);
        e.waited_for = s
            .metadata()
            .get(WAITED_FOR_KEY)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.parse().ok());
        e.expired = s.metadata().get(EXPIRED_KEY).is_some();
        e
    }
}

/// What to do when the address to listen on is taken.
fn busy_hint(error: &std::io::Error) -> &'static str {
    if error.kind() == std::io::ErrorKind::AddrInUse {
        " (another program holds this port: give --listen 127.0.0.1:0 for a free one, or \
         another port)"
    } else {
        ""
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_goes_to_its_code_and_back() {
        let mut codes = std::collections::HashSet::new();
        for kind in WorkerErrorKind::ALL {
            let sent = tonic::Status::from(WorkerError::new(kind, "why"));
            assert!(codes.insert(sent.code()), "{kind:?} shares a code");
            assert_eq!(WorkerError::from(sent), WorkerError::new(kind, "why"));
        }
        // The codes a worker answers with, by name.
        assert_eq!(
            tonic::Status::from(WorkerError::new(WorkerErrorKind::Invalid, "x")).code(),
            tonic::Code::InvalidArgument
        );
        assert_eq!(
            tonic::Status::from(WorkerError::new(WorkerErrorKind::Precondition, "x")).code(),
            tonic::Code::FailedPrecondition
        );
        assert_eq!(
            tonic::Status::from(WorkerError::new(WorkerErrorKind::Exhausted, "x")).code(),
            tonic::Code::ResourceExhausted
        );
        assert_eq!(
            tonic::Status::from(WorkerError::new(WorkerErrorKind::Aborted, "x")).code(),
            tonic::Code::Aborted
        );
    }

    #[test]
    fn every_code_reads_as_a_kind_that_answers_with_it() {
        for c in 0..=16 {
            let code = tonic::Code::from_i32(c);
            let e = WorkerError::from(tonic::Status::new(code, ""));
            assert_eq!(e.code(), code);
            // An empty reason reads as the code's description.
            assert_eq!(e.message, code.description());
        }
        assert_eq!(
            WorkerErrorKind::of(tonic::Code::Unimplemented),
            WorkerErrorKind::Other(tonic::Code::Unimplemented)
        );
    }
}
