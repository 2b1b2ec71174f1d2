//! The Simulate and Pose calls: the share's wisps stepped as a frame's plan
//! says, and its drawn strands posed and reported on.

use engine::FrameStats;
use tonic::{Request, Response, Status};

use super::Chunks;
use super::session::with_share;
use super::share::{share_chunks, step_plan};
use super::status::{invalid, logged, refused, status, stop_switch, stream_of};
use crate::error::WorkerErrorKind as Kind;
use crate::tls::Caller;
use crate::{WorkerService, pb, wire};

impl WorkerService {
    pub(super) async fn simulate_call(
        &self,
        req: Request<pb::SimulateRequest>,
    ) -> Result<Response<Chunks<pb::WispChunk>>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Coordinator)?;
            let r = req.into_inner();
            // Set when this call is dropped (cancelled, or past its deadline):
            // the steps stop at the next one and the share is free again.
            let (_stop_on_drop, go) = stop_switch();
            let chunks = with_share(&session.held, move |share| {
                let start = std::time::Instant::now();
                let (plan, accel) = step_plan(&r, share).map_err(invalid)?;
                let mut stats = FrameStats::new(r.frame_id, 0.0);
                if !share.step_while(&plan, accel.as_deref(), &mut stats, go) {
                    return Err(status(
                        Kind::Cancelled,
                        format!(
                            "the Simulate call was cancelled after {} of {} time steps",
                            stats.steps,
                            plan.heads.len()
                        ),
                    ));
                }
                let report = share.pose(&plan.pose).map_err(refused)?;
                let mut chunks = share_chunks(share)?;
                if let Some(c) = chunks.last_mut() {
                    c.compute_ms = start.elapsed().as_secs_f64() * 1e3;
                    c.report = Some(wire::report_to_pb(&report));
                }
                tracing::debug!(
                    frame_id = r.frame_id,
                    version = plan.pose.version,
                    steps = stats.steps,
                    "step done"
                );
                Ok(chunks)
            })
            .await?;
            Ok(Response::new(stream_of(chunks)))
        };
        logged(peer, "Simulate", served.await)
    }

    pub(super) async fn pose_call(
        &self,
        req: Request<pb::PosePlan>,
    ) -> Result<Response<pb::PoseReport>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Coordinator)?;
            let plan = wire::pose_plan_from_pb(&req.into_inner()).map_err(invalid)?;
            let report = with_share(&session.held, move |share| {
                share.pose(&plan).map_err(refused)
            })
            .await?;
            Ok(Response::new(wire::report_to_pb(&report)))
        };
        logged(peer, "Pose", served.await)
    }
}
