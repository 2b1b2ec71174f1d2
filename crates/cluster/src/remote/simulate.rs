//! The coordinator's stage calls that move the hair: sharing the groups out (Assign), stepping the wisps (Simulate) and posing the drawn hair (Pose).

use super::*;

impl RemoteExecutor {
    /// Shares the groups out over the live workers, with the scene and
    /// the wisps' state gathered last.
    pub(super) fn assign(&mut self) -> Result<(), ClusterError> {
        let hair = self.hair()?;
        let weights = &hair.strands;
        let shares = split_by(weights.len(), self.workers.len(), |g| weights[g] + 1);
        let wisp_range = |g: &Range<usize>| match &hair.wisps {
            Some(w) => w[g.start] as usize..w[g.end] as usize,
            None => 0..0,
        };
        let files: Vec<(String, &[u8])> = self
            .source
            .files
            .iter()
            .map(|(p, b)| (p.to_string_lossy().into_owned(), &b[..]))
            .collect();
        let mut requests = Vec::with_capacity(shares.len());
        let mut sent = 0u64;
        // The only workers this session's workers may call.
        let peers: Vec<String> = self.workers.iter().map(|w| w.addr.clone()).collect();
        for (w, share) in self.workers.iter().zip(&shares) {
            let wisps = wisp_range(share);
            let mut text = wire::text_pieces(&self.source.text, wire::TEXT_PIECE_BYTES);
            let mut chunks = vec![pb::AssignChunk {
                scene_toml: text.next().unwrap_or_default().to_string(),
                scene_path: self.source.path.to_string_lossy().into_owned(),
                first_group: share.start as u32,
                end_group: share.end as u32,
                peers: peers.clone(),
                ..Default::default()
            }];
            chunks.extend(text.map(|t| pb::AssignChunk {
                scene_toml: t.to_string(),
                ..Default::default()
            }));
            if !wisps.is_empty() {
                let states = &hair.states[wisps.clone()];
                chunks.extend(wire::wisp_chunks(wisps.start, states).into_iter().map(|s| {
                    pb::AssignChunk {
                        state: Some(s),
                        ..Default::default()
                    }
                }));
            }
            for (path, bytes) in &files {
                for (i, piece) in bytes.chunks(1 << 20).enumerate() {
                    chunks.push(pb::AssignChunk {
                        file_path: if i == 0 { path.clone() } else { String::new() },
                        file_data: piece.to_vec(),
                        ..Default::default()
                    });
                }
            }
            sent += chunks.iter().map(|c| c.encoded_len() as u64).sum::<u64>();
            requests.push((w.clone(), (chunks, wisps)));
        }
        let (per, groups) = (hair.points_per_wisp as u32, weights.len() as u32);
        fan_out(
            &self.rt,
            requests,
            "assign",
            self.deadline,
            move |mut w, (chunks, wisps)| async move {
                let reply = w
                    .client
                    .assign(tokio_stream::iter(chunks))
                    .await
                    .map_err(|s| call_error(&w.addr, "assign", s))?
                    .into_inner();
                let theirs = reply.first_wisp as usize..reply.end_wisp as usize;
                if reply.groups != groups
                    || (!wisps.is_empty() && (reply.points_per_wisp != per || theirs != wisps))
                {
                    return Err(malformed(
                        &w.addr,
                        format!(
                            "the worker made {} groups, wisps {theirs:?} of {} guide points; the coordinator {groups} groups, wisps {wisps:?} of {per}",
                            reply.groups, reply.points_per_wisp
                        ),
                    ));
                }
                Ok(())
            },
        )?;
        tracing::info!(shares = ?shares, "groups assigned");
        self.count(|t| t.assign_sent += sent);
        self.shares = Some(shares);
        Ok(())
    }

    /// Assigns the shares after a loss and poses them again as last posed:
    /// the survivors then hold every strand as the lost worker held it.
    pub(super) fn ensure_posed(&mut self) -> Result<(), ClusterError> {
        if self.shares.is_none() {
            self.assign()?;
        }
        if self.posed.is_none()
            && let Some(plan) = self.last_pose.clone()
        {
            // The same hair as the frame was told of: its report stands.
            self.pose_call(&plan)?;
        }
        Ok(())
    }

