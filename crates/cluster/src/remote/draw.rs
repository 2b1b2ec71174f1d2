//! The coordinator's drawing calls: partial pictures composited here, or bands composited among the workers; the state a frame is drawn again from.

use super::*;

impl RemoteExecutor {
    pub(super) fn draw_remote(&mut self, job: &DrawJob) -> Result<DrawReport, ClusterError> {
        self.ensure_posed()?;
        if self.posed != Some(job.version) {
            return Err(ClusterError::Setup(format!(
                "the workers hold hair version {:?}, not {}",
                self.posed, job.version
            )));
        }
        let first = pb::DrawChunk {
            job: Some(wire::job_to_pb(job)),
            ..Default::default()
        };
        let mut requests = Vec::with_capacity(self.workers.len());
        let mut sent = 0u64;
        for (i, w) in self.workers.iter().enumerate() {
            let mut chunks = vec![first.clone()];
            if job.shadows {
                for (l, state) in self.lights.iter().enumerate() {
                    let (frame, slabs) = state
                        .swept
                        .as_ref()
                        .ok_or_else(|| {
                            ClusterError::Setup(format!("light {l} was not swept before drawing"))
                        })?
                        .get();
                    // The columns this worker reads; all of them after a loss.
                    let keep = state.reads.as_ref().and_then(|r| r.get(i));
                    chunks.extend(wire::draw_columns(
                        l as u32,
                        frame,
                        slabs,
                        keep.map(|k| &k[..]),
                    ));
                }
            }
            sent += chunks.iter().map(|c| c.encoded_len() as u64).sum::<u64>();
            requests.push((w.clone(), chunks));
        }
        let (width, height) = (job.camera.width(), job.camera.height());
        let t = Instant::now();
        let replies = fan_out(
            &self.rt,
            requests,
            "draw",
            self.deadline,
            move |mut w, chunks| async move {
                let mut s = w
                    .client
                    .draw(tokio_stream::iter(chunks))
                    .await
                    .map_err(|s| call_error(&w.addr, "draw", s))?
                    .into_inner();
                let mut reader = wire::LayerReader::new(width, height);
                let mut bytes = 0u64;
                // Each chunk is decoded as it comes, while the rest travel.
                while let Some(c) = s
                    .message()
                    .await
                    .map_err(|e| call_error(&w.addr, "draw", e))?
                {
                    bytes += c.encoded_len() as u64;
                    reader.add(&c).map_err(|e| malformed(&w.addr, e))?;
                }
                let times = reader.times;
                let layer = reader.finish().map_err(|e| malformed(&w.addr, e))?;
                Ok((layer, times, bytes))
            },
        )?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let mut report = DrawReport::default();
        let mut received = 0u64;
        let mut slowest = 0.0f64;
        let mut layers = Vec::with_capacity(replies.len());
        for (layer, times, bytes) in replies {
            received += bytes;
            report.filter_ms = report.filter_ms.max(times.filter_ms);
            report.shade_ms = report.shade_ms.max(times.shade_ms);
            report.raster_ms = report.raster_ms.max(times.raster_ms);
            slowest = slowest.max(times.filter_ms + times.shade_ms + times.raster_ms);
            layers.push(layer);
        }
        report.drawn = Drawn::Layers(layers);
        self.count(|x| {
            x.draw_sent += sent;
            x.layers_received += received;
        });
        self.clock(|x| {
            x.draw_ms += ms;
            x.draw_compute_ms += slowest;
        });
        Ok(report)
    }

    /// Whether the frame's Draw is composited on the workers: its scheme
    /// is one of theirs, two or more are left, and compositing among
    /// themselves did not fail for good.
    pub(super) fn composites_now(&self) -> bool {
        self.scheme.sort().is_some() && self.composite.is_on() && self.workers.len() >= 2
    }

