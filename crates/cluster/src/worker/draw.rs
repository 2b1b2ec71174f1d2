//! Draw rounds with a band plan: the band this worker composites from the other workers' stripes.

use super::inbox::{SendFailed, no_part, send_within, stalled};
use super::memory::Grant;
use super::session::{Session, on_pool};
use super::status::{cancelled, poisoned, status};
use super::{Chunks, STRIPES_IN_FLIGHT};
use crate::error::WorkerErrorKind as Kind;
use crate::{WorkerService, pb, wire};
use prost::Message;
use std::sync::{Arc, Mutex};
use std::time::Instant;
use tonic::Status;

impl WorkerService {
    /// A Draw composited on the workers (see [`wire::Bands`]): one
    /// Composite call to each other band's worker carries this worker's
    /// stripes of that band while it rasterizes; then the others' stripes
    /// of its own band are gathered, and the band's finished rows are the
    /// reply.
    pub(super) fn draw_band(
        &self,
        session: &Session,
        job: engine::DrawJob,
        maps: Vec<shadow::Transmittance>,
        received: (Grant, Vec<Grant>),
        bands: wire::Bands,
    ) -> Result<Chunks<pb::LayerChunk>, Status> {
        let n = bands.plan.workers;
        let own = bands.plan.own;
        session.inbox.begin(bands.round);
        let (width, height) = (job.camera.width(), job.camera.height());
        let failed: Arc<Mutex<Option<String>>> = Arc::default();
        let mut senders: Vec<Option<tokio::sync::mpsc::Sender<pb::LayerChunk>>> = vec![None; n];
        for (b, slot) in senders.iter_mut().enumerate() {
            if b == own {
                continue;
            }
            let (addr, sid) = &bands.peers[b];
            session.allows(b, addr)?;
            let mut client = self.peer(addr, sid, bands.tls_domain.as_deref(), bands.wait)?;
            let (tx, rx) = tokio::sync::mpsc::channel(STRIPES_IN_FLIGHT);
            let header = pb::LayerChunk {
                width,
                height,
                round: bands.round,
                from: own as u32,
                sort_middle: bands.plan.sort == engine::Sort::Middle,
                ..Default::default()
            };
            tx.try_send(header)
                .map_err(|_| status(Kind::Internal, "a new channel refused its first chunk"))?;
            *slot = Some(tx);
            let (failed, addr) = (failed.clone(), addr.clone());
            tokio::spawn(async move {
                let stream = tokio_stream::wrappers::ReceiverStream::new(rx);
                if let Err(s) = client.composite(stream).await
                    && let Ok(mut f) = failed.lock()
                {
                    // One answer whatever the cause (a closed port, a
                    // silent one, another server): the caller learns
                    // nothing of the address but that it did not take
                    // part. The cause is in this worker's log.
                    tracing::warn!(band = b, %addr, code = ?s.code(), message = s.message(), "a peer did not take this worker's stripes");
                    f.get_or_insert(no_part(b));
                }
            });
        }
        let (tx, rx) = tokio::sync::mpsc::channel(STRIPES_IN_FLIGHT);
        let (held, inbox) = (session.held.clone(), session.inbox.clone());
        let handle = tokio::runtime::Handle::current();
        tokio::task::spawn_blocking(move || {
            let _received = received;
            let peer_failed = || failed.lock().ok().and_then(|f| f.clone());
            let mut canvas = None;
            let drawn = (|| {
                let others: Vec<u32> = (0..n as u32).filter(|&b| b != own as u32).collect();
                let mut stripes_sent = 0u64;
                // Rasterized and sent under the share's lock, which is then
                // free for the next frame's calls while this one composites.
                let (work, background) = {
                    let mut slot = held.lock().map_err(poisoned)?;
                    let h = slot.as_mut().ok_or_else(|| {
                        status(
                            Kind::Precondition,
                            "no share of the hair here: call Assign first",
                        )
                    })?;
                    let background = raster::to_srgb8(h.share.background());
                    let mut encoders: Vec<wire::StripeEncoder> =
                        (0..n).map(|_| wire::StripeEncoder::new()).collect();
                    // The peer that stopped taking its stripes, if one did.
                    let mut stalled_peer = None;
                    let work = on_pool(|| {
                        h.share.draw_band(&job, &maps, &bands.plan, |b, stripe| {
                            let to = senders[b].as_ref().expect("a call for each other worker");
                            let chunks = match &stripe {
                                engine::Stripe::Layer(l) => encoders[b].chunks(l),
                                engine::Stripe::Segments(s) => {
                                    wire::segment_chunks(s, width, height)
                                }
                            };
                            for c in chunks {
                                stripes_sent += c.encoded_len() as u64;
                                match send_within(&handle, to, c, bands.wait) {
                                    Ok(()) => {}
                                    Err(SendFailed::Stalled) => {
                                        stalled_peer = Some(b);
                                        return Err(engine::EngineError::executor("stalled"));
                                    }
                                    Err(SendFailed::Ended) => {
                                        return Err(engine::EngineError::executor(
                                            peer_failed().unwrap_or_else(|| no_part(b)),
                                        ));
                                    }
                                }
                            }
                            Ok(())
                        })
                    })
                    .map_err(|e| match stalled_peer {
                        Some(b) => stalled(b),
                        None => status(Kind::Aborted, e.to_string()),
                    })?;
                    (work, background)
                };
                // The calls' streams end: the others can finish.
                drop(senders);
                let mut marker = wire::StripeEncoder::new().last(width, height, &work.times);
                marker.drawn = true;
                if tx.blocking_send(Ok(marker)).is_err() {
                    return Err(cancelled("Draw"));
                }
                let t = Instant::now();
                let gathered = inbox.gather(bands.round, &others, bands.wait, || {
                    if tx.is_closed() {
                        return Err("the coordinator left the Draw".into());
                    }
                    peer_failed().map_or(Ok(()), Err)
                });
                let wait_ms = t.elapsed().as_secs_f64() * 1e3;
                let gathered = match gathered {
                    // Their memory goes as it did: the resolve copies them.
                    Ok(g) => g.into_iter().flat_map(|(stripes, _)| stripes).collect(),
                    Err(e) => {
                        canvas = Some(work.into_canvas());
                        return Err(e.status());
                    }
                };
                let (resolved, done) = work.resolve(gathered);
                canvas = Some(done);
                let (bands_drawn, mut times) =
                    resolved.map_err(|e| status(Kind::Invalid, e.to_string()))?;
                times.wait_ms = wait_ms;
                let mut chunks = Vec::new();
                for b in &bands_drawn {
                    chunks.extend(wire::band_chunks(
                        width,
                        height,
                        b.rows.start,
                        &b.rgb,
                        background,
                    ));
                }
                let mut last = wire::StripeEncoder::new().last(width, height, &times);
                last.stripes_sent = stripes_sent;
                last.band_ms = bands_drawn.iter().map(|b| b.ms).collect();
                chunks.push(last);
                Ok(chunks)
            })();
            match drawn {
                Ok(chunks) => {
                    for c in chunks {
                        if tx.blocking_send(Ok(c)).is_err() {
                            break;
                        }
                    }
                }
                Err(s) => {
                    let _ = tx.blocking_send(Err(s));
                }
            }
            // The canvas back to the share, for the next frame's draw.
            if let Some(c) = canvas
                && let Ok(mut slot) = held.lock()
                && let Some(h) = slot.as_mut()
            {
                h.share.put_canvas(c);
            }
        });
        // The band's rows (or the refusal, as the stream's status) come
        // once it is resolved.
        Ok(Box::pin(tokio_stream::wrappers::ReceiverStream::new(rx)))
    }
}