    /// One Simulate call on every worker; the new states go into `anim` only when
    /// every worker answered. Each poses its share after the steps: the
    /// report of the whole pose comes back.
    pub(super) fn simulate(
        &mut self,
        anim: &mut Animator,
        plan: &StepPlan,
    ) -> Result<PoseReport, ClusterError> {
        if self.shares.is_none() {
            self.assign()?;
        }
        let shares = self.shares.clone().expect("assigned above");
        let hair = self.hair()?;
        let (per, lights) = (hair.points_per_wisp, plan.pose.lights.len());
        let wisps: Vec<Range<usize>> = shares
            .iter()
            .map(|g| match &hair.wisps {
                Some(w) => w[g.start] as usize..w[g.end] as usize,
                None => 0..0,
            })
            .collect();
        let mut base = pb::SimulateRequest {
            frame_id: plan.pose.version,
            has_accel: plan.accel.is_some(),
            pose: Some(wire::pose_plan_to_pb(&plan.pose)),
            ..Default::default()
        };
        for (h, b) in plan.heads.iter().zip(&plan.bodies) {
            wire::affine_to_floats(h, &mut base.heads);
            base.body_counts.push(b.len() as u32);
            wire::bodies_to_floats(b, &mut base.bodies);
        }
        let mut requests = Vec::with_capacity(shares.len());
        let mut sent = 0u64;
        for (w, share) in self.workers.iter().zip(&wisps) {
            let mut r = base.clone();
            if let Some(a) = &plan.accel {
                (r.accel_skip, r.accel) = wire::accel_to_pb(&a[share.start * per..share.end * per]);
            }
            sent += r.encoded_len() as u64;
            requests.push((w.clone(), (r, share.clone())));
        }
        let t = Instant::now();
        let replies = fan_out(
            &self.rt,
            requests,
            "step",
            self.deadline,
            move |mut w, (r, share)| async move {
                let s = w
                    .client
                    .simulate(r)
                    .await
                    .map_err(|s| call_error(&w.addr, "simulate", s))?
                    .into_inner();
                let chunks = collect(&w.addr, "simulate", s).await?;
                let mut states = Vec::with_capacity(share.len());
                let (mut bytes, mut compute, mut report) = (0u64, 0.0f64, None);
                for c in &chunks {
                    bytes += c.encoded_len() as u64;
                    compute += c.compute_ms;
                    states.extend(
                        wire::wisps_from_chunk(c, per, &share)
                            .map_err(|e| malformed(&w.addr, e))?,
                    );
                    if let Some(r) = &c.report {
                        report = Some(
                            wire::report_from_pb(r, lights).map_err(|e| malformed(&w.addr, e))?,
                        );
                    }
                }
                let in_order = states.iter().map(|(i, _)| *i).eq(share.clone());
                if !in_order {
                    return Err(malformed(
                        &w.addr,
                        format!("the states of wisps {share:?} did not come whole and in order"),
                    ));
                }
                let report = report.ok_or_else(|| {
                    malformed(&w.addr, "a Simulate reply without its pose's report")
                })?;
                Ok((w.addr, states, report, bytes, compute))
            },
        )?;
        let wall = t.elapsed().as_secs_f64() * 1e3;
        let mut received = 0u64;
        let mut slowest = 0.0f64;
        let mut reports = Vec::with_capacity(replies.len());
        let n = self.workers.len();
        for (addr, states, report, bytes, compute) in replies {
            received += bytes;
            slowest = slowest.max(compute);
            if let Some(i) = self.workers.iter().position(|w| w.addr == addr) {
                self.loads.stepped(i, n, compute);
            }
            for (i, state) in states {
                anim.set_wisp_state(i, state.clone())
                    .map_err(|e| malformed(&addr, e))?;
                if let Some(h) = &mut self.hair {
                    h.states[i] = state;
                }
            }
            reports.push(report);
        }
        self.count(|t| {
            t.step_sent += sent;
            t.wisps_received += received;
        });
        self.clock(|t| {
            t.step_wall_ms += wall;
            t.step_compute_ms += slowest;
        });
        self.posed_as(&plan.pose, reports)
    }

    /// Notes that the workers posed the hair as `plan` says: the report of
    /// the whole pose, their shares' reports joined.
    pub(super) fn posed_as(
        &mut self,
        plan: &PosePlan,
        reports: Vec<PoseReport>,
    ) -> Result<PoseReport, ClusterError> {
        let mut reports = reports.into_iter();
        let first = reports
            .next()
            .ok_or_else(|| ClusterError::Setup("no worker reported its pose".into()))?;
        self.posed = Some(plan.version);
        self.last_pose = Some(plan.clone());
        Ok(reports.fold(first, |a, b| a.union(&b)))
    }

    /// One Pose on every worker: the report of the whole pose.
    pub(super) fn pose_call(&mut self, plan: &PosePlan) -> Result<PoseReport, ClusterError> {
        let request = wire::pose_plan_to_pb(plan);
        let lights = plan.lights.len();
        let sent = request.encoded_len() as u64 * self.workers.len() as u64;
        let requests: Vec<_> = self
            .workers
            .iter()
            .map(|w| (w.clone(), request.clone()))
            .collect();
        let t = Instant::now();
        let replies = fan_out(
            &self.rt,
            requests,
            "pose",
            self.deadline,
            move |mut w, r| async move {
                let reply = w
                    .client
                    .pose(r)
                    .await
                    .map_err(|s| call_error(&w.addr, "pose", s))?
                    .into_inner();
                let bytes = reply.encoded_len() as u64;
                let report =
                    wire::report_from_pb(&reply, lights).map_err(|e| malformed(&w.addr, e))?;
                Ok((report, bytes))
            },
        )?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let received: u64 = replies.iter().map(|(_, b)| b).sum();
        self.count(|t| t.pose += sent + received);
        self.clock(|t| t.pose_ms += ms);
        self.posed_as(plan, replies.into_iter().map(|(r, _)| r).collect())
    }
}
