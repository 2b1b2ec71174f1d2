//! What crosses the wire when the workers sum and sweep a light's map
//! among themselves (a posed Density round with a [`ColumnPlan`]): the
//! plan, and the swept columns they send each other. Everything received
//! is checked before use.

use std::ops::Range;
use std::time::Duration;

use glam::Affine3A;
use shadow::{ColumnSlab, LightFrame};

use super::{Malformed, bad, draw_columns};
use crate::pb;

/// How the workers of one posed Density round sum and sweep a light's map
/// among themselves: reduce-scatter of the density to the columns' owners,
/// each sweeping its own columns, then all-gather of the swept columns.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ColumnPlan {
    /// The round, counted by the coordinator.
    pub round: u64,
    /// Worker `i` owns columns `cuts[i]..cuts[i + 1]`.
    pub cuts: Vec<u32>,
    /// This worker.
    pub own: usize,
    /// Each worker: its address and its session of this coordinator.
    pub peers: Vec<(String, String)>,
    /// How long a worker waits for the others' columns.
    pub wait: Duration,
    /// The name workers check each other's certificates for, with TLS.
    pub tls_domain: Option<String>,
    /// The head's transform, when the head casts shadow on the hair: each
    /// owner adds it to its columns before sweeping them.
    pub head: Option<Affine3A>,
}

impl ColumnPlan {
    /// Columns `0..columns` cut in contiguous ranges, worker `i` getting
    /// about `weights` of them summed over its range (each column at
    /// least 1).
    pub(crate) fn cuts(columns: usize, workers: usize, weight: impl Fn(usize) -> u64) -> Vec<u32> {
        let shares = engine::split_by(columns, workers, weight);
        let mut cuts: Vec<u32> = shares.iter().map(|r| r.start as u32).collect();
        cuts.push(columns as u32);
        cuts
    }

    /// Worker `i`'s columns.
    pub(crate) fn range(&self, i: usize) -> Range<usize> {
        self.cuts[i] as usize..self.cuts[i + 1] as usize
    }

    /// Workers in the round.
    pub(crate) fn workers(&self) -> usize {
        self.peers.len()
    }

    /// The plan as sent.
    pub(crate) fn to_pb(&self) -> pb::ColumnPlan {
        let mut head = Vec::new();
        if let Some(h) = &self.head {
            super::affine_to_floats(h, &mut head);
        }
        pb::ColumnPlan {
            round: self.round,
            cuts: self.cuts.clone(),
            own: self.own as u32,
            peers: self.peers.iter().map(|p| p.0.clone()).collect(),
            sessions: self.peers.iter().map(|p| p.1.clone()).collect(),
            wait_ms: self.wait.as_millis().min(u128::from(u32::MAX)) as u32,
            tls_domain: self.tls_domain.clone().unwrap_or_default(),
            head,
        }
    }

    /// A plan as sent, for a map of `columns` columns: 2 to
    /// [`super::MAX_WORKERS`] workers, each with an address and a session,
    /// cuts from 0 to `columns` that never fall, a wait of at most ten
    /// minutes, and no head or one finite transform.
    pub(crate) fn from_pb(p: &pb::ColumnPlan, columns: usize) -> Result<ColumnPlan, Malformed> {
        let n = p.peers.len();
        if !(2..=super::MAX_WORKERS).contains(&n) || p.sessions.len() != n {
            return Err(bad(format!(
                "a column plan of {n} workers and {} sessions (2 to {} workers, a session each)",
                p.sessions.len(),
                super::MAX_WORKERS
            )));
        }
        if p.own as usize >= n {
            return Err(bad(format!(
                "worker {} of a column plan of {n} workers",
                p.own
            )));
        }
        let ok = p.cuts.len() == n + 1
            && p.cuts.first() == Some(&0)
            && p.cuts.last() == Some(&(columns as u32))
            && p.cuts.windows(2).all(|w| w[0] <= w[1]);
        if !ok {
            return Err(bad(format!(
                "column cuts {:?} do not cut a map of {columns} columns among {n} workers",
                p.cuts
            )));
        }
        let long = |v: &String| v.is_empty() || v.len() > 256;
        if p.peers.iter().chain(&p.sessions).any(long) || p.tls_domain.len() > 256 {
            return Err(bad("a worker's address or session is empty or too long"));
        }
        if p.wait_ms > 600_000 {
            return Err(bad(format!("a wait of {} ms for the columns", p.wait_ms)));
        }
        let head = if p.head.is_empty() {
            None
        } else {
            Some(super::one_affine("the column plan's head", &p.head)?)
        };
        Ok(ColumnPlan {
            round: p.round,
            cuts: p.cuts.clone(),
            own: p.own as usize,
            peers: p
                .peers
                .iter()
                .cloned()
                .zip(p.sessions.iter().cloned())
                .collect(),
            wait: Duration::from_millis(u64::from(p.wait_ms)),
            tls_domain: (!p.tls_domain.is_empty()).then(|| p.tls_domain.clone()),
            head,
        })
    }
}

/// A worker's swept columns `slab` as Exchange chunks (light 0, no
/// frame: the receiver knows it), after the first chunk `first`.
pub(crate) fn swept_chunks(frame: &LightFrame, slab: &ColumnSlab) -> Vec<pb::DrawChunk> {
    let mut chunks = draw_columns(0, frame, std::slice::from_ref(slab), None);
    for c in &mut chunks {
        c.map = None;
    }
    chunks
}

/// Every worker's swept columns of one round, `owners` in worker order
/// (each its chunks, as [`swept_chunks`] made them), as one light's
/// transmittance in `frame`: each owner's columns checked to lie in its
/// range of `plan`.
pub(crate) fn assemble_swept(
    frame: LightFrame,
    plan: &ColumnPlan,
    owners: &[Vec<pb::DrawChunk>],
) -> Result<shadow::Transmittance, Malformed> {
    let mut reader = super::ColumnsReader::new(1);
    reader.add(&pb::DrawChunk {
        light: 0,
        map: Some(super::frame_to_pb(&frame)),
        ..Default::default()
    })?;
    for (i, chunks) in owners.iter().enumerate() {
        let range = plan.range(i);
        for c in chunks {
            if c.map.is_some() || c.light != 0 || c.job.is_some() || c.bands.is_some() {
                return Err(bad(format!(
                    "worker {i}'s swept columns carry a frame, a light, a job or a band plan"
                )));
            }
            reader.add_within(c, range.clone())?;
        }
    }
    let mut maps = reader.finish()?;
    Ok(maps.remove(0))
}