    /// One Draw round composited on the workers (see [`wire::Bands`]): each
    /// resolves a band of rows and sends it finished. Any failure fails the
    /// round (the caller composites the frame here instead); no worker is
    /// dropped for it.
    pub(super) fn draw_composited(
        &mut self,
        job: &DrawJob,
        ahead: bool,
    ) -> Result<DrawReport, ClusterError> {
        self.ensure_posed()?;
        if self.posed != Some(job.version) {
            return Err(ClusterError::Setup(format!(
                "the workers hold hair version {:?}, not {}",
                self.posed, job.version
            )));
        }
        let n = self.workers.len();
        let (width, height) = (job.camera.width(), job.camera.height());
        self.calls += 1;
        let round = self.calls;
        let peers: Vec<(String, String)> = self
            .workers
            .iter()
            .map(|w| (w.addr.clone(), w.session.clone()))
            .collect();
        // The workers hold every column when they swept them together.
        let exchanged = job.shadows
            && self.posed == Some(job.version)
            && self
                .lights
                .iter()
                .all(|l| l.swept_on_workers == Some(job.version));
        // The workers' columns go with this Draw.
        self.lights
            .iter_mut()
            .for_each(|l| l.swept_on_workers = None);
        // Band owners shade the head under the hair's shadow: every column.
        let all_columns = job.shadows && self.head_shadow;
        let mut shared = Vec::new();
        let columns = |ex: &Self, i: usize, out: &mut Vec<pb::DrawChunk>| {
            for (l, state) in ex.lights.iter().enumerate() {
                let (frame, slabs) = state
                    .swept
                    .as_ref()
                    .ok_or_else(|| {
                        ClusterError::Setup(format!("light {l} was not swept before drawing"))
                    })?
                    .get();
                let keep = if all_columns {
                    None
                } else {
                    state.reads.as_ref().and_then(|r| r.get(i))
                };
                out.extend(wire::draw_columns(
                    l as u32,
                    frame,
                    slabs,
                    keep.map(|k| &k[..]),
                ));
            }
            Ok::<_, ClusterError>(())
        };
        if job.shadows && all_columns && !exchanged {
            columns(self, 0, &mut shared)?;
        }
        let mut pb_job = wire::job_to_pb(job);
        pb_job.exchanged = exchanged;
        // The frame's plan says which sort.
        let sort = self.scheme.sort().unwrap_or_default();
        let mut requests = Vec::with_capacity(n);
        let mut sent = 0u64;
        // Bands cut by what the last round of this sort measured, each
        // worker's of a cost that brings its own strands' work and its
        // bands to the same total (see `loads.rs`); until measured, of
        // equal rows.
        let costs = self.row_costs.lock().ok().and_then(|c| c.get(sort, height));
        let shares = costs
            .as_ref()
            .map_or_else(Vec::new, |c| self.loads.row_shares(sort, n, c.iter().sum()));
        let bands = height.div_ceil(BAND_ROWS).div_ceil(n as u32) as usize * n;
        for (i, w) in self.workers.iter().enumerate() {
            let mut plan = costs
                .as_ref()
                .and_then(|c| engine::BandPlan::weighted(height, c, &shares, bands, n, i))
                .unwrap_or_else(|| engine::BandPlan::dealt(height, BAND_ROWS, n, i));
            plan.sort = sort;
            let bands = wire::Bands {
                round,
                plan,
                peers: peers.clone(),
                wait: self.deadline / 2,
                tls_domain: self.tls_domain.clone(),
            };
            let rows = bands.plan.rows_of(i);
            let mut chunks = vec![pb::DrawChunk {
                job: Some(pb_job.clone()),
                bands: Some(bands.to_pb()),
                ..Default::default()
            }];
            if job.shadows && !exchanged {
                if all_columns {
                    chunks.extend(shared.iter().cloned());
                } else {
                    columns(self, i, &mut chunks)?;
                }
            }
            sent += chunks.iter().map(|c| c.encoded_len() as u64).sum::<u64>();
            requests.push((w.clone(), (chunks, rows)));
        }
        let deadline = self.deadline;
        let t = Instant::now();
        // Each worker's reply: first the word that it rasterized and sent
        // its stripes (with its times), then its bands once composited.
        let (mut drawn, mut tasks) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for (mut w, (chunks, rows)) in requests {
            let (said, hear) = tokio::sync::oneshot::channel();
            drawn.push(hear);
            tasks.push(self.rt.spawn(async move {
                let addr = w.addr.clone();
                let call = async move {
                    let mut s = w
                        .client
                        .draw(tokio_stream::iter(chunks))
                        .await
                        .map_err(|s| call_error(&w.addr, "draw", s))?
                        .into_inner();
                    let first = s
                        .message()
                        .await
                        .map_err(|e| call_error(&w.addr, "draw", e))?
                        .filter(|c| c.drawn)
                        .ok_or_else(|| malformed(&w.addr, "a band reply without its first word"))?;
                    let mut bytes = first.encoded_len() as u64;
                    let _ = said.send(first);
                    let mut reader = wire::BandReader::new(width, height, rows);
                    // A worker that gave up for another's sake names no
                    // worker to drop: the one at fault fails on its own.
                    let failed = |e: tonic::Status| match WorkerError::from(e) {
                        e if e.kind == WorkerErrorKind::Aborted => {
                            ClusterError::Composite(format!("worker {}: {}", w.addr, e.message))
                        }
                        error => ClusterError::Call {
                            addr: w.addr.clone(),
                            stage: "draw",
                            error,
                        },
                    };
                    while let Some(c) = s.message().await.map_err(failed)? {
                        bytes += c.encoded_len() as u64;
                        reader.add(&c).map_err(|e| malformed(&w.addr, e))?;
                    }
                    let (times, stripes) = (reader.times, reader.stripes_sent);
                    let band_ms = std::mem::take(&mut reader.band_ms);
                    let bands = reader.finish().map_err(|e| malformed(&w.addr, e))?;
                    Ok(BandReply {
                        bands,
                        band_ms,
                        times,
                        bytes,
                        stripes,
                    })
                };
                match tokio::time::timeout(deadline, call).await {
                    Ok(r) => r,
                    Err(_) => Err(ClusterError::Deadline {
                        addr,
                        stage: "draw",
                        secs: deadline.as_secs_f64(),
                    }),
                }
            }));
        }
        self.count(|x| x.draw_sent += sent);
        // Until every worker has rasterized: a failure before is this
        // round's, and the frame is composited here at once.
        let words = self.rt.block_on(async {
            let mut out = Vec::with_capacity(n);
            for hear in drawn {
                out.push(hear.await.ok());
            }
            out
        });
        let mut report = DrawReport::default();
        let mut slowest = 0.0f64;
        for (i, w) in words.iter().enumerate() {
            let Some(c) = w else { continue };
            self.loads
                .drew(sort, i, n, c.filter_ms + c.shade_ms + c.raster_ms);
            report.filter_ms = report.filter_ms.max(c.filter_ms);
            report.shade_ms = report.shade_ms.max(c.shade_ms);
            report.raster_ms = report.raster_ms.max(c.raster_ms);
            slowest = slowest.max(c.filter_ms + c.shade_ms + c.raster_ms);
        }
        let round = BandRound {
            rt: self.rt.handle().clone(),
            tasks,
            width,
            height,
            traffic: self.traffic.clone(),
            timing: self.timing.clone(),
            sort,
            row_costs: self.row_costs.clone(),
        };
        if words.iter().any(Option::is_none) {
            let e = round.finish().err().unwrap_or_else(|| {
                ClusterError::Composite("a worker's reply ended before its first word".into())
            });
            return Err(ClusterError::Composite(e.to_string()));
        }
        let ms = t.elapsed().as_secs_f64() * 1e3;
        self.clock(|x| {
            x.draw_ms += ms;
            x.draw_compute_ms += slowest;
        });
        if ahead {
            let failure = self.failure.clone();
            report.drawn = Drawn::Pending(PendingPicture::new(move || {
                round.finish().map_err(|e| {
                    if let Ok(mut f) = failure.lock() {
                        *f = Some(e.clone());
                    }
                    EngineError::Executor(Box::new(e))
                })
            }));
        } else {
            report.drawn = Drawn::Picture(
                round
                    .finish()
                    .map_err(|e| ClusterError::Composite(e.to_string()))?,
            );
        }
        Ok(report)
    }

