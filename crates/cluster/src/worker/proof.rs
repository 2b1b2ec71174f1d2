//! The worker's side of the token proofs (see `crate::token`): the
//! challenges it gives, the Hello it checks and proves back to, the
//! proof it gives a fellow worker (Prove), and the proof it asks of a
//! fellow worker before it sends it anything.

use std::collections::{HashSet, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tonic::{Request, Response, Status};

use super::status::{poisoned, status};
use crate::client::SessionClient;
use crate::error::WorkerErrorKind as Kind;
use crate::tls::{Caller, request_may_call};
use crate::token::{self, MAX_NONCE_BYTES, NONCE_BYTES, Purpose, Token};
use crate::{WorkerService, pb};

/// The most challenges a worker remembers; the oldest goes first.
const MAX_CHALLENGES: usize = 1024;

/// How long a challenge is good for.
const CHALLENGE_LIFE: Duration = Duration::from_secs(30);

/// The most peers a worker remembers it has proved.
const MAX_PROVEN: usize = 256;

/// Challenges given and not yet answered, each good once.
#[derive(Debug, Default)]
pub(super) struct Challenges(Mutex<VecDeque<([u8; NONCE_BYTES], Instant)>>);

impl Challenges {
    /// A fresh challenge, remembered.
    fn give(&self) -> Result<[u8; NONCE_BYTES], Status> {
        let n = token::nonce().map_err(|e| {
            status(
                Kind::Internal,
                format!("no randomness for a challenge: {e}"),
            )
        })?;
        let mut c = self.0.lock().map_err(poisoned)?;
        c.retain(|(_, at)| at.elapsed() < CHALLENGE_LIFE);
        if c.len() >= MAX_CHALLENGES {
            c.pop_front();
        }
        c.push_back((n, Instant::now()));
        Ok(n)
    }

    /// Whether `n` was given within its life and not yet taken; taken now.
    fn take(&self, n: &[u8]) -> Result<bool, Status> {
        let mut c = self.0.lock().map_err(poisoned)?;
        c.retain(|(_, at)| at.elapsed() < CHALLENGE_LIFE);
        match c.iter().position(|(x, _)| x[..] == *n) {
            Some(i) => {
                c.remove(i);
                Ok(true)
            }
            None => Ok(false),
        }
    }
}

/// Fellow workers' sessions this worker has seen prove they belong to
/// the cluster, by address and session.
#[derive(Debug, Default)]
pub(super) struct Proven(Mutex<HashSet<(String, String)>>);

impl Proven {
    fn has(&self, key: &(String, String)) -> bool {
        self.0.lock().is_ok_and(|p| p.contains(key))
    }

    fn add(&self, key: (String, String)) {
        if let Ok(mut p) = self.0.lock() {
            if p.len() >= MAX_PROVEN {
                p.clear();
            }
            p.insert(key);
        }
    }
}

/// What asking a fellow worker for its proof takes, for a call's task:
/// its address, the session named there, this worker's token and the
/// peers already proved.
#[derive(Debug, Clone)]
pub(super) struct PeerCheck {
    addr: String,
    session: String,
    token: Option<Token>,
    proven: Arc<Proven>,
}

impl PeerCheck {
    /// Asks the peer to prove, over a fresh nonce, that it knows the
    /// token (without one: that it holds the session) before anything
    /// else is sent to it; remembered once proved. Its answer says nothing
    /// of why a peer failed (the caller answers one message whatever the
    /// cause).
    pub(super) async fn prove(&self, client: &mut SessionClient) -> Result<(), String> {
        let key = (self.addr.clone(), self.session.clone());
        if self.proven.has(&key) {
            return Ok(());
        }
        let nonce = token::nonce().map_err(|e| e.to_string())?;
        let reply = client
            .prove(pb::ProveRequest {
                nonce: nonce.to_vec(),
                session: self.session.clone(),
            })
            .await
            .map_err(|s| format!("no proof: {}", s.message()))?
            .into_inner();
        let session = self.session.as_bytes();
        let secret = self.token.as_ref().map_or(session, Token::key);
        if !token::proves(secret, Purpose::Peer, &[&nonce, session], &reply.proof) {
            return Err("its proof does not hold: it is not a worker of this cluster".into());
        }
        self.proven.add(key);
        Ok(())
    }
}

/// A peer's call that failed, in words, for this worker's log.
pub(super) fn call_failed(s: Status) -> String {
    format!("{:?}: {}", s.code(), s.message())
}

impl WorkerService {
    /// The check of the peer at `addr`, naming `session` there.
    pub(super) fn peer_check(&self, addr: &str, session: &str) -> PeerCheck {
        PeerCheck {
            addr: addr.to_string(),
            session: session.to_string(),
            token: self.token.clone(),
            proven: self.proven.clone(),
        }
    }

    pub(super) async fn challenge_call(
        &self,
        req: Request<pb::ChallengeRequest>,
    ) -> Result<Response<pb::ChallengeReply>, Status> {
        request_may_call(&req, Caller::Coordinator)?;
        let nonce = self.challenges.give()?.to_vec();
        Ok(Response::new(pb::ChallengeReply { nonce }))
    }

    /// Whether `r` may open a session: with a token, it answers one of
    /// this worker's challenges with the token's proof.
    pub(super) fn check_hello(&self, r: &pb::HelloRequest) -> Result<(), Status> {
        let Some(token) = &self.token else {
            return Ok(());
        };
        if r.proof.is_empty() {
            return Err(Status::unauthenticated(
                "this worker requires the cluster's token: give the coordinator the same \
                 --token (or WISPLIGHT_TOKEN) as its workers",
            ));
        }
        if r.client_nonce.len() != NONCE_BYTES || !self.challenges.take(&r.challenge)? {
            return Err(Status::unauthenticated(
                "the Hello answers no challenge this worker gave in the last 30 s (each is \
                 good once)",
            ));
        }
        let parts: [&[u8]; 2] = [&r.challenge, &r.client_nonce];
        if !token::proves(token.key(), Purpose::Hello, &parts, &r.proof) {
            return Err(Status::unauthenticated(
                "this worker's cluster token is another (--token or WISPLIGHT_TOKEN)",
            ));
        }
        Ok(())
    }

    /// The worker's proof back to a Hello that opened `session`: empty
    /// without a token.
    pub(super) fn hello_proof(&self, r: &pb::HelloRequest, session: &str) -> Vec<u8> {
        match &self.token {
            Some(t) => token::prove(
                t.key(),
                Purpose::Worker,
                &[&r.client_nonce, session.as_bytes()],
            ),
            None => Vec::new(),
        }
    }

    pub(super) async fn prove_call(
        &self,
        req: Request<pb::ProveRequest>,
    ) -> Result<Response<pb::ProveReply>, Status> {
        request_may_call(&req, Caller::Peer)?;
        let r = req.into_inner();
        if !(NONCE_BYTES..=MAX_NONCE_BYTES).contains(&r.nonce.len()) {
            return Err(status(
                Kind::Invalid,
                format!(
                    "a nonce of {} bytes: {NONCE_BYTES} to {MAX_NONCE_BYTES}",
                    r.nonce.len()
                ),
            ));
        }
        let proof = match &self.token {
            Some(t) => token::prove(t.key(), Purpose::Peer, &[&r.nonce, r.session.as_bytes()]),
            None => {
                // Without a token, the session's id is the secret: proved
                // for an open session only.
                let open = self
                    .sessions
                    .lock()
                    .map_err(poisoned)?
                    .contains_key(&r.session);
                if !open {
                    return Err(status(Kind::Precondition, "no such session here"));
                }
                let id = r.session.as_bytes();
                token::prove(id, Purpose::Peer, &[&r.nonce, id])
            }
        };
        Ok(Response::new(pb::ProveReply { proof }))
    }
}
