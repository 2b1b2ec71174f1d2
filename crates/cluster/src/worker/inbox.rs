//! What other workers send a session for its rounds, until the round's call gathers it.

use super::memory::Grant;
use super::status::{poisoned, status};
use crate::WorkerError;
use crate::error::WorkerErrorKind as Kind;
use std::sync::Mutex;
use std::time::{Duration, Instant};
use tonic::Status;

/// The most stripes a session's inbox holds at once (each a whole
/// Composite call, counted against the memory budget).
pub(super) const INBOX_LAYERS: usize = 64;

/// Bytes a received stripe pixel costs: its index and its sums.
pub(super) const STRIPE_PIXEL_BYTES: u64 = 4 + std::mem::size_of::<raster::Sums>() as u64;

/// What other workers sent this worker for one of its rounds (their
/// stripes of its band, Composite calls; their columns, Exchange calls),
/// until the call of that round gathers them.
#[derive(Debug)]
pub(super) struct Inbox<T> {
    pub(super) state: Mutex<InboxState<T>>,
    pub(super) ready: std::sync::Condvar,
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
pub(super) struct InboxState<T> {
    /// The latest round begun: items of earlier rounds are dropped.
    pub(super) round: u64,
    /// Per delivered call: its round, its sender, what it carried and
    /// that memory.
    pub(super) items: Vec<(u64, u32, T, Grant)>,
}

impl<T> Inbox<T> {
    /// A round begins: earlier rounds' items go.
    pub(super) fn begin(&self, round: u64) {
        if let Ok(mut st) = self.state.lock() {
            st.round = st.round.max(round);
            let r = st.round;
            st.items.retain(|l| l.0 >= r);
        }
    }

    /// Keeps a sender's item of `round` (stale ones are dropped).
    pub(super) fn deliver(
        &self,
        round: u64,
        from: u32,
        item: T,
        grant: Grant,
    ) -> Result<(), Status> {
        let mut st = self.state.lock().map_err(poisoned)?;
        if round < st.round {
            return Ok(());
        }
        if st.items.iter().any(|l| l.0 == round && l.1 == from) {
            return Err(status(
                Kind::Invalid,
                format!("worker {from}'s call of round {round} comes twice"),
            ));
        }
        if st.items.len() >= INBOX_LAYERS {
            return Err(status(
                Kind::Exhausted,
                format!("{INBOX_LAYERS} calls of other workers already wait here"),
            ));
        }
        st.items.push((round, from, item, grant));
        self.ready.notify_all();
        Ok(())
    }

    /// The items of `round` from every worker in `from`, in that order,
    /// with their memory, once all came; an error naming the workers
    /// missing after `wait`, or as soon as `go()` says stop.
    pub(super) fn gather(
        &self,
        round: u64,
        from: &[u32],
        wait: Duration,
        go: impl Fn() -> Result<(), String>,
    ) -> Result<Vec<(T, Grant)>, Gather> {
        let fail = |m: String| Gather {
            message: m,
            missing: None,
        };
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
                return Err(Gather {
                    message: no_part(missing[0] as usize),
                    missing: missing.first().copied(),
                });
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

/// Why a [`Inbox::gather`] gave up: the message, and the first worker of
/// the round nothing came from when that is why.
#[derive(Debug)]
pub(super) struct Gather {
    pub(super) message: String,
    pub(super) missing: Option<u32>,
}

impl Gather {
    /// The call's status: ABORTED, naming the peer waited for in vain
    /// (`wisplight-waited-for`), so that the coordinator drops that one.
    pub(super) fn status(self) -> Status {
        let mut e = WorkerError::new(Kind::Aborted, self.message);
        e.waited_for = self.missing;
        e.into()
    }
}

impl std::fmt::Display for Gather {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

/// Why a send to another worker's call failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum SendFailed {
    /// The call ended (the peer refused or went away).
    Ended,
    /// No room within the wait: the peer stopped reading.
    Stalled,
}

/// Sends `c` on `to` from a thread outside the async runtime (`handle`'s),
/// waiting at most `wait` for room: a peer that stops reading fills the
/// call's window and the channel, and is then named, not waited on
/// forever.
pub(super) fn send_within<T>(
    handle: &tokio::runtime::Handle,
    to: &tokio::sync::mpsc::Sender<T>,
    c: T,
    wait: Duration,
) -> Result<(), SendFailed> {
    let c = match to.try_send(c) {
        Ok(()) => return Ok(()),
        Err(tokio::sync::mpsc::error::TrySendError::Closed(_)) => return Err(SendFailed::Ended),
        Err(tokio::sync::mpsc::error::TrySendError::Full(c)) => c,
    };
    handle.block_on(async {
        match tokio::time::timeout(wait, to.send(c)).await {
            Ok(Ok(())) => Ok(()),
            Ok(Err(_)) => Err(SendFailed::Ended),
            Err(_) => Err(SendFailed::Stalled),
        }
    })
}

/// Why a round failed for peer `b`, whatever happened to it (it refused
/// the connection, stayed silent, took nothing, or is not a worker at
/// all): one answer, so that the caller learns nothing more of the
/// address it named. What happened is in this worker's log.
pub(super) fn no_part(b: usize) -> String {
    format!("worker {b} of the round took no part in it")
}

/// The status of a call that gave up on peer `b`, which stalled.
pub(super) fn stalled(b: usize) -> Status {
    Gather {
        message: no_part(b),
        missing: Some(b as u32),
    }
    .status()
}