    /// What drawing hair version `version` again takes, as things stand.
    pub(super) fn snapshot(&self, version: u64) -> Snapshot {
        Snapshot {
            version,
            states: self
                .hair
                .as_ref()
                .map(|h| h.states.clone())
                .unwrap_or_default(),
            pose: self.last_pose.clone(),
            lights: self.lights.clone(),
            workers: self.addrs(),
        }
    }

    /// Back to `to`: the workers are assigned its states and pose it again
    /// before their next stage (reading every column when they changed).
    pub(super) fn restore(&mut self, to: Snapshot) {
        if let Some(h) = &mut self.hair {
            h.states = to.states;
        }
        self.last_pose = to.pose;
        // The snapshot's sweeps, and its reads when the workers are the
        // same; the columns' weights stay the latest.
        let same_workers = self.addrs() == to.workers;
        for (l, then) in self.lights.iter_mut().zip(to.lights) {
            l.forget_workers();
            l.swept = then.swept;
            l.reads = then.reads.filter(|_| same_workers);
        }
        self.shares = None;
        self.posed = None;
    }

    /// A Draw, composited on the workers when they can (and, `ahead`, its
    /// picture left to finish while the next frame's stages run),
    /// otherwise here.
    pub(super) fn draw_with(
        &mut self,
        job: &DrawJob,
        ahead: bool,
    ) -> Result<DrawReport, EngineError> {
        self.drawn = None;
        if self.composites_now() {
            match self.draw_composited(job, ahead) {
                Ok(r) => {
                    if ahead {
                        self.drawn = Some(self.snapshot(job.version));
                    }
                    return Ok(r);
                }
                Err(e) => {
                    // The frame is composited here instead, with whichever
                    // workers answer; a worker that fails that is dropped.
                    // The frame is no measure of its scheme.
                    self.chosen.clear();
                    tracing::warn!(error = %e, "compositing on the workers failed; this frame is composited on the coordinator");
                    self.clock(|t| t.composite_fallbacks += 1);
                    let before = self.workers.len();
                    let r = self
                        .with_survivors(|ex| ex.draw_remote(job))
                        .map_err(engine_error);
                    if r.is_ok() && self.workers.len() == before && self.composite.failed() {
                        tracing::warn!(
                            "the workers failed twice to composite together with none of them lost (can they reach each other at the addresses the coordinator dials? with TLS, do their certificates allow client use?); the coordinator composites from now on"
                        );
                    }
                    return r;
                }
            }
        }
        self.with_survivors(|ex| ex.draw_remote(job))
            .map_err(engine_error)
    }
}

