//! Density rounds with a column plan: this worker's columns summed and swept among the workers (reduce-scatter, then all-gather), and what the rounds leave for the Draw.

use super::STRIPES_IN_FLIGHT;
use super::inbox::{Gather, Inbox, SendFailed, send_within, stalled};
use super::memory::{Budget, Grant};
use super::proof::call_failed;
use super::session::{Exchanged, Session, on_pool};
use super::status::{cancelled, first_message, invalid, logged, refused, status};
use crate::error::WorkerErrorKind as Kind;
use crate::tls::Caller;
use crate::{WorkerService, pb, wire};
use engine::Share;
use prost::Message;
use shadow::{DensityMap, Fiber, LightFrame};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tonic::{Request, Response, Status, Streaming};

/// The calls carrying this worker's columns to each other worker of a
/// column plan: per worker (none for this one), a sender of the density
/// call and one of the swept columns' call; and the first failure of any.
pub(super) struct ExchangeSends {
    pub(super) density: Vec<Option<tokio::sync::mpsc::Sender<pb::ExchangeChunk>>>,
    pub(super) swept: Vec<Option<tokio::sync::mpsc::Sender<pb::ExchangeChunk>>>,
    pub(super) failed: Arc<Mutex<Option<String>>>,
    /// How long a send waits for a peer to take it.
    pub(super) wait: Duration,
    pub(super) handle: tokio::runtime::Handle,
}

impl WorkerService {
    /// Opens the Exchange calls of a Density round with column plan
    /// `plan`: two to each other worker, fed as the round goes.
    pub(super) fn exchange_calls(
        &self,
        session: &Session,
        plan: &wire::ColumnPlan,
    ) -> Result<ExchangeSends, Status> {
        let n = plan.workers();
        // Earlier rounds' columns go, but for those of the rounds just
        // before (another light's, whose swept columns may still be
        // gathered).
        session
            .exchange
            .begin((2 * plan.round).saturating_sub(4 * wire::MAX_LIGHTS as u64));
        let failed: Arc<Mutex<Option<String>>> = Arc::default();
        let mut sends = ExchangeSends {
            density: vec![None; n],
            swept: vec![None; n],
            failed: failed.clone(),
            wait: plan.wait,
            handle: tokio::runtime::Handle::try_current()
                .map_err(|e| status(Kind::Internal, format!("no runtime: {e}")))?,
        };
        for b in (0..n).filter(|&b| b != plan.own) {
            let (addr, sid) = &plan.peers[b];
            session.allows(b, addr)?;
            let client = self.peer(addr, sid, plan.tls_domain.as_deref(), plan.wait)?;
            for swept in [false, true] {
                let (tx, rx) = tokio::sync::mpsc::channel(STRIPES_IN_FLIGHT);
                let (failed, addr, mut client) = (failed.clone(), addr.clone(), client.clone());
                let check = self.peer_check(&addr, sid);
                tokio::spawn(async move {
                    // Nothing is sent to a peer that did not prove it
                    // belongs to the cluster.
                    let sent = async {
                        check.prove(&mut client).await?;
                        let stream = tokio_stream::wrappers::ReceiverStream::new(rx);
                        client.exchange(stream).await.map_err(call_failed)?;
                        Ok::<_, String>(())
                    }
                    .await;
                    if let Err(why) = sent
                        && let Ok(mut f) = failed.lock()
                    {
                        // One answer whatever the cause (see the Draw's).
                        tracing::warn!(worker = b, %addr, why, "a peer did not take this worker's columns");
                        f.get_or_insert(super::inbox::no_part(b));
                    }
                });
                if swept {
                    sends.swept[b] = Some(tx);
                } else {
                    sends.density[b] = Some(tx);
                }
            }
        }
        Ok(sends)
    }
}

/// One worker's part of a Density round with a column plan (see
/// [`wire::ColumnPlan`]).
pub(super) struct ExchangeRound {
    pub(super) version: u64,
    pub(super) frame: LightFrame,
    pub(super) plan: wire::ColumnPlan,
    pub(super) sends: ExchangeSends,
}

/// What is left of a round once the worker's columns are summed and
/// swept: the all-gather of the swept columns.
pub(super) struct SweptRound {
    pub(super) round: ExchangeRound,
    /// This worker's swept columns, as the Exchange chunks that carry them.
    pub(super) own: Vec<pb::ExchangeChunk>,
}

