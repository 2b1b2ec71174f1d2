//! Building a session's share and turning its requests and replies into the engine's terms.

use super::memory::{Budget, Grant, share_bytes};
use super::session::Held;
use super::status::{invalid, status};
use crate::error::WorkerErrorKind as Kind;
use crate::{WorkerService, pb, wire};
use engine::{Scene, SceneSource, Share, StepPlan};
use shadow::{DensityMap, FillStats, LightFrame};
use std::ops::Range;
use std::sync::Mutex;
use tonic::Status;

/// A Density call's reply: a pooled map in `frame`, filled by `fill`, as
/// column chunks, the last one carrying the fill's counts and, for posed
/// strands, the columns their lookups read.
pub(super) fn density_reply(
    maps: &Mutex<Vec<DensityMap>>,
    frame: LightFrame,
    fill: impl FnOnce(&mut DensityMap) -> Result<(FillStats, Option<Vec<u64>>), Status>,
) -> Result<Vec<pb::ColumnChunk>, Status> {
    let mut map = WorkerService::map_in(maps, frame);
    let (stats, read) = fill(&mut map)?;
    let mut chunks = wire::column_chunks(&map, 0..frame.columns());
    WorkerService::give_back(maps, map);
    if let Some(c) = chunks.last_mut() {
        c.samples = stats.samples;
        c.out_of_map = stats.out_of_map;
        if let Some(read) = read {
            c.columns_read = wire::columns_to_pb(&read);
        }
    }
    Ok(chunks)
}

/// The state of the share's wisps, as chunks.
pub(super) fn share_chunks(share: &Share) -> Result<Vec<pb::WispChunk>, Status> {
    let wisps = share.wisps();
    let states: Option<Vec<_>> = wisps
        .clone()
        .map(|w| share.animator().wisp_state(w))
        .collect();
    let states = states.ok_or_else(|| status(Kind::Internal, "a wisp of the share is missing"))?;
    Ok(wire::wisp_chunks(wisps.start, states))
}

/// Builds the share an Assign call asks for (off the async threads: the
/// scene's hair is generated here). The share of `groups` of the scene `source` says, with wisp `states`:
/// `old` when it is of the same scene and groups, else a new one, whose
/// memory (estimated before it is built) joins `received` in the budget.
pub(super) fn build_share(
    old: Option<Held>,
    source: SceneSource,
    groups: Range<usize>,
    states: &[pb::WispChunk],
    memory: &Budget,
    mut received: Grant,
) -> Result<Held, Status> {
    let mut held = match old {
        Some(h) if h.source == source && h.share.groups() == groups => h,
        old => {
            drop(old);
            let scene = Scene::from_source(&source)
                .map_err(|e| status(Kind::Invalid, format!("the scene: {e}")))?;
            let bytes = share_bytes(&scene)
                .map_err(|e| status(Kind::Invalid, format!("the scene's hair: {e}")))?;
            memory.take(&mut received, bytes, "the scene's hair and picture")?;
            let share = Share::new(&scene, groups)
                .map_err(|e| status(Kind::Invalid, format!("the scene's hair: {e}")))?;
            Held {
                source,
                share,
                _memory: received,
            }
        }
    };
    let share = &mut held.share;
    let wisps = share.wisps();
    let per = share.animator().points_per_wisp();
    let mut seen = vec![false; wisps.len()];
    for c in states {
        for (w, state) in wire::wisps_from_chunk(c, per, &wisps).map_err(invalid)? {
            share
                .animator_mut()
                .set_wisp_state(w, state)
                .map_err(|e| status(Kind::Invalid, e.to_string()))?;
            seen[w - wisps.start] = true;
        }
    }
    if let Some(i) = seen.iter().position(|s| !s) {
        return Err(status(
            Kind::Invalid,
            format!("no state for wisp {}", wisps.start + i),
        ));
    }
    Ok(held)
}

/// A Simulate request as a plan for `share`: the worker's accelerations apart.
pub(super) fn step_plan(
    r: &pb::SimulateRequest,
    share: &Share,
) -> Result<(StepPlan, Option<Vec<glam::Vec3>>), wire::Malformed> {
    let heads = wire::affines_from_floats(&r.heads)?;
    if r.body_counts.len() != heads.len() {
        return Err(wire::Malformed(format!(
            "{} steps with {} body counts",
            heads.len(),
            r.body_counts.len()
        )));
    }
    let all = wire::bodies_from_floats(&r.bodies)?;
    let total: u64 = r.body_counts.iter().map(|&c| u64::from(c)).sum();
    if total != all.len() as u64 {
        return Err(wire::Malformed(format!(
            "body counts add up to {total}, {} bodies came",
            all.len()
        )));
    }
    let mut at = 0;
    let bodies = r
        .body_counts
        .iter()
        .map(|&c| {
            let b = all[at..at + c as usize].to_vec();
            at += c as usize;
            b
        })
        .collect();
    let points = share.wisps().len() * share.animator().points_per_wisp();
    // The work the call asks for: every guide point of the share at
    // every time step, against every body.
    let work = wire::step_work(points as u64, heads.len() as u64, total);
    if work > wire::MAX_STEP_WORK {
        return Err(wire::Malformed(format!(
            "{} time steps of {points} guide points and {total} bodies: about {:.0} s of one \
             core, more than the {:.0} s one call may take (wire::MAX_STEP_WORK)",
            heads.len(),
            work as f64 * 1e-9,
            wire::MAX_STEP_WORK as f64 * 1e-9
        )));
    }
    let accel = if r.has_accel {
        Some(wire::accel_from_pb(&r.accel_skip, &r.accel, points)?)
    } else {
        None
    };
    let pose = r
        .pose
        .as_ref()
        .ok_or_else(|| wire::Malformed("a Simulate call without its pose".into()))?;
    let plan = StepPlan {
        heads,
        bodies,
        accel: None,
        pose: wire::pose_plan_from_pb(pose)?,
    };
    Ok((plan, accel))
}
