//! Status values, session names and the small helpers every call uses.

use super::Chunks;
use crate::client::SESSION_KEY;
use crate::error::WorkerErrorKind as Kind;
use crate::{WorkerError, wire};
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use tonic::{Status, Streaming};

/// A status of `kind` with the worker's `reason`, through the one mapping
/// of worker errors to status codes ([`WorkerError`]).
pub(super) fn status(kind: Kind, reason: impl Into<String>) -> Status {
    WorkerError::new(kind, reason).into()
}

pub(super) fn invalid(e: wire::Malformed) -> Status {
    status(Kind::Invalid, e.to_string())
}

/// A call that needs the session's share before any Assign made one.
pub(super) fn no_share() -> Status {
    status(
        Kind::Precondition,
        "no share of the hair here: call Assign first",
    )
}

/// An engine error of a call about the share (a hair version it does not
/// hold, say): the coordinator asked for something this worker lacks.
pub(super) fn refused(e: engine::EngineError) -> Status {
    status(Kind::Precondition, e.to_string())
}

pub(super) fn stream_of<T: Send + 'static>(items: Vec<T>) -> Chunks<T> {
    Box::pin(tokio_stream::iter(items.into_iter().map(Ok)))
}

/// A new session id: 128 random bits, in hex (unguessable: only the
/// coordinator that opened a session can name it).
pub(super) fn session_id() -> Result<String, Status> {
    let mut b = [0u8; 16];
    getrandom::fill(&mut b).map_err(|e| {
        status(
            Kind::Internal,
            format!("no randomness for a session id: {e}"),
        )
    })?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// Sets its flag when dropped: a call's work, running off the async
/// threads, learns that the call is gone.
pub(super) struct StopOnDrop(Arc<AtomicBool>);

impl Drop for StopOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// A call's stop switch, kept by the call's future, and the question its
/// work asks between runs: go on? (No, once the call is dropped.)
pub(super) fn stop_switch() -> (
    StopOnDrop,
    impl Fn() -> bool + Send + Sync + Clone + 'static,
) {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    (StopOnDrop(stop), move || !flag.load(Ordering::Relaxed))
}

/// What a call whose caller has gone answers (nobody reads it).
pub(super) fn cancelled(call: &str) -> Status {
    status(Kind::Cancelled, format!("the {call} was cancelled"))
}

/// Logs a refused call at the default level, with its peer and the
/// reason, and passes the result on.
pub(super) fn logged<T>(
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
pub(super) fn named_session(meta: &tonic::metadata::MetadataMap) -> Result<&str, Status> {
    let id = meta.get(SESSION_KEY).ok_or_else(|| {
        status(
            Kind::Precondition,
            "the call names no session: call Hello first and send its session id",
        )
    })?;
    Ok(id.to_str().unwrap_or_default())
}

pub(super) fn not_open(id: &str) -> Status {
    status(
        Kind::Precondition,
        format!("session {id:.8}... is not open on this worker (ended, or never opened)"),
    )
}

/// A call naming a session this worker ended for going unused: said so,
/// with why, and marked ([`WorkerError::expired`]) for its coordinator.
pub(super) fn expired(id: &str, why: &str) -> Status {
    let mut e = WorkerError::new(
        Kind::Precondition,
        format!("session {id:.8}... expired on this worker: {why}"),
    );
    e.expired = true;
    e.into()
}

/// The first message of a client stream; a stream of none is refused.
pub(super) async fn first_message<T>(s: &mut Streaming<T>, call: &str) -> Result<T, Status> {
    s.message()
        .await?
        .ok_or_else(|| status(Kind::Invalid, format!("an empty {call} call")))
}

pub(super) fn poisoned<T>(_: T) -> Status {
    status(Kind::Internal, "worker state poisoned")
}
