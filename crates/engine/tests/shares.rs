//! Drawing elsewhere: hair split into shares of whole groups, each
//! stepped, posed, filled, filtered, shaded and rasterized on its own (as
//! cluster workers do, here in one process), composited to the same bytes
//! as one process, frame after frame.

use std::ops::Range;
use std::path::Path;

use engine::{
    Animator, DrawJob, DrawReport, Drawing, Drawn, EngineError, Executor, FrameStats, PosePlan,
    PoseReport, Scene, Sequence, Share, StepPlan, Strands,
};
use shadow::{DensityMap, Fiber, FillStats, Transmittance};

/// The shares of a scene's hair, in this process.
#[derive(Debug)]
struct Shares {
    shares: Vec<Share>,
    fiber: Fiber,
    /// Each light's last sweep, as a slab of every column.
    maps: Vec<Option<(shadow::LightFrame, shadow::ColumnSlab)>>,
}

impl Shares {
    fn new(scene: &Scene, split: &[Range<usize>]) -> Shares {
        Shares {
            shares: split
                .iter()
                .map(|g| Share::new(scene, g.clone()).unwrap())
                .collect(),
            fiber: scene.fiber,
            maps: vec![None; scene.lights.len()],
        }
    }
}

impl Executor for Shares {
    fn simulate(
        &mut self,
        anim: &mut Animator,
        plan: &StepPlan,
        stats: &mut FrameStats,
    ) -> Result<Option<engine::PoseReport>, EngineError> {
        let per = anim.points_per_wisp();
        for s in &mut self.shares {
            let w = s.wisps();
            let accel = plan
                .accel
                .as_ref()
                .map(|a| a[w.start * per..w.end * per].to_vec());
            s.step(plan, accel.as_deref(), stats);
            for i in w {
                anim.set_wisp_state(i, s.animator().wisp_state(i).unwrap().clone())?;
            }
        }
        // Not posed: the frame asks Drawing::pose.
        Ok(None)
    }

    fn density(
        &mut self,
        _light: usize,
        map: &mut DensityMap,
        strands: Strands<'_>,
        fiber: &Fiber,
    ) -> Result<FillStats, EngineError> {
        let v = match strands {
            Strands::Held { posed }
            | Strands::Here {
                posed: Some(posed), ..
            } => posed,
            Strands::Here { posed: None, .. } => panic!("the shares fill posed hair"),
        };
        let mut total = FillStats::default();
        for s in &self.shares {
            total = total + s.deposit(v, map, fiber)?;
        }
        Ok(total)
    }

    fn transmittance(
        &mut self,
        light: usize,
        map: &DensityMap,
    ) -> Result<Transmittance, EngineError> {
        let frame = *map.frame();
        self.maps[light] = Some((frame, shadow::sweep(map, 0..frame.columns() as u32)));
        Ok(Transmittance::compute(map))
    }

    fn drawing(&mut self) -> Option<&mut dyn Drawing> {
        Some(self)
    }
}

impl Drawing for Shares {
    fn composites(&self) -> bool {
        false
    }

    fn pose(&mut self, plan: &PosePlan) -> Result<PoseReport, EngineError> {
        let reports = self
            .shares
            .iter_mut()
            .map(|s| s.pose(plan))
            .collect::<Result<Vec<_>, _>>()?;
        let (first, rest) = reports.split_first().unwrap();
        Ok(rest.iter().fold(first.clone(), |a, b| a.union(b)))
    }

    fn draw(&mut self, job: &DrawJob) -> Result<DrawReport, EngineError> {
        let maps: Vec<_> = if job.shadows {
            self.maps.iter().map(|m| m.clone().unwrap()).collect()
        } else {
            Vec::new()
        };
        let mut layers = Vec::new();
        for s in &mut self.shares {
            // Each share sees only the columns its own strands read.
            let mine: Vec<Transmittance> = maps
                .iter()
                .map(|(frame, slab)| {
                    let need = s.columns_read(job.version, frame, job.trilinear).unwrap();
                    Transmittance::assemble(*frame, [slab.keep(&need)]).unwrap()
                })
                .collect();
            let (layer, _) = s.draw(job, &mine)?;
            layers.push(layer);
        }
        let _ = &self.fiber;
        Ok(DrawReport {
            drawn: Drawn::Layers(layers),
            ..DrawReport::default()
        })
    }
}

fn scene(text: &str) -> Scene {
    Scene::from_toml_str(text, Path::new("shares.toml")).unwrap()
}

fn frames(scene: &Scene, split: Option<&[Range<usize>]>, n: usize) -> Vec<image::RgbImage> {
    let mut seq = Sequence::new(scene).unwrap();
    if let Some(split) = split {
        seq.set_executor(Box::new(Shares::new(scene, split)))
            .unwrap();
    }
    seq.expect_frames(n as u64);
    (0..n)
        .map(|_| seq.next_frame().unwrap().0.clone())
        .collect()
}

/// One share of all six groups, three even shares, and uneven ones.
#[allow(clippy::single_range_in_vec_init)]
const SPLITS: [&[Range<usize>]; 3] = [&[0..6], &[0..2, 2..4, 4..6], &[0..1, 1..5, 5..6]];

