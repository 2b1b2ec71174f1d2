//! A coordinator's session on a worker: its state, its memory, its pool of maps, and finding it from a call.

use super::inbox::Inbox;
use super::memory::{Budget, Grant, Memory};
use super::status::{
    expired, logged, named_session, no_share, not_open, poisoned, session_id, status,
};
use super::swept::SweptStore;
use crate::error::WorkerErrorKind as Kind;
use crate::tls::{self, Caller, request_may_call};
use crate::{SessionLimits, WorkerService, pb, wire};
use engine::{SceneSource, Share};
use shadow::{DensityMap, Fiber, LightFrame};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tonic::{Request, Response, Status};

/// The most cells a map kept between calls (a session's pool) may have:
/// 2^22 (16 MiB of quanta); larger maps are dropped after their call.
pub(super) const POOLED_CELLS: u64 = 1 << 22;

/// The most maps a session keeps between calls.
pub(super) const POOLED_MAPS: usize = 4;

/// The most deposit scratch points a pooled map keeps (5 MiB).
pub(super) const POOLED_SCRATCH_POINTS: usize = 1 << 18;

/// What one coordinator's calls share: the fiber it said Hello with, its
/// share of the scene's hair, and density maps kept between calls (their
/// memory, not their content).
#[derive(Debug)]
pub(super) struct Session {
    pub(super) fiber: Fiber,
    pub(super) maps: Arc<Mutex<Vec<DensityMap>>>,
    pub(super) held: Arc<Mutex<Option<Held>>>,
    pub(super) last_used: Mutex<Instant>,
    /// The session's own memory budget.
    pub(super) memory: Memory,
    /// Other workers' stripes of this worker's band, by Draw round.
    pub(super) inbox: Arc<Inbox<Vec<engine::Stripe>>>,
    /// Other workers' columns, by Density round (twice the round for
    /// density, and one more for swept columns).
    pub(super) exchange: Arc<Inbox<Exchanged>>,
    /// What the last Density rounds with a column plan swept.
    pub(super) swept: Arc<SweptStore>,
    /// The workers this session's last Assign named: the only peers its
    /// plans may make this worker call.
    pub(super) peers: Mutex<Vec<String>>,
    /// The picture size of the scene its last Assign made a share of: the
    /// only size its Draws may ask for (none before an Assign).
    pub(super) picture: Mutex<Option<(u32, u32)>>,
    /// The client address the Hello came from.
    pub(super) origin: Option<SocketAddr>,
}

impl Session {
    /// Refuses a peer the session's Assign did not name (not dialled, and
    /// the error says nothing of it beyond its index).
    pub(super) fn allows(&self, index: usize, addr: &str) -> Result<(), Status> {
        named_peer(&self.peers.lock().map_err(poisoned)?, index, addr)
    }
}

/// Whether `addr`, peer `index` of a plan, is one of `peers`.
fn named_peer(peers: &[String], index: usize, addr: &str) -> Result<(), Status> {
    if peers.iter().any(|p| p == addr) {
        Ok(())
    } else {
        Err(status(
            Kind::Invalid,
            format!(
                "peer {index} of the plan is not one of the workers this session's Assign named"
            ),
        ))
    }
}

/// What another worker sent in an Exchange call: its density of this
/// worker's columns, or its own swept columns.
#[derive(Debug)]
pub(super) enum Exchanged {
    Density(LightFrame, Vec<pb::ColumnChunk>),
    Swept(Vec<pb::DrawChunk>),
}

/// A share of a scene's hair and the scene it came from (a new Assign of
/// the same scene and groups keeps it).
#[derive(Debug)]
pub(super) struct Held {
    pub(super) source: SceneSource,
    pub(super) share: Share,
    /// The memory budget the scene, its files, the states and the share
    /// take, given back when the share is dropped.
    pub(super) _memory: Grant,
}

/// How many ended sessions a worker remembers the reason of.
pub(super) const EXPIRED_KEPT: usize = 64;

impl WorkerService {
    /// A worker holding at most `limits` sessions.
    pub fn new(limits: SessionLimits) -> WorkerService {
        WorkerService {
            sessions: Mutex::default(),
            memory: Memory::new(limits.max_memory, "this worker's", "--max-memory-mib"),
            limits,
            peer_tls: None,
            token: None,
            challenges: Default::default(),
            proven: Default::default(),
            connections: Arc::default(),
            peers: Mutex::default(),
            expired: Mutex::default(),
        }
    }