/// One worker's bands of a Draw round composited on the workers.
pub(super) struct BandReply {
    pub(super) bands: Vec<(Range<u32>, Vec<u8>)>,
    /// What drawing each band took on the worker, ms (empty: not said).
    pub(super) band_ms: Vec<f64>,
    pub(super) times: engine::DrawTimes,
    pub(super) bytes: u64,
    pub(super) stripes: u64,
}

/// A Draw round composited on the workers, past their rasterization: the
/// calls still bringing the finished bands.
pub(super) struct BandRound {
    pub(super) rt: tokio::runtime::Handle,
    pub(super) tasks: Vec<tokio::task::JoinHandle<Result<BandReply, ClusterError>>>,
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) traffic: Arc<Mutex<Traffic>>,
    pub(super) timing: Arc<Mutex<Timing>>,
    /// The round's sort.
    pub(super) sort: engine::Sort,
    /// Where its bands' costs go, for the next round's cuts.
    pub(super) row_costs: Arc<Mutex<RowCosts>>,
}

impl BandRound {
    /// The finished picture, once every worker's bands came: the first
    /// failure otherwise (the other calls are stopped).
    pub(super) fn finish(self) -> Result<image::RgbImage, ClusterError> {
        let aborts: Vec<_> = self.tasks.iter().map(|t| t.abort_handle()).collect();
        let replies = self.rt.block_on(async {
            let mut out = Vec::with_capacity(self.tasks.len());
            for t in self.tasks {
                let r = t
                    .await
                    .map_err(|e| ClusterError::Setup(e.to_string()))
                    .and_then(|r| r);
                if r.is_err() {
                    aborts.iter().for_each(|a| a.abort());
                }
                out.push(r);
            }
            out
        });
        let mut img = image::RgbImage::new(self.width, self.height);
        let mut measured = RowCosts::units(self.height);
        let (mut received, mut stripes) = (0u64, 0u64);
        let (mut wait, mut composite) = (0.0f64, 0.0f64);
        let mut first_error = None;
        for r in replies {
            match r {
                Ok(reply) => {
                    let row = 3 * self.width as usize;
                    let buf: &mut [u8] = &mut img;
                    if reply.band_ms.len() == reply.bands.len() {
                        for ((rows, _), &ms) in reply.bands.iter().zip(&reply.band_ms) {
                            RowCosts::spread(&mut measured, rows.clone(), ms);
                        }
                    }
                    for (rows, rgb) in reply.bands {
                        let at = rows.start as usize * row;
                        buf[at..at + rgb.len()].copy_from_slice(&rgb);
                    }
                    received += reply.bytes;
                    stripes += reply.stripes;
                    wait = wait.max(reply.times.wait_ms);
                    composite = composite.max(reply.times.composite_ms);
                }
                Err(e) => {
                    if first_error
                        .as_ref()
                        .is_none_or(|f: &ClusterError| f.worker().is_none() && e.worker().is_some())
                    {
                        first_error = Some(e);
                    }
                }
            }
        }
        if let Ok(mut t) = self.traffic.lock() {
            t.bands_received += received;
            t.stripes_between_workers += stripes;
        }
        if let Some(e) = first_error {
            return Err(e);
        }
        if let Ok(mut c) = self.row_costs.lock() {
            c.set(self.sort, self.height, measured);
        }
        if let Ok(mut t) = self.timing.lock() {
            t.band_wait_ms += wait;
            t.band_composite_ms += composite;
        }
        Ok(img)
    }
}

