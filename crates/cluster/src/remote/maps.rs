//! The coordinator's calls of the shadow maps: the density stage (Density), with the workers summing and sweeping each map among themselves or here, and the transmittance stage's sweep (Transmittance).

use super::*;

/// What one worker's Density reply held, decoded and checked.
#[derive(Default)]
pub(super) struct Gathered {
    pub(super) columns: Vec<wire::Columns>,
    pub(super) bytes: u64,
    pub(super) samples: u64,
    pub(super) out_of_map: u64,
    /// The columns its strands' lookups read, for posed strands.
    pub(super) read: Option<Vec<u64>>,
}

impl RemoteExecutor {
    /// The Density requests of one fill: the workers' posed strands when
    /// they hold hair `version`, else shares of `hair`'s strands; `None`
    /// when they hold another version and no strands are given.
    pub(super) fn density_requests(
        &self,
        id: u64,
        light: u32,
        frame: &LightFrame,
        hair: Option<&Hair>,
        version: Option<u64>,
    ) -> Option<Vec<(Remote, Vec<pb::DensityChunk>)>> {
        if version.is_some() && version == self.posed && self.shares.is_some() {
            return Some(
                self.workers
                    .iter()
                    .map(|w| {
                        let c = pb::DensityChunk {
                            frame_id: id,
                            light,
                            map: Some(wire::frame_to_pb(frame)),
                            posed: true,
                            version: version.unwrap_or_default(),
                            trilinear: self.trilinear,
                            ..Default::default()
                        };
                        (w.clone(), vec![c])
                    })
                    .collect(),
            );
        }
        let hair = hair.filter(|h| h.strand_count() > 0)?;
        let offsets = hair.offsets();
        let shares = split_by(hair.strand_count(), self.workers.len(), |s| {
            u64::from(offsets[s + 1] - offsets[s]) + 1
        });
        Some(
            self.workers
                .iter()
                .zip(shares)
                .map(|(w, share)| {
                    (
                        w.clone(),
                        wire::density_chunks(id, light, frame, hair, share),
                    )
                })
                .collect(),
        )
    }