#[test]
fn a_dancing_simulated_groom_drawn_in_shares_is_the_same_bytes() {
    for extra in [
        "",
        "[effects]\nself_shadow = false\n",
        "[[light]]\ndirection = [0.9, -0.35, -0.25]\n[[light]]\ndirection = [-0.3, -1, 0.2]\n",
        "[shading]\nmodel = \"marschner\"\n",
        "[shading]\nmodel = \"marschner\"\neumelanin = 0.4\n[[light]]\ndirection = [0.9, -0.35, -0.25]\n[[light]]\ndirection = [-0.3, -1, 0.2]\n",
        "[shading]\nmodel = \"marschner\"\neumelanin = 0.3\n[effects]\nmultiple_scattering = true\n",
        // Strands of about a tenth of a pixel, every other one drawn: each
        // share draws the strands one process draws.
        "[fiber]\nwidth = 0.05\n[render]\nsimplify = 0.5\n",
    ] {
        let (extra, render) = extra.split_once("[render]\n").unwrap_or((extra, ""));
        let s = scene(&format!(
            "[hair]\nstrands_per_wisp = 3\n[render]\nwidth = 120\nheight = 80\n{render}[shadow]\ncells = 48\n\
             [animation]\nmotion = \"dance\"\n[dynamics]\nsettle = 0.1\n{extra}"
        ));
        let one = frames(&s, None, 4);
        assert!(one[3] != one[1], "the hair moves");
        for split in SPLITS {
            let shared = frames(&s, Some(split), 4);
            for (f, (a, b)) in one.iter().zip(&shared).enumerate() {
                assert!(a == b, "{extra:?} split {split:?}: frame {f} differs");
            }
        }
    }
}

#[test]
fn rigid_hair_on_a_moving_head_drawn_in_shares_is_the_same_bytes() {
    let s = scene(
        "[hair]\nstrands_per_wisp = 3\n[render]\nwidth = 120\nheight = 80\n[shadow]\ncells = 48\n\
         [effects]\ndynamics = false\n[animation]\nmotion = \"dance\"\n",
    );
    let one = frames(&s, None, 3);
    assert!(one[2] != one[0], "the head moves");
    for split in SPLITS {
        assert!(frames(&s, Some(split), 3) == one, "split {split:?}");
    }
}

/// Shares whose pictures are left to finish (as cluster workers composite
/// them) and, at the `fail`-th, fail to: that frame is drawn again.
#[derive(Debug)]
struct Unfinished {
    shares: Shares,
    /// Which call of `draw_ahead` leaves a picture that fails (from 1).
    fail: u64,
    calls: u64,
    /// The partial pictures of the frame last drawn ahead, by its version.
    kept: Option<(u64, Vec<raster::HairLayer>)>,
    redrawn: std::sync::Arc<std::sync::atomic::AtomicU32>,
}

impl Executor for Unfinished {
    fn simulate(
        &mut self,
        anim: &mut Animator,
        plan: &StepPlan,
        stats: &mut FrameStats,
    ) -> Result<Option<engine::PoseReport>, EngineError> {
        self.shares.simulate(anim, plan, stats)
    }

    fn density(
        &mut self,
        light: usize,
        map: &mut DensityMap,
        strands: Strands<'_>,
        fiber: &Fiber,
    ) -> Result<FillStats, EngineError> {
        self.shares.density(light, map, strands, fiber)
    }

    fn transmittance(
        &mut self,
        light: usize,
        map: &DensityMap,
    ) -> Result<Transmittance, EngineError> {
        self.shares.transmittance(light, map)
    }

    fn drawing(&mut self) -> Option<&mut dyn Drawing> {
        Some(self)
    }
}

impl Drawing for Unfinished {
    fn composites(&self) -> bool {
        false
    }

    fn pose(&mut self, plan: &PosePlan) -> Result<PoseReport, EngineError> {
        self.shares.pose(plan)
    }

    fn draw(&mut self, job: &DrawJob) -> Result<DrawReport, EngineError> {
        self.shares.draw(job)
    }

    fn draw_ahead(&mut self, job: &DrawJob) -> Result<DrawReport, EngineError> {
        let mut drawn = self.shares.draw(job)?;
        self.calls += 1;
        if self.calls == self.fail {
            let Drawn::Layers(layers) = std::mem::take(&mut drawn.drawn) else {
                panic!("the shares draw partial pictures");
            };
            self.kept = Some((job.version, layers));
            drawn.drawn = Drawn::Pending(engine::PendingPicture::new(|| {
                Err(EngineError::executor("a worker went away"))
            }));
        }
        Ok(drawn)
    }

    fn redraw(&mut self, job: &DrawJob) -> Result<DrawReport, EngineError> {
        // Later frames' stages ran since: the shares no longer hold this
        // frame's hair, but what they drew of it is kept.
        let (v, layers) = self.kept.take().expect("a frame drawn ahead failed");
        assert_eq!(v, job.version);
        self.redrawn
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        Ok(DrawReport {
            drawn: Drawn::Layers(layers),
            ..DrawReport::default()
        })
    }
}

#[test]
fn a_picture_that_fails_to_finish_is_drawn_again_on_its_own_head() {
    let s = scene(
        "[hair]\nstrands_per_wisp = 3\n[render]\nwidth = 120\nheight = 80\n[shadow]\ncells = 48\n\
         [animation]\nmotion = \"dance\"\n[dynamics]\nsettle = 0.1\n",
    );
    let one = frames(&s, None, 5);
    let redrawn = std::sync::Arc::new(std::sync::atomic::AtomicU32::new(0));
    let mut seq = Sequence::new(&s).unwrap();
    seq.set_executor(Box::new(Unfinished {
        shares: Shares::new(&s, &[0..2, 2..4, 4..6]),
        fail: 2,
        calls: 0,
        kept: None,
        redrawn: redrawn.clone(),
    }))
    .unwrap();
    // Each frame runs the next one's stages while its picture finishes:
    // the head the frame drawn again is composited on is its own frame's,
    // under its own frame's shadow.
    seq.expect_frames(5);
    for (f, want) in one.iter().enumerate() {
        assert!(seq.next_frame().unwrap().0 == want, "frame {f}");
    }
    assert_eq!(redrawn.load(std::sync::atomic::Ordering::Relaxed), 1);
}