/// What drawing each 16 rows of the picture cost in the last round of
/// each sort, ms: the next round of that sort cuts its bands by it.
#[derive(Debug, Default)]
pub(super) struct RowCosts {
    /// Per sort (in the order of [`engine::Sort::ALL`]): the picture's height, and the
    /// cost of each 16 rows.
    of: [Option<(u32, Vec<f64>)>; 2],
}

impl RowCosts {
    /// No cost yet for each 16 rows of a picture of `height` rows.
    pub(super) fn units(height: u32) -> Vec<f64> {
        vec![0.0; height.div_ceil(raster::Canvas::BAND_ROWS) as usize]
    }

    /// Spreads `ms`, the cost of rows `rows`, evenly over them.
    pub(super) fn spread(units: &mut [f64], rows: Range<u32>, ms: f64) {
        let step = raster::Canvas::BAND_ROWS;
        let per_row = ms / rows.len().max(1) as f64;
        for (u, c) in units.iter_mut().enumerate() {
            let (a, b) = (u as u32 * step, (u as u32 + 1) * step);
            let overlap = b.min(rows.end).saturating_sub(a.max(rows.start));
            *c += per_row * f64::from(overlap);
        }
    }

    /// The last costs of `sort` for a picture of `height` rows; until
    /// that sort has drawn one, the other sort's: both follow where the
    /// hair's pixels are, and the first round of a sort cut in rows of
    /// equal height would hand one worker most of the hair (a frame that
    /// `--draw auto` would hold against the sort).
    pub(super) fn get(&self, sort: engine::Sort, height: u32) -> Option<Vec<f64>> {
        let of = |s: engine::Sort| match &self.of[s.index()] {
            Some((h, c)) if *h == height && c.iter().any(|&x| x > 0.0) => Some(c.clone()),
            _ => None,
        };
        of(sort).or_else(|| {
            engine::Sort::ALL
                .into_iter()
                .filter(|&s| s != sort)
                .find_map(of)
        })
    }

    /// Keeps a round's costs.
    pub(super) fn set(&mut self, sort: engine::Sort, height: u32, units: Vec<f64>) {
        self.of[sort.index()] = Some((height, units));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bands_cost_is_spread_over_its_rows_kept_per_sort_and_lent_to_the_other() {
        let mut units = RowCosts::units(90);
        assert_eq!(units.len(), 6);
        // Rows 16..64 took 30 ms: 10 for each 16; rows 64..90, 13 ms.
        RowCosts::spread(&mut units, 16..64, 30.0);
        RowCosts::spread(&mut units, 64..90, 13.0);
        let want = [0.0, 10.0, 10.0, 10.0, 8.0, 5.0];
        assert!(
            units.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-9),
            "{units:?}"
        );
        let mut costs = RowCosts::default();
        costs.set(engine::Sort::Middle, 90, units.clone());
        assert_eq!(costs.get(engine::Sort::Middle, 90), Some(units.clone()));
        // A sort not measured yet is cut by the other's costs.
        assert_eq!(costs.get(engine::Sort::Last, 90), Some(units.clone()));
        assert_eq!(costs.get(engine::Sort::Middle, 96), None, "another picture");
        // Once measured, each its own; a round that measured nothing is
        // no measure.
        let last = vec![1.0; 6];
        costs.set(engine::Sort::Last, 90, last.clone());
        assert_eq!(costs.get(engine::Sort::Last, 90), Some(last));
        assert_eq!(costs.get(engine::Sort::Middle, 90), Some(units.clone()));
        costs.set(engine::Sort::Last, 90, RowCosts::units(90));
        assert_eq!(
            costs.get(engine::Sort::Last, 90),
            Some(units),
            "the other's"
        );
        let mut none = RowCosts::default();
        none.set(engine::Sort::Last, 90, RowCosts::units(90));
        assert_eq!(none.get(engine::Sort::Last, 90), None, "nothing measured");
    }
}