    /// One Density round in which the workers sum and sweep light
    /// `light`'s map among themselves (see [`wire::ColumnPlan`]): `map`
    /// gets the sum of every worker's columns, each as its owner summed
    /// it. Any failure of the round is the round's ([`ClusterError::Exchange`]),
    /// but for a worker that failed its own call, which is named.
    pub(super) fn fill_exchanged(
        &mut self,
        light: usize,
        map: &mut DensityMap,
        version: u64,
    ) -> Result<FillStats, ClusterError> {
        let frame = *map.frame();
        let n = self.workers.len();
        let columns = frame.columns();
        let weights = self
            .lights
            .get(light)
            .and_then(|l| l.column_weights.as_ref())
            .filter(|w| w.len() == columns);
        let cuts = wire::ColumnPlan::cuts(columns, n, |c| weights.map_or(1, |w| u64::from(w[c])));
        let head = if self.head_shadow {
            match &self.last_pose {
                Some(p) if p.version == version => Some(p.head),
                _ => {
                    return Err(ClusterError::Exchange(format!(
                        "the head's pose for hair version {version} is not known here"
                    )));
                }
            }
        } else {
            None
        };
        self.calls += 1;
        let round = self.calls;
        let peers: Vec<(String, String)> = self
            .workers
            .iter()
            .map(|w| (w.addr.clone(), w.session.clone()))
            .collect();
        let mut requests = Vec::with_capacity(n);
        let mut sent = 0u64;
        for (i, w) in self.workers.iter().enumerate() {
            let plan = wire::ColumnPlan {
                round,
                cuts: cuts.clone(),
                own: i,
                peers: peers.clone(),
                wait: self.deadline / 2,
                tls_domain: self.tls_domain.clone(),
                head,
            };
            let c = pb::DensityChunk {
                frame_id: version,
                light: light as u32,
                map: Some(wire::frame_to_pb(&frame)),
                posed: true,
                version,
                trilinear: self.trilinear,
                columns: Some(plan.to_pb()),
                ..Default::default()
            };
            sent += c.encoded_len() as u64;
            requests.push((w.clone(), (c, plan.range(i))));
        }
        let t = Instant::now();
        let replies = fan_out_all(
            &self.rt,
            requests,
            "density",
            self.deadline,
            move |mut w, (chunk, range)| async move {
                // A worker that gave up for another's sake names no
                // worker to drop: the one at fault fails on its own.
                let failed = |e: tonic::Status| match WorkerError::from(e) {
                    e if e.kind == WorkerErrorKind::Aborted => {
                        ClusterError::Exchange(format!("worker {}: {}", w.addr, e.message))
                    }
                    error => ClusterError::Call {
                        addr: w.addr.clone(),
                        stage: "density",
                        error,
                    },
                };
                let mut s = w
                    .client
                    .density(tokio_stream::iter([chunk]))
                    .await
                    .map_err(failed)?
                    .into_inner();
                let mut got = Gathered::default();
                let mut between = (0u64, 0u64);
                while let Some(c) = s.message().await.map_err(failed)? {
                    let d = wire::decode_columns(&frame, &c).map_err(|e| malformed(&w.addr, e))?;
                    if !d.within(range.clone()) {
                        return Err(malformed(
                            &w.addr,
                            format!("summed columns past its own, {range:?}"),
                        ));
                    }
                    got.columns.push(d);
                    got.bytes += c.encoded_len() as u64;
                    got.samples += c.samples;
                    got.out_of_map += c.out_of_map;
                    between.0 += c.exchanged_density;
                    between.1 += c.exchanged_swept;
                }
                Ok((got, between))
            },
        );
        // A worker at fault is named before a round given up for its sake.
        let mut gathered = Vec::with_capacity(n);
        let mut first_error: Option<ClusterError> = None;
        for r in replies {
            match r {
                Ok(g) => gathered.push(g),
                Err(e) => {
                    if first_error
                        .as_ref()
                        .is_none_or(|f| f.worker().is_none() && e.worker().is_some())
                    {
                        first_error = Some(e);
                    }
                }
            }
        }
        if let Some(e) = first_error {
            return Err(e);
        }
        let mut stats = FillStats::default();
        let (mut received, mut density_between, mut swept_between) = (0u64, 0u64, 0u64);
        for (got, between) in &gathered {
            received += got.bytes;
            stats.samples += got.samples;
            stats.out_of_map += got.out_of_map;
            density_between += between.0;
            swept_between += between.1;
            for d in &got.columns {
                wire::add_columns(map, d);
            }
        }
        // The next map's columns are cut by this one's.
        if let Some(l) = self.lights.get_mut(light) {
            l.column_weights = Some(
                (0..columns)
                    .map(|c| {
                        let m = map.meta(c);
                        if m.is_empty() {
                            1
                        } else {
                            u32::from(m.hi - m.lo) + 2
                        }
                    })
                    .collect(),
            );
            l.exchanged = Some(version);
            l.reads = None;
        }
        tracing::debug!(
            frame_id = version,
            light,
            "density summed and swept on the workers"
        );
        self.count(|t| {
            t.strands_sent += sent;
            t.density_received += received;
            t.density_between_workers += density_between;
            t.swept_between_workers += swept_between;
        });
        let ms = t.elapsed().as_secs_f64() * 1e3;
        self.clock(|x| x.density_ms += ms);
        Ok(stats)
    }

    /// The transmittance of a map the workers summed and swept among
    /// themselves, swept again here: for the head drawn here; the map is
    /// kept, to sweep into slabs if a frame must be drawn again after a
    /// failure.
    pub(super) fn sweep_here(
        &mut self,
        light: usize,
        map: &DensityMap,
    ) -> Result<Transmittance, ClusterError> {
        let t = Instant::now();
        let trans = Transmittance::compute(map);
        if let Some(l) = self.lights.get_mut(light) {
            l.swept = Some(Arc::new(SweptMap::of_map(map.clone())));
            l.swept_on_workers = l.exchanged;
        }
        let ms = t.elapsed().as_secs_f64() * 1e3;
        self.clock(|x| x.transmittance_ms += ms);
        Ok(trans)
    }

