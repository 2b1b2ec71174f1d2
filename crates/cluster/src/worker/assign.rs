//! The Assign call: a session's share of the hair, built from the scene's
//! source the coordinator streams, within the memory budgets; the peers it
//! names kept once the share is made.

use engine::SceneSource;
use tonic::{Request, Response, Status, Streaming};

use super::memory::Grant;
use super::share::build_share;
use super::status::{first_message, logged, poisoned, status};
use crate::error::WorkerErrorKind as Kind;
use crate::tls::Caller;
use crate::{WorkerService, pb, wire};

impl WorkerService {
    pub(super) async fn assign_call(
        &self,
        req: Request<Streaming<pb::AssignChunk>>,
    ) -> Result<Response<pb::AssignReply>, Status> {
        let peer = req.remote_addr();
        let served = async move {
            let session = self.session(&req, Caller::Coordinator)?;
            let mut stream = req.into_inner();
            let first = first_message(&mut stream, "Assign").await?;
            let groups = first.first_group as usize..first.end_group as usize;
            let path = first.scene_path.clone();
            if first.peers.len() > wire::MAX_WORKERS
                || first.peers.iter().any(|p| p.len() > wire::MAX_ADDR_BYTES)
            {
                return Err(status(
                    Kind::Invalid,
                    format!(
                        "at most {} peers of at most {} bytes each (wire::MAX_WORKERS)",
                        wire::MAX_WORKERS,
                        wire::MAX_ADDR_BYTES
                    ),
                ));
            }
            // The peers of the Assign before are forgotten, and this one's
            // are kept only once its share is made: a refused Assign names
            // no one this worker will call.
            session.peers.lock().map_err(poisoned)?.clear();
            *session.picture.lock().map_err(poisoned)? = None;
            let peers = first.peers.clone();
            let mut text = String::new();
            let mut states: Vec<pb::WispChunk> = Vec::new();
            let mut files: Vec<(String, Vec<u8>)> = Vec::new();
            // What the call has made this worker keep, checked before each
            // chunk is kept.
            let (mut file_bytes, mut state_floats) = (0usize, 0usize);
            // What the Assign received, in the memory budget; kept with the
            // share it makes.
            let mut received = Grant::default();
            let memory = self.budget(&session);
            let mut take = |c: pb::AssignChunk| -> Result<(), Status> {
                // The scene text may come in pieces, one a chunk.
                if text.len() + c.scene_toml.len() > wire::MAX_SCENE_TEXT {
                    return Err(status(
                        Kind::Exhausted,
                        format!(
                            "a scene of more than {} bytes (wire::MAX_SCENE_TEXT)",
                            wire::MAX_SCENE_TEXT
                        ),
                    ));
                }
                let bytes = c.scene_toml.len() + c.file_data.len() + c.file_path.len();
                let floats = c.state.as_ref().map_or(0, |w| w.pos.len() + w.prev.len());
                memory.take(
                    &mut received,
                    (bytes + 4 * floats) as u64,
                    "the Assign's scene, data files and wisp states",
                )?;
                text.push_str(&c.scene_toml);
                file_bytes += c.file_data.len() + c.file_path.len();
                if file_bytes > wire::MAX_FILE_BYTES {
                    return Err(status(
                        Kind::Exhausted,
                        format!(
                            "data files of more than {} bytes (wire::MAX_FILE_BYTES)",
                            wire::MAX_FILE_BYTES
                        ),
                    ));
                }
                state_floats += floats;
                if state_floats > wire::MAX_STATE_FLOATS {
                    return Err(status(
                        Kind::Exhausted,
                        format!(
                            "wisp states of more than {} values (wire::MAX_STATE_FLOATS)",
                            wire::MAX_STATE_FLOATS
                        ),
                    ));
                }
                states.extend(c.state);
                if !c.file_path.is_empty() {
                    files.push((c.file_path, Vec::new()));
                }
                if !c.file_data.is_empty() {
                    let (_, data) = files
                        .last_mut()
                        .ok_or_else(|| status(Kind::Invalid, "file data before any file's path"))?;
                    data.extend_from_slice(&c.file_data);
                }
                Ok(())
            };
            take(first)?;
            while let Some(c) = stream.message().await? {
                take(c)?;
            }
            let mut source = SceneSource {
                text: text.into(),
                path: path.into(),
                files: Default::default(),
            };
            for (path, data) in files {
                source.files.insert(path.into(), data.into());
            }
            let held = session.held.clone();
            let reply = tokio::task::spawn_blocking(move || {
                let mut slot = held.lock().map_err(poisoned)?;
                let h = build_share(slot.take(), source, groups, &states, &memory, received)?;
                let anim = h.share.animator();
                let wisps = h.share.wisps();
                let picture = h.share.picture_size();
                let reply = pb::AssignReply {
                    points_per_wisp: anim.points_per_wisp() as u32,
                    groups: anim.groups().count() as u32,
                    first_wisp: wisps.start as u32,
                    end_wisp: wisps.end as u32,
                };
                tracing::info!(groups = ?h.share.groups(), wisps = ?wisps, "share assigned");
                *slot = Some(h);
                Ok::<_, Status>((reply, picture))
            })
            .await
            .map_err(|e| status(Kind::Internal, format!("assign task failed: {e}")))??;
            let (reply, picture) = reply;
            *session.peers.lock().map_err(poisoned)? = peers;
            *session.picture.lock().map_err(poisoned)? = Some(picture);
            Ok(Response::new(reply))
        };
        logged(peer, "Assign", served.await)
    }
}
