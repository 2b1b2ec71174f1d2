//! What a session's Density rounds with a column plan leave for its Draw:
//! the transmittance swept among the workers, light by light.

use std::sync::Mutex;
use std::time::{Duration, Instant};

use super::memory::Grant;

/// The transmittance a session's workers swept among themselves for one
/// hair version, light by light, until its Draw takes it (with its memory).
#[derive(Debug, Default)]
pub(super) struct SweptHere {
    pub(super) version: u64,
    pub(super) maps: Vec<Option<(shadow::Transmittance, Grant)>>,
    /// Per light, whether its round is still gathering.
    pub(super) pending: Vec<bool>,
    /// The first round of the version that failed.
    pub(super) failed: Option<String>,
}

/// The transmittance each Density round with a column plan leaves for the
/// Draw of its hair version, light by light, as the rounds finish.
#[derive(Debug, Default)]
pub(super) struct SweptStore {
    pub(super) state: Mutex<SweptHere>,
    pub(super) ready: std::sync::Condvar,
}

impl SweptStore {
    /// A round of hair `version`, light `light`, begins.
    pub(super) fn begin(&self, version: u64, light: usize) {
        if let Ok(mut st) = self.state.lock() {
            if st.version != version {
                *st = SweptHere {
                    version,
                    ..Default::default()
                };
            }
            if st.maps.len() <= light {
                st.maps.resize_with(light + 1, || None);
                st.pending.resize(light + 1, false);
            }
            st.maps[light] = None;
            st.pending[light] = true;
        }
    }

    /// The round of `version`, `light` ended with `result`.
    pub(super) fn end(
        &self,
        version: u64,
        light: usize,
        result: Result<(shadow::Transmittance, Grant), String>,
    ) {
        if let Ok(mut st) = self.state.lock()
            && st.version == version
            && light < st.maps.len()
        {
            st.pending[light] = false;
            match result {
                Ok(m) => st.maps[light] = Some(m),
                Err(e) => {
                    tracing::warn!(version, light, error = %e, "the swept columns were not gathered");
                    st.failed.get_or_insert(e);
                }
            }
            self.ready.notify_all();
        }
    }

    /// Every light's transmittance of hair `version`, `lights` of them,
    /// once the rounds gathered them (waiting at most `wait`), and their
    /// memory; why not otherwise.
    #[allow(clippy::type_complexity)]
    pub(super) fn take(
        &self,
        version: u64,
        lights: usize,
        wait: Duration,
    ) -> Result<(Vec<shadow::Transmittance>, Vec<Grant>), String> {
        let until = Instant::now() + wait;
        let mut st = self.state.lock().map_err(|_| "worker state poisoned")?;
        loop {
            if st.version != version || st.maps.len() != lights {
                return Err(format!(
                    "no columns of all {lights} lights summed here for hair version {version}"
                ));
            }
            if let Some(e) = &st.failed {
                return Err(e.clone());
            }
            if st.maps.iter().all(Option::is_some) {
                st.pending.clear();
                return Ok(st.maps.drain(..).map(|m| m.expect("checked")).unzip());
            }
            if !st.pending.iter().any(|&p| p) {
                return Err("a light's columns were not summed here".into());
            }
            let now = Instant::now();
            if now >= until {
                return Err(format!(
                    "the other workers' swept columns did not come within {} ms",
                    wait.as_millis()
                ));
            }
            st = self
                .ready
                .wait_timeout(st, (until - now).min(Duration::from_millis(50)))
                .map_err(|_| "worker state poisoned")?
                .0;
        }
    }
}