    pub(super) fn fill_remote(
        &mut self,
        light: usize,
        map: &mut DensityMap,
        hair: Option<&Hair>,
        version: Option<u64>,
    ) -> Result<FillStats, ClusterError> {
        if self.draw.on_workers() {
            self.ensure_posed()?;
        }
        let id = version.unwrap_or_else(|| {
            self.calls += 1;
            self.calls
        });
        let frame = *map.frame();
        let Some(requests) = self.density_requests(id, light as u32, &frame, hair, version) else {
            return Err(ClusterError::Setup(format!(
                "the workers hold hair version {:?}, not {version:?}, and no strands were given",
                self.posed
            )));
        };
        let posed = requests.first().is_some_and(|(_, c)| c[0].posed);
        let sent: u64 = requests
            .iter()
            .flat_map(|(_, c)| c)
            .map(|c| c.encoded_len() as u64)
            .sum();
        let t = Instant::now();
        let replies = fan_out(
            &self.rt,
            requests,
            "density",
            self.deadline,
            move |mut w, chunks| async move {
                let mut s = w
                    .client
                    .density(tokio_stream::iter(chunks))
                    .await
                    .map_err(|s| call_error(&w.addr, "density", s))?
                    .into_inner();
                // Each chunk is decoded as it comes (the other workers'
                // replies still travel), and checked before the map changes.
                let mut got = Gathered::default();
                let mut last = None;
                while let Some(c) = s
                    .message()
                    .await
                    .map_err(|e| call_error(&w.addr, "density", e))?
                {
                    let d = wire::decode_columns(&frame, &c).map_err(|e| malformed(&w.addr, e))?;
                    got.columns.push(d);
                    got.bytes += c.encoded_len() as u64;
                    got.samples += c.samples;
                    got.out_of_map += c.out_of_map;
                    last = Some(c.columns_read);
                }
                if posed {
                    let last = last.ok_or_else(|| malformed(&w.addr, "an empty Density reply"))?;
                    got.read = Some(
                        wire::columns_from_pb(&last, frame.columns())
                            .map_err(|e| malformed(&w.addr, e))?,
                    );
                }
                Ok(got)
            },
        )?;
        // Merge in worker order (integer sums: any order gives the same
        // map).
        let mut stats = FillStats::default();
        let mut received = 0u64;
        let mut decoded = Vec::with_capacity(replies.len());
        let mut reads = Vec::with_capacity(replies.len());
        for got in replies {
            received += got.bytes;
            stats.samples += got.samples;
            stats.out_of_map += got.out_of_map;
            decoded.extend(got.columns);
            reads.extend(got.read);
        }
        for d in &decoded {
            wire::add_columns(map, d);
        }
        if let Some(l) = self.lights.get_mut(light) {
            l.reads = posed.then_some(reads);
        }
        tracing::debug!(frame_id = id, light, posed, "density gathered");
        self.count(|t| {
            t.strands_sent += sent;
            t.density_received += received;
        });
        let ms = t.elapsed().as_secs_f64() * 1e3;
        self.clock(|x| x.density_ms += ms);
        Ok(stats)
    }

    pub(super) fn sweep_remote(
        &mut self,
        light: usize,
        map: &DensityMap,
    ) -> Result<Transmittance, ClusterError> {
        let frame = *map.frame();
        let n = frame.columns();
        let shares = split_by(n, self.workers.len(), |c| {
            let m = map.meta(c);
            if m.is_empty() {
                1
            } else {
                u64::from(m.hi - m.lo) + 2
            }
        });
        self.calls += 1;
        let id = self.calls;
        let mut requests = Vec::with_capacity(shares.len());
        let mut sent = 0u64;
        for (w, share) in self.workers.iter().zip(&shares) {
            let mut chunks = wire::column_chunks(map, share.clone());
            let first = &mut chunks[0];
            first.frame_id = id;
            first.light = light as u32;
            first.map = Some(wire::frame_to_pb(&frame));
            first.first_column = share.start as u32;
            first.end_column = share.end as u32;
            sent += chunks.iter().map(|c| c.encoded_len() as u64).sum::<u64>();
            // The spans the slab will have: those of the density sent.
            let range = share.start as u32..share.end as u32;
            requests.push((w.clone(), (chunks, ColumnSlab::layout(map, range))));
        }
        let t = Instant::now();
        let replies = fan_out(
            &self.rt,
            requests,
            "transmittance",
            self.deadline,
            move |mut w, (chunks, layout)| async move {
                let s = w
                    .client
                    .transmittance(tokio_stream::iter(chunks))
                    .await
                    .map_err(|s| call_error(&w.addr, "transmittance", s))?
                    .into_inner();
                let mut reader = wire::SlabReader::new(layout);
                let mut bytes = 0u64;
                for c in collect(&w.addr, "transmittance", s).await? {
                    bytes += c.encoded_len() as u64;
                    reader.add(&c).map_err(|e| malformed(&w.addr, e))?;
                }
                let slab = reader.finish().map_err(|e| malformed(&w.addr, e))?;
                Ok((w.addr, slab, bytes))
            },
        )?;
        let received: u64 = replies.iter().map(|(_, _, b)| b).sum();
        let slabs: Vec<ColumnSlab> = replies.into_iter().map(|(_, s, _)| s).collect();
        // Each reader already refused, naming its worker, whatever does not
        // fit the spans the coordinator sent; `assemble` checks once more.
        let trans = Transmittance::assemble(frame, slabs.iter().cloned())
            .map_err(|e| malformed("workers", e))?;
        if self.draw.on_workers()
            && let Some(l) = self.lights.get_mut(light)
        {
            l.swept = Some(Arc::new(SweptMap::of_slabs(frame, slabs)));
        }
        let ms = t.elapsed().as_secs_f64() * 1e3;
        self.count(|x| {
            x.density_sent += sent;
            x.slabs_received += received;
        });
        self.clock(|x| x.transmittance_ms += ms);
        tracing::debug!(frame_id = id, light, "transmittance gathered");
        Ok(trans)
    }
}
