//! The Density call: a share's density filled into a map, summed and swept
//! among the workers when the call carries a column plan.

use super::exchange::ExchangeRound;
use super::memory::{Grant, POINT_BYTES, STRAND_BYTES};
use super::session::with_share;
use super::share::density_reply;
use super::status::{
    cancelled, first_message, invalid, logged, no_share, poisoned, refused, status, stop_switch,
    stream_of,
};
use super::{Chunks, STRIPES_IN_FLIGHT};
use crate::error::WorkerErrorKind as Kind;
use crate::tls::Caller;
use crate::{WorkerService, pb, wire};
use strands::Hair;
use tonic::{Request, Response, Status, Streaming};

impl WorkerService {
    pub(super) async fn density_call(
        &self,
        req: Request<Streaming<pb::DensityChunk>>,
    ) -> Result<Response<Chunks<pb::ColumnChunk>>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Coordinator)?;
            let fiber = session.fiber;
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Density").await?;
            let frame = wire::frame_from_pb(first.map.as_ref()).map_err(invalid)?;
            let (frame_id, light) = (first.frame_id, first.light);
            let mut hair = Hair::new();
            // The strands' memory, held until the call ends.
            let mut received = Grant::default();
            let memory = self.budget(&session);
            let mut add = |c: &pb::DensityChunk| -> Result<(), Status> {
                let bytes = c.points.len() as u64 / 3 * POINT_BYTES
                    + c.strand_lengths.len() as u64 * STRAND_BYTES;
                memory.take(&mut received, bytes, "the Density call's strands")?;
                wire::add_strands(&mut hair, c).map_err(invalid)
            };
            add(&first)?;
            while let Some(c) = stream.message().await? {
                add(&c)?;
            }
            let maps = session.maps.clone();
            // Held until the map is back in the pool or dropped.
            let budget = (memory.map(&frame).await?, received);
            // The deposit stops between runs of strands once the call is gone.
            let (_stop_on_drop, go) = stop_switch();
            let plan = first
                .columns
                .as_ref()
                .map(|p| wire::ColumnPlan::from_pb(p, frame.columns()))
                .transpose()
                .map_err(invalid)?;
            let chunks = if let Some(plan) = plan {
                if !first.posed || hair.strand_count() > 0 {
                    return Err(status(
                        Kind::Invalid,
                        "a Density with a column plan is of posed strands, and carries none",
                    ));
                }
                if light as usize >= wire::MAX_LIGHTS {
                    return Err(status(
                        Kind::Invalid,
                        format!("light {light} (at most {} lights)", wire::MAX_LIGHTS),
                    ));
                }
                let (version, light) = (first.version, light as usize);
                let round = ExchangeRound {
                    version,
                    frame,
                    sends: self.exchange_calls(&session, &plan)?,
                    plan,
                };
                let (inbox, store, memory) = (
                    session.exchange.clone(),
                    session.swept.clone(),
                    memory.clone(),
                );
                store.begin(version, light);
                // The summed columns go back as soon as they are, while the
                // swept columns are gathered for the Draw.
                let (tx, mut rx) = tokio::sync::mpsc::channel(STRIPES_IN_FLIGHT);
                let held = session.held.clone();
                tokio::task::spawn_blocking(move || {
                    let go = || !tx.is_closed();
                    let summed = (|| {
                        let mut slot = held.lock().map_err(poisoned)?;
                        let h = slot.as_mut().ok_or_else(no_share)?;
                        round.sum(&mut h.share, &maps, &fiber, &inbox, go)
                    })();
                    drop(budget);
                    match summed {
                        Err(s) => {
                            store.end(version, light, Err(s.message().to_string()));
                            let _ = tx.blocking_send(Err(s));
                        }
                        Ok((mut reply, rest)) => {
                            if let Some(c) = reply.first_mut() {
                                c.frame_id = frame_id;
                                c.light = light as u32;
                            }
                            for c in reply {
                                if tx.blocking_send(Ok(c)).is_err() {
                                    store.end(
                                        version,
                                        light,
                                        Err("the coordinator left the Density call".into()),
                                    );
                                    return;
                                }
                            }
                            drop(tx);
                            store.end(version, light, rest.finish(&inbox, &memory));
                        }
                    }
                });
                // A refusal before any column is the call's own status.
                let first = match rx.recv().await {
                    Some(Ok(c)) => c,
                    Some(Err(s)) => return Err(s),
                    None => {
                        return Err(status(
                            Kind::Internal,
                            "the Density call's task ended without a reply",
                        ));
                    }
                };
                let rest = tokio_stream::wrappers::ReceiverStream::new(rx);
                let stream: Chunks<pb::ColumnChunk> = Box::pin(tokio_stream::StreamExt::chain(
                    tokio_stream::once(Ok::<_, Status>(first)),
                    rest,
                ));
                return Ok(Response::new(stream));
            } else if first.posed {
                if hair.strand_count() > 0 {
                    return Err(status(Kind::Invalid, "a posed Density carries no strands"));
                }
                let (version, filter) = (first.version, first.trilinear);
                with_share(&session.held, move |share| {
                    let _budget = budget;
                    density_reply(&maps, frame, |map| {
                        let stats = share
                            .deposit_while(version, map, &fiber, go)
                            .map_err(refused)?
                            .ok_or_else(|| cancelled("Density"))?;
                        let read = share
                            .columns_read(version, &frame, filter)
                            .map_err(refused)?;
                        Ok((stats, Some(read)))
                    })
                })
                .await?
            } else {
                tokio::task::spawn_blocking(move || {
                    let _budget = budget;
                    density_reply(&maps, frame, |map| {
                        let stats = map
                            .deposit_while(&hair, 0..hair.strand_count(), &fiber, go)
                            .ok_or_else(|| cancelled("Density"))?;
                        Ok((stats, None))
                    })
                })
                .await
                .map_err(|e| status(Kind::Internal, format!("deposit task failed: {e}")))??
            };
            let mut chunks = chunks;
            if let Some(c) = chunks.first_mut() {
                c.frame_id = frame_id;
                c.light = light;
            }
            tracing::debug!(frame_id, light, chunks = chunks.len(), "deposit done");
            Ok(Response::new(stream_of(chunks)))
        };
        logged(peer, "Density", served.await)
    }
}