impl ExchangeRound {
    /// Deposits the share's strands, sends each other worker its columns,
    /// sums the others' density of this worker's columns, adds the head
    /// and sweeps them. The reply: the summed density of this worker's
    /// columns, the last chunk with the fill's counts and the bytes this
    /// worker sends the others; and the rest of the round.
    pub(super) fn sum(
        mut self,
        share: &mut Share,
        maps: &Mutex<Vec<DensityMap>>,
        fiber: &Fiber,
        inbox: &Inbox<Exchanged>,
        go: impl Fn() -> bool + Clone + Send + Sync,
    ) -> Result<(Vec<pb::ColumnChunk>, SweptRound), Status> {
        let (frame, plan) = (self.frame, &self.plan);
        let (n, own) = (plan.workers(), plan.own);
        let others: Vec<u32> = (0..n as u32).filter(|&b| b != own as u32).collect();
        let mine = plan.range(own);
        let failed = self.sends.failed.clone();
        let go_on = || {
            if !go() {
                return Err("the coordinator left the Density call".to_string());
            }
            failed
                .lock()
                .ok()
                .and_then(|f| f.clone())
                .map_or(Ok(()), Err)
        };
        let mut map = WorkerService::map_in(maps, frame);
        let stats = on_pool(|| share.deposit_while(self.version, &mut map, fiber, go.clone()))
            .map_err(refused)?
            .ok_or_else(|| cancelled("Density"))?;
        // Reduce-scatter: each other worker's columns to it.
        let mut density_sent = 0u64;
        for b in 0..n {
            let Some(to) = self.sends.density[b].take() else {
                continue;
            };
            for (i, c) in wire::column_chunks(&map, plan.range(b))
                .into_iter()
                .enumerate()
            {
                density_sent += self.sends.send(
                    b,
                    &to,
                    pb::ExchangeChunk {
                        round: plan.round,
                        from: own as u32,
                        map: (i == 0).then(|| wire::frame_to_pb(&frame)),
                        density: Some(c),
                        ..Default::default()
                    },
                )?;
            }
        }
        let got = inbox
            .gather(2 * plan.round, &others, plan.wait, go_on)
            .map_err(Gather::status)?;
        for (b, (item, _)) in others.iter().zip(got) {
            let Exchanged::Density(f, chunks) = item else {
                return Err(status(
                    Kind::Aborted,
                    format!("worker {b} sent swept columns for density"),
                ));
            };
            if f != frame {
                return Err(status(
                    Kind::Aborted,
                    format!("worker {b}'s density is of another map"),
                ));
            }
            for c in &chunks {
                let d = wire::decode_columns(&frame, c)
                    .map_err(|e| status(Kind::Aborted, format!("worker {b}'s density: {e}")))?;
                if !d.within(mine.clone()) {
                    return Err(status(
                        Kind::Aborted,
                        format!("worker {b}'s density reaches past this worker's columns {mine:?}"),
                    ));
                }
                wire::add_columns(&mut map, &d);
            }
        }
        let mut reply = wire::column_chunks(&map, mine.clone());
        // The head, then the sweep of this worker's columns.
        if let Some(h) = plan.head {
            share.deposit_head(&mut map, h);
        }
        let slab = on_pool(|| shadow::sweep_while(&map, mine.start as u32..mine.end as u32, go));
        WorkerService::give_back(maps, map);
        let slab = slab.ok_or_else(|| cancelled("Density"))?;
        let own_swept: Vec<pb::ExchangeChunk> = wire::swept_chunks(&frame, &slab)
            .into_iter()
            .map(|c| pb::ExchangeChunk {
                round: plan.round,
                from: own as u32,
                swept: true,
                columns: Some(c),
                ..Default::default()
            })
            .collect();
        // Each other worker gets them all.
        let swept_sent = (n as u64 - 1)
            * own_swept
                .iter()
                .map(|c| c.encoded_len() as u64)
                .sum::<u64>();
        if let Some(c) = reply.last_mut() {
            c.samples = stats.samples;
            c.out_of_map = stats.out_of_map;
            c.exchanged_density = density_sent;
            c.exchanged_swept = swept_sent;
        }
        Ok((
            reply,
            SweptRound {
                round: self,
                own: own_swept,
            },
        ))
    }
}

impl ExchangeSends {
    /// Sends `c` on `to`: its bytes, or the round's failure.
    pub(super) fn send(
        &self,
        b: usize,
        to: &tokio::sync::mpsc::Sender<pb::ExchangeChunk>,
        c: pb::ExchangeChunk,
    ) -> Result<u64, Status> {
        let bytes = c.encoded_len() as u64;
        send_within(&self.handle, to, c, self.wait).map_err(|f| {
            if f == SendFailed::Stalled {
                return stalled(b);
            }
            status(
                Kind::Aborted,
                self.failed
                    .lock()
                    .ok()
                    .and_then(|f| f.clone())
                    .unwrap_or_else(|| "a call to another worker ended".to_string()),
            )
        })?;
        Ok(bytes)
    }
}

