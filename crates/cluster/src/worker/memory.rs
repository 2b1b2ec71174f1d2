//! The worker's memory budgets: what calls and sessions may hold.

use super::status::status;
use crate::error::WorkerErrorKind as Kind;
use engine::Scene;
use shadow::{DensityMap, LightFrame};
use std::sync::Arc;
use tonic::Status;

/// Memory is budgeted in granules of 64 KiB.
pub(super) const GRANULE: u64 = 1 << 16;

/// Bytes a received point costs until its call ends: its coordinates, and
/// their copy in map coordinates while it is deposited.
pub(super) const POINT_BYTES: u64 = 24;

/// Bytes a received strand costs until its call ends: its offset, and
/// its range along the light while it is deposited.
pub(super) const STRAND_BYTES: u64 = 12;

/// A memory budget: the worker's (`--max-memory-mib`) or one session's
/// (`--max-session-memory-mib`). It counts every density map a call
/// holds, every strand and swept column a call receives, and each
/// session's scene, data files, wisp states and share of the hair. A map
/// waits for room (a call holding one finishes without asking for more);
/// received data that does not fit is refused with RESOURCE_EXHAUSTED.
#[derive(Debug, Clone)]
pub(super) struct Memory {
    pub(super) free: Arc<tokio::sync::Semaphore>,
    pub(super) total: u64,
    /// Whose budget, as its messages say it.
    pub(super) whose: &'static str,
    pub(super) flag: &'static str,
}

pub(super) type Held64k = tokio::sync::OwnedSemaphorePermit;

impl Memory {
    pub(super) fn new(total: u64, whose: &'static str, flag: &'static str) -> Memory {
        let units = (total / GRANULE).min(tokio::sync::Semaphore::MAX_PERMITS as u64);
        Memory {
            free: Arc::new(tokio::sync::Semaphore::new(units as usize)),
            total: units * GRANULE,
            whose,
            flag,
        }
    }

    pub(super) fn units(bytes: u64) -> u32 {
        bytes.div_ceil(GRANULE).min(u64::from(u32::MAX)) as u32
    }

    pub(super) fn too_much(&self, bytes: u64, what: &str) -> Status {
        status(
            Kind::Exhausted,
            format!(
                "{what} would take {} MiB of {} memory budget of {} MiB, \
             of which {} MiB are free ({})",
                bytes.div_ceil(1 << 20),
                self.whose,
                self.total >> 20,
                (self.free.available_permits() as u64 * GRANULE) >> 20,
                self.flag
            ),
        )
    }

    /// Waits until `bytes` fit; held until dropped. More than the whole
    /// budget is refused.
    pub(super) async fn wait_for(&self, bytes: u64, what: &str) -> Result<Held64k, Status> {
        if bytes > self.total {
            return Err(self.too_much(bytes, what));
        }
        self.free
            .clone()
            .acquire_many_owned(Memory::units(bytes))
            .await
            .map_err(|_| status(Kind::Unavailable, "the worker is stopping"))
    }

    /// Takes `bytes` now, into `held`, or refuses.
    pub(super) fn take(
        &self,
        held: &mut Option<Held64k>,
        bytes: u64,
        what: &str,
    ) -> Result<(), Status> {
        if bytes == 0 {
            return Ok(());
        }
        let p = self
            .free
            .clone()
            .try_acquire_many_owned(Memory::units(bytes))
            .map_err(|_| self.too_much(bytes, what))?;
        match held {
            Some(h) => h.merge(p),
            None => *held = Some(p),
        }
        Ok(())
    }
}

/// What a call may take: from its session's budget and the worker's.
#[derive(Debug, Clone)]
pub(super) struct Budget {
    pub(super) session: Memory,
    pub(super) worker: Memory,
}

/// Memory a [`Budget`] granted, given back when dropped.
#[derive(Debug, Default)]
pub(super) struct Grant {
    pub(super) _session: Option<Held64k>,
    pub(super) _worker: Option<Held64k>,
}

impl Budget {
    /// Takes `bytes` now, into `grant`, or refuses naming the budget.
    pub(super) fn take(&self, grant: &mut Grant, bytes: u64, what: &str) -> Result<(), Status> {
        self.session.take(&mut grant._session, bytes, what)?;
        self.worker.take(&mut grant._worker, bytes, what)
    }

    /// A map in `frame`, once it fits both.
    pub(super) async fn map(&self, frame: &LightFrame) -> Result<Grant, Status> {
        let what = format!("a density map of {}^3 cells", frame.n_cells);
        let bytes = DensityMap::bytes_for(frame.n_cells);
        let session = self.session.wait_for(bytes, &what).await?;
        let worker = self.worker.wait_for(bytes, &what).await?;
        Ok(Grant {
            _session: Some(session),
            _worker: Some(worker),
        })
    }
}

/// What a share of a scene may come to hold, estimated before it is built
/// from the scene's drawn segments and picture:
/// `SHARE_BYTES_PER_SEGMENT * segments + CANVAS_BYTES_PER_PIXEL * pixels`.
pub(super) fn share_bytes(scene: &Scene) -> Result<u64, engine::EngineError> {
    let pixels = u64::from(scene.render.width) * u64::from(scene.render.height);
    Ok(engine::drawn_segments(scene)? * SHARE_BYTES_PER_SEGMENT + pixels * CANVAS_BYTES_PER_PIXEL)
}

/// Bytes a drawn segment of the scene costs a worker's share, at most:
/// the whole hair at rest and posed (every share keeps the scene's
/// animator), and the share's own vertices' transmittance, colours and
/// screen vertices. Measured: see the worker's memory test.
pub(super) const SHARE_BYTES_PER_SEGMENT: u64 = 256;

/// Bytes a picture's pixel costs a worker's share: its partial picture's
/// sums and marks, the opaque depth and colour it draws behind.
pub(super) const CANVAS_BYTES_PER_PIXEL: u64 = 48;
