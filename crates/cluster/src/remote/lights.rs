//! What the coordinator keeps of each light's map between calls: where
//! the workers' columns are, and the last sweep.

use std::sync::Arc;

use shadow::{ColumnSlab, DensityMap, LightFrame};

/// A light's last sweep: its frame and slabs.
pub(super) type Swept = Arc<SweptMap>;

/// What the coordinator keeps of one light's map between calls.
#[derive(Debug, Clone, Default)]
pub(super) struct LightState {
    /// The columns each live worker's lookups read (from its last posed
    /// Density), in worker order.
    pub(super) reads: Option<Vec<Vec<u64>>>,
    /// The frame and slabs of its last sweep.
    pub(super) swept: Option<Swept>,
    /// The hair version whose map the live workers last summed and swept
    /// among themselves (each holding every column for its Draw).
    pub(super) exchanged: Option<u64>,
    /// The hair version whose map's transmittance came from the workers'
    /// own sweep (the frame's shadow map, not another map filled on the
    /// workers such as a separate self-collision map).
    pub(super) swept_on_workers: Option<u64>,
    /// Each column's weight in the last map (its occupied cells), for
    /// cutting the next map's columns among the workers.
    pub(super) column_weights: Option<Vec<u32>>,
}

impl LightState {
    /// Forgets what depended on the workers as they were (after a loss
    /// or a restore): where their columns are.
    pub(super) fn forget_workers(&mut self) {
        self.reads = None;
        self.exchanged = None;
        self.swept_on_workers = None;
    }
}

/// A light's last sweep: its frame and slabs, or (when the workers summed
/// and swept it among themselves) the summed map, swept here only if a
/// frame must be drawn from it through the coordinator.
#[derive(Debug)]
pub(super) struct SweptMap {
    frame: LightFrame,
    slabs: std::sync::OnceLock<Vec<ColumnSlab>>,
    map: Option<DensityMap>,
}

impl SweptMap {
    pub(super) fn of_slabs(frame: LightFrame, slabs: Vec<ColumnSlab>) -> SweptMap {
        SweptMap {
            frame,
            slabs: std::sync::OnceLock::from(slabs),
            map: None,
        }
    }

    pub(super) fn of_map(map: DensityMap) -> SweptMap {
        SweptMap {
            frame: *map.frame(),
            slabs: std::sync::OnceLock::new(),
            map: Some(map),
        }
    }

    /// The frame and its slabs (of every column).
    pub(super) fn get(&self) -> (&LightFrame, &[ColumnSlab]) {
        let slabs = self.slabs.get_or_init(|| {
            let map = self.map.as_ref().expect("a sweep has its slabs or its map");
            vec![shadow::sweep(map, 0..self.frame.columns() as u32)]
        });
        (&self.frame, slabs)
    }
}