impl SweptRound {
    /// Sends this worker's swept columns to every other worker, gathers
    /// theirs, and assembles the light's transmittance, in the budget.
    pub(super) fn finish(
        self,
        inbox: &Inbox<Exchanged>,
        memory: &Budget,
    ) -> Result<(shadow::Transmittance, Grant), String> {
        let SweptRound { mut round, own } = self;
        let plan = &round.plan;
        let n = plan.workers();
        let others: Vec<u32> = (0..n as u32).filter(|&b| b != plan.own as u32).collect();
        for b in 0..n {
            let Some(to) = round.sends.swept[b].take() else {
                continue;
            };
            for c in &own {
                round
                    .sends
                    .send(b, &to, c.clone())
                    .map_err(|s| s.message().to_string())?;
            }
        }
        let failed = round.sends.failed.clone();
        let go_on = || {
            failed
                .lock()
                .ok()
                .and_then(|f| f.clone())
                .map_or(Ok(()), Err)
        };
        let got = inbox
            .gather(2 * plan.round + 1, &others, plan.wait, go_on)
            .map_err(|e| e.to_string())?;
        let mut owners: Vec<Vec<pb::DrawChunk>> = vec![Vec::new(); n];
        owners[plan.own] = own.into_iter().filter_map(|c| c.columns).collect();
        let mut grants = Vec::with_capacity(n);
        for (&b, (item, grant)) in others.iter().zip(got) {
            let Exchanged::Swept(chunks) = item else {
                return Err(format!("worker {b} sent density for swept columns"));
            };
            owners[b as usize] = chunks;
            grants.push(grant);
        }
        let trans = wire::assemble_swept(round.frame, plan, &owners)
            .map_err(|e| format!("the swept columns: {e}"))?;
        drop(owners);
        drop(grants);
        // Kept until the Draw, in the budget.
        let mut kept = Grant::default();
        memory
            .take(
                &mut kept,
                trans.bytes() as u64,
                "the swept columns kept for the Draw",
            )
            .map_err(|s| s.message().to_string())?;
        Ok((trans, kept))
    }
}

impl WorkerService {
    pub(super) async fn exchange_call(
        &self,
        req: Request<Streaming<pb::ExchangeChunk>>,
    ) -> Result<Response<pb::ExchangeReply>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Peer)?;
            let memory = self.budget(&session);
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Exchange").await?;
            let (round, from, swept) = (first.round, first.from, first.swept);
            if from as usize >= wire::MAX_WORKERS || round >= u64::MAX / 2 {
                return Err(status(
                    Kind::Invalid,
                    format!(
                        "columns from worker {from} of round {round} (at most {} workers)",
                        wire::MAX_WORKERS
                    ),
                ));
            }
            let frame = if swept {
                None
            } else {
                Some(wire::frame_from_pb(first.map.as_ref()).map_err(invalid)?)
            };
            let mut grant = Grant::default();
            let (mut density, mut columns) = (Vec::new(), Vec::new());
            let mut add = |c: pb::ExchangeChunk| -> Result<(), Status> {
                match (swept, c.density, c.columns) {
                    (false, Some(d), None) => {
                        // The cells unpacked, and the chunk as it came.
                        let cells: u64 =
                            d.lo.iter()
                                .zip(&d.hi)
                                .map(|(&lo, &hi)| u64::from(hi.saturating_sub(lo)) + 1)
                                .sum();
                        let bytes = cells * 4 + d.encoded_len() as u64;
                        memory.take(&mut grant, bytes, "an Exchange call's density")?;
                        density.push(d);
                    }
                    (true, None, Some(col)) => {
                        let bytes =
                            wire::ColumnsReader::bytes_to_add(&col) + col.encoded_len() as u64;
                        memory.take(&mut grant, bytes, "an Exchange call's swept columns")?;
                        columns.push(col);
                    }
                    (_, None, None) => {}
                    _ => {
                        return Err(status(
                            Kind::Invalid,
                            "an Exchange chunk carries what its call does not (density in a call of swept columns, or the reverse, or both)",
                        ));
                    }
                }
                Ok(())
            };
            add(first)?;
            while let Some(c) = stream.message().await? {
                add(c)?;
            }
            let item = match frame {
                Some(f) => Exchanged::Density(f, density),
                None => Exchanged::Swept(columns),
            };
            session
                .exchange
                .deliver(2 * round + u64::from(swept), from, item, grant)?;
            Ok(Response::new(pb::ExchangeReply {}))
        };
        logged(peer, "Exchange", served.await)
    }
}
