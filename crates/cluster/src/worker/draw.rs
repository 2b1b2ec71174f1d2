//! Draw rounds with a band plan: the band this worker composites from the other workers' stripes.

use super::inbox::{STRIPE_PIXEL_BYTES, SendFailed, no_part, send_within, stalled};
use super::memory::Grant;
use super::session::{Session, on_pool};
use super::status::{
    cancelled, first_message, invalid, logged, no_share, poisoned, refused, status,
};
use super::{Chunks, STRIPE_ROWS, STRIPES_IN_FLIGHT};
use crate::error::WorkerErrorKind as Kind;
use crate::tls::Caller;
use crate::{WorkerService, pb, wire};
use prost::Message;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tonic::{Request, Response, Status, Streaming};

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
            let check = self.peer_check(&addr, sid);
            tokio::spawn(async move {
                // Nothing is sent to a peer that did not prove it belongs
                // to the cluster.
                let sent = async {
                    check.prove(&mut client).await?;
                    let stream = tokio_stream::wrappers::ReceiverStream::new(rx);
                    client
                        .composite(stream)
                        .await
                        .map_err(super::proof::call_failed)?;
                    Ok::<_, String>(())
                }
                .await;
                if let Err(why) = sent
                    && let Ok(mut f) = failed.lock()
                {
                    // One answer whatever the cause (a closed port, a
                    // silent one, another server, no proof): the caller
                    // learns nothing of the address but that it did not
                    // take part. The cause is in this worker's log.
                    tracing::warn!(band = b, %addr, why, "a peer did not take this worker's stripes");
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
                    let h = slot.as_mut().ok_or_else(no_share)?;
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

impl WorkerService {
    pub(super) async fn draw_call(
        &self,
        req: Request<Streaming<pb::DrawChunk>>,
    ) -> Result<Response<Chunks<pb::LayerChunk>>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Coordinator)?;
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Draw").await?;
            let job = first.job.as_ref().ok_or_else(|| {
                status(Kind::Invalid, "a Draw call's first chunk carries the job")
            })?;
            let exchanged = job.exchanged;
            let job = wire::job_from_pb(job).map_err(invalid)?;
            // The picture's size follows from the session's own scene:
            // checked before anything is allocated for it.
            let asked = (job.camera.width(), job.camera.height());
            match *session.picture.lock().map_err(poisoned)? {
                Some(size) if size == asked => {}
                Some((w, h)) => {
                    return Err(status(
                        Kind::Invalid,
                        format!(
                            "a Draw of a {}x{} picture for a scene of {w}x{h}",
                            asked.0, asked.1
                        ),
                    ));
                }
                None => return Err(no_share()),
            }
            let bands = first
                .bands
                .as_ref()
                .map(|b| wire::Bands::from_pb(b, job.camera.height()))
                .transpose()
                .map_err(invalid)?;
            let mut reader =
                wire::ColumnsReader::new(if job.shadows { job.lights.len() } else { 0 });
            // The swept columns' memory, held until the picture is drawn.
            let mut received = Grant::default();
            let memory = self.budget(&session);
            let mut add = |c: &pb::DrawChunk| -> Result<(), Status> {
                let bytes = wire::ColumnsReader::bytes_to_add(c);
                memory.take(&mut received, bytes, "the Draw's swept columns")?;
                reader.add(c).map_err(invalid)
            };
            if exchanged && (first.map.is_some() || !first.column_steps.is_empty()) {
                return Err(status(
                    Kind::Invalid,
                    "a Draw with the exchanged columns carries none",
                ));
            }
            if first.map.is_some() || !first.column_steps.is_empty() {
                add(&first)?;
            }
            while let Some(c) = stream.message().await? {
                if c.job.is_some() {
                    return Err(status(Kind::Invalid, "a Draw call carries one job"));
                }
                if exchanged {
                    return Err(status(
                        Kind::Invalid,
                        "a Draw with the exchanged columns carries none",
                    ));
                }
                add(&c)?;
            }
            // The columns swept here, or those the call brought.
            let (maps, kept) = if exchanged && job.shadows {
                let (store, version, lights) =
                    (session.swept.clone(), job.version, job.lights.len());
                let wait = bands.as_ref().map_or(Duration::from_secs(30), |b| b.wait);
                tokio::task::spawn_blocking(move || store.take(version, lights, wait))
                    .await
                    .map_err(|e| status(Kind::Internal, format!("worker task failed: {e}")))?
                    .map_err(Status::aborted)?
            } else {
                (reader.finish().map_err(invalid)?, Vec::new())
            };
            let received = (received, kept);
            if let Some(bands) = bands {
                let stream = self.draw_band(&session, job, maps, received, bands)?;
                return Ok(Response::new(stream));
            }
            // The picture streams a stripe of rows at a time, each sent
            // (and decoded by the coordinator) while the next is rasterized.
            let (tx, mut rx) = tokio::sync::mpsc::channel(STRIPES_IN_FLIGHT);
            let held = session.held.clone();
            let (width, height) = (job.camera.width(), job.camera.height());
            tokio::task::spawn_blocking(move || {
                let _received = received;
                let send = |c: Result<pb::LayerChunk, Status>| tx.blocking_send(c).is_ok();
                let drawn = (|| {
                    let mut slot = held.lock().map_err(poisoned)?;
                    let h = slot.as_mut().ok_or_else(no_share)?;
                    let mut encoder = wire::StripeEncoder::new();
                    let times = h
                        .share
                        .draw_stripes(&job, &maps, STRIPE_ROWS, |stripe| {
                            for c in encoder.chunks(&stripe) {
                                if !send(Ok(c)) {
                                    return Err(engine::EngineError::executor(
                                        "the coordinator stopped reading the picture",
                                    ));
                                }
                            }
                            Ok(())
                        })
                        .map_err(refused)?;
                    Ok(encoder.last(width, height, &times))
                })();
                send(drawn);
            });
            // A refusal before any pixel is the call's own status.
            let first = match rx.recv().await {
                Some(Ok(c)) => c,
                Some(Err(s)) => return Err(s),
                None => {
                    return Err(status(
                        Kind::Internal,
                        "the Draw's task ended without a picture",
                    ));
                }
            };
            let rest = tokio_stream::wrappers::ReceiverStream::new(rx);
            let stream: Chunks<pb::LayerChunk> = Box::pin(tokio_stream::StreamExt::chain(
                tokio_stream::once(Ok::<_, Status>(first)),
                rest,
            ));
            Ok(Response::new(stream))
        };
        logged(peer, "Draw", served.await)
    }

    pub(super) async fn composite_call(
        &self,
        req: Request<Streaming<pb::LayerChunk>>,
    ) -> Result<Response<pb::CompositeReply>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Peer)?;
            let memory = self.budget(&session);
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Composite").await?;
            let (round, from) = (first.round, first.from);
            let (w, h) = (first.width, first.height);
            if from as usize >= wire::MAX_WORKERS
                || w == 0
                || h == 0
                || u64::from(w) * u64::from(h) > raster::MAX_PIXELS
            {
                return Err(status(
                    Kind::Invalid,
                    format!(
                        "stripes from worker {from} of a {w}x{h} picture (at most {} workers, {} pixels)",
                        wire::MAX_WORKERS,
                        raster::MAX_PIXELS
                    ),
                ));
            }
            let mut grant = Grant::default();
            let stripes = if first.sort_middle {
                // Shaded segments of this worker's bands (sort-middle).
                let mut reader = wire::SegmentReader::new(w, h);
                let mut add = |c: &pb::LayerChunk| -> Result<(), Status> {
                    // The piece, and the band decoded from it.
                    let bytes = 2 * c.segments.len() as u64;
                    memory.take(&mut grant, bytes, "a Composite call's segments")?;
                    reader.add(c).map_err(invalid)
                };
                add(&first)?;
                while let Some(c) = stream.message().await? {
                    add(&c)?;
                }
                let bands = reader.finish().map_err(invalid)?;
                bands.into_iter().map(engine::Stripe::Segments).collect()
            } else {
                let mut reader = wire::LayerReader::new(w, h);
                let mut add = |c: &pb::LayerChunk| -> Result<(), Status> {
                    // The fragments take their own bytes again once read.
                    let bytes = u64::from(c.count) * STRIPE_PIXEL_BYTES + 2 * c.fronts.len() as u64;
                    memory.take(&mut grant, bytes, "a Composite call's stripes")?;
                    reader.add(c).map_err(invalid)
                };
                add(&first)?;
                while let Some(c) = stream.message().await? {
                    add(&c)?;
                }
                vec![engine::Stripe::Layer(reader.finish().map_err(invalid)?)]
            };
            session.inbox.deliver(round, from, stripes, grant)?;
            Ok(Response::new(pb::CompositeReply {}))
        };
        logged(peer, "Composite", served.await)
    }
}
