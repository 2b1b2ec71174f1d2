//! The Transmittance call: the columns a coordinator sends swept, slab by
//! slab.

use shadow::ColumnSlab;
use tonic::{Request, Response, Status, Streaming};

use super::Chunks;
use super::status::{cancelled, first_message, invalid, logged, status, stop_switch, stream_of};
use crate::error::WorkerErrorKind as Kind;
use crate::tls::Caller;
use crate::{WorkerService, pb, wire};

impl WorkerService {
    pub(super) async fn transmittance_call(
        &self,
        req: Request<Streaming<pb::ColumnChunk>>,
    ) -> Result<Response<Chunks<pb::SlabChunk>>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Coordinator)?;
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Transmittance").await?;
            let frame = wire::frame_from_pb(first.map.as_ref()).map_err(invalid)?;
            let (lo, hi) = (first.first_column, first.end_column);
            if lo > hi || hi as usize > frame.columns() {
                return Err(status(
                    Kind::Invalid,
                    format!("columns {lo}..{hi} in a map of {} columns", frame.columns()),
                ));
            }
            let maps = session.maps.clone();
            let budget = self.budget(&session).map(&frame).await?;
            // On an error the map is dropped (the pool makes another).
            let mut map = WorkerService::map_in(&maps, frame);
            wire::merge_columns(&mut map, &first).map_err(invalid)?;
            while let Some(c) = stream.message().await? {
                wire::merge_columns(&mut map, &c).map_err(invalid)?;
            }
            // The sweep stops between runs of columns once the call is gone.
            let (_stop_on_drop, go) = stop_switch();
            let chunks = tokio::task::spawn_blocking(move || {
                let slab: Option<ColumnSlab> = shadow::sweep_while(&map, lo..hi, go);
                WorkerService::give_back(&maps, map);
                drop(budget);
                slab.map(|s| wire::slab_chunks(&s))
                    .ok_or_else(|| cancelled("Transmittance"))
            })
            .await
            .map_err(|e| status(Kind::Internal, format!("sweep task failed: {e}")))??;
            tracing::debug!(
                frame_id = first.frame_id,
                light = first.light,
                columns = hi - lo,
                "sweep done"
            );
            Ok(Response::new(stream_of(chunks)))
        };
        logged(peer, "Transmittance", served.await)
    }
}