    /// A client of the worker at `addr`, naming session `session` there:
    /// one connection per worker, kept.
    pub(super) fn peer(
        &self,
        addr: &str,
        session: &str,
        domain: Option<&str>,
        timeout: Duration,
    ) -> Result<crate::client::SessionClient, Status> {
        let header = crate::client::SessionHeader::new(session)
            .ok_or_else(|| status(Kind::Invalid, "a band's session is not a header value"))?;
        let key = (addr.to_string(), domain.map(str::to_string));
        let mut peers = self.peers.lock().map_err(poisoned)?;
        let channel = match peers.get(&key) {
            Some(c) => c.clone(),
            None => {
                let tls = match (&self.peer_tls, domain) {
                    (Some(t), Some(d)) => Some(t.clone().with_domain(d)),
                    (t, _) => t.clone(),
                };
                let c = crate::client::Dial::new(addr, timeout, tls.as_ref())
                    .map_err(|e| status(Kind::Invalid, e.to_string()))?
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
    pub(super) fn budget(&self, session: &Session) -> Budget {
        Budget {
            session: session.memory.clone(),
            worker: self.memory.clone(),
        }
    }

    /// The session a call names in its metadata, marked used now, once
    /// the client may make the call (with TLS, only a coordinator's
    /// certificate may make a coordinator's call).
    pub(super) fn session<T>(
        &self,
        req: &Request<T>,
        caller: Caller,
    ) -> Result<Arc<Session>, Status> {
        request_may_call(req, caller)?;
        let id = named_session(req.metadata())?;
        let sessions = self.sessions.lock().map_err(poisoned)?;
        let s = sessions.get(id).cloned().ok_or_else(|| self.not_open(id))?;
        *s.last_used.lock().map_err(poisoned)? = Instant::now();
        Ok(s)
    }

    /// The answer to a call naming session `id`, which is not open: why,
    /// when this worker ended it for going unused.
    pub(super) fn not_open(&self, id: &str) -> Status {
        let why = self
            .expired
            .lock()
            .ok()
            .and_then(|e| e.iter().find(|(x, _)| x == id).map(|(_, why)| why.clone()));
        match why {
            Some(why) => expired(id, &why),
            None => not_open(id),
        }
    }

    /// Ends the sessions unused for longer than the idle limit; how many.
    pub fn end_idle(&self) -> usize {
        let Ok(mut sessions) = self.sessions.lock() else {
            return 0;
        };
        let idle = self.limits.idle;
        let orphaned = self.limits.orphaned.min(idle);
        let before = sessions.len();
        let mut ended = Vec::new();
        sessions.retain(|id, s| {
            let unused = match s.last_used.lock() {
                Ok(t) => t.elapsed(),
                Err(_) => return false,
            };
            // Its coordinator's connection closed and nobody came back.
            let gone = s.origin.is_some_and(|a| !self.connections.is_open(a));
            let why = if unused >= idle {
                format!("unused for more than {idle:?} (this worker's --session-idle)")
            } else if gone && unused >= orphaned {
                format!("its coordinator's connection closed and it went unused for {orphaned:?}")
            } else {
                return true;
            };
            ended.push((id.clone(), why));
            false
        });
        if let Ok(mut e) = self.expired.lock() {
            for x in ended {
                if e.len() == EXPIRED_KEPT {
                    e.pop_front();
                }
                e.push_back(x);
            }
        }
        let ended = before - sessions.len();
        if ended > 0 {
            tracing::info!(ended, left = sessions.len(), "idle sessions ended");
        }
        ended
    }

    /// A map in `frame`, empty, from the pool when one is free.
    pub(super) fn map_in(maps: &Mutex<Vec<DensityMap>>, frame: LightFrame) -> DensityMap {
        let pooled = maps.lock().ok().and_then(|mut m| m.pop());
        match pooled {
            Some(mut m) => {
                m.set_frame(frame);
                m
            }
            None => DensityMap::new(frame),
        }
    }

    pub(super) fn give_back(maps: &Mutex<Vec<DensityMap>>, mut map: DensityMap) {
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
pub(super) fn on_pool<T: Send>(f: impl FnOnce() -> T + Send) -> T {
    let mut out = None;
    rayon::scope(|_| out = Some(f()));
    out.expect("the scope ran its closure")
}

/// Runs `f` on the held share off the async threads.
pub(super) async fn with_share<T: Send + 'static>(
    held: &Arc<Mutex<Option<Held>>>,
    f: impl FnOnce(&mut Share) -> Result<T, Status> + Send + 'static,
) -> Result<T, Status> {
    let held = held.clone();
    tokio::task::spawn_blocking(move || {
        let mut slot = held.lock().map_err(poisoned)?;
        let h = slot.as_mut().ok_or_else(no_share)?;
        on_pool(|| f(&mut h.share))
    })
    .await
    .map_err(|e| status(Kind::Internal, format!("worker task failed: {e}")))?
}

impl WorkerService {
    pub(super) async fn hello_call(
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
            self.check_hello(&r)?;
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
                proof: self.hello_proof(&r, &id),
                session: id,
            }))
        };
        logged(peer, "Hello", served.await)
    }

    pub(super) async fn end_call(
        &self,
        req: Request<pb::EndRequest>,
    ) -> Result<Response<pb::EndReply>, Status> {
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plan_may_name_only_the_peers_the_assign_named_and_the_error_does_not_echo_them() {
        let peers = vec!["10.0.0.1:7000".to_string(), "10.0.0.2:7000".to_string()];
        assert!(named_peer(&peers, 1, "10.0.0.2:7000").is_ok());
        for stray in ["10.0.0.3:7000", "10.0.0.2:22", "", "10.0.0.1:7000 "] {
            let e = named_peer(&peers, 1, stray).unwrap_err();
            assert_eq!(e.code(), tonic::Code::InvalidArgument);
            assert!(
                !e.message().contains(stray) || stray.is_empty(),
                "{}",
                e.message()
            );
        }
        // Before any Assign, nobody.
        assert!(named_peer(&[], 0, "10.0.0.1:7000").is_err());
    }
}
