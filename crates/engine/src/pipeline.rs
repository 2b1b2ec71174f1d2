//! Running the shadow stages for each light.

use std::sync::Arc;

use glam::{Affine3A, Vec3};
use shadow::{Extent, Fiber, FillStats, Light, Occluder, ShadowInput, ShadowMethod};
use strands::Hair;

use crate::{EngineError, Executor, Head, LocalExecutor, Scene, Strands};

/// How far off an opaque surface its lookups of the hair's shadow go,
/// along its normal, in map cells (see
/// [`ShadowPipeline::transmittance_off_surface`]).
pub(crate) const HEAD_NORMAL_BIAS: f32 = 1.5;

/// How far towards the light an opaque surface's lookups go, in map
/// cells, past the rounding of its deposit's front.
pub(crate) const HEAD_LIGHT_BIAS: f32 = 0.5;

/// With the density map's contact shadows, an opaque surface's lookups go
/// this fraction of [`HEAD_NORMAL_BIAS`] and [`HEAD_LIGHT_BIAS`] off it:
/// its contact ray then counts the hair lying on it, exactly (the
/// exact reference, on its grid of 512 columns, goes a quarter of a
/// 128^3 map's cells off). Measured against Blender Cycles on the
/// point-lit groom (mesh head, 128^3, contact 2 cells), block error at
/// 1, 0.5, 0.25 and 0.1: 0.075, 0.059, 0.049, 0.053.
pub(crate) const HEAD_CONTACT_SCALE: f32 = 0.25;

/// The three shadow stages for every light of a scene, by the scene's
/// method. Each light owns its method's maps.
///
/// With the density-map method, the filling of the map and the sweep of its
/// columns go through an [`Executor`]: in this process, or on cluster
/// workers. Either gives the same bytes.
#[derive(Debug)]
pub struct ShadowPipeline {
    fiber: Fiber,
    /// The head, drawn by the renderer; with head shadows on, also the
    /// one occluder.
    head: Option<Head>,
    head_shadow: bool,
    occluders: Vec<Occluder>,
    lights: Vec<LightState>,
}

#[derive(Debug)]
struct LightState {
    light: Light,
    method: ShadowMethod,
}

impl ShadowPipeline {
    /// One method per light of `scene`, nothing built yet.
    pub fn new(scene: &Scene) -> Result<ShadowPipeline, EngineError> {
        // The exact reference weighs a fiber's rays by the light each
        // part of its width sends to the eye: the physically based
        // fiber's lobes are narrow across it. Kajiya-Kay's fiber is the
        // same across its width.
        let across: Option<Arc<dyn shadow::AcrossFiber>> = match &scene.shading.model {
            raster::ShadingModel::Marschner { optics, .. } => {
                Some(Arc::new(FiberWidth::new(optics)))
            }
            raster::ShadingModel::KajiyaKay => None,
        };
        let lights = scene
            .lights
            .iter()
            .map(|&light| {
                let mut method = ShadowMethod::new(&scene.shadow.method)?;
                method.set_across(across.clone());
                Ok(LightState { light, method })
            })
            .collect::<Result<_, EngineError>>()?;
        let head = scene
            .head
            .as_ref()
            .map(|h| Head::load(h, scene))
            .transpose()?;
        let mut p = ShadowPipeline {
            fiber: scene.fiber,
            head,
            // A head casts shadow on hair only with head shadows on.
            head_shadow: scene.effects.head_shadow,
            occluders: Vec::new(),
            lights,
        };
        p.set_head_pose(Affine3A::IDENTITY);
        Ok(p)
    }

    /// Moves the head (drawn, and as an occluder when it is one) to
    /// `pose`, the head motion's transform.
    pub fn set_head_pose(&mut self, pose: Affine3A) {
        if let Some(h) = &mut self.head {
            h.set_pose(pose);
            self.occluders.clear();
            if self.head_shadow {
                self.occluders.push(h.occluder());
            }
        }
    }

    /// The head as it stands now.
    pub fn head(&self) -> Option<&Head> {
        self.head.as_ref()
    }

    /// The head motion's transform the head stands under now.
    pub fn head_pose(&self) -> Affine3A {
        self.head.as_ref().map_or(Affine3A::IDENTITY, Head::pose)
    }

    /// The density map of the first light, when the method fills one and
    /// has been built.
    pub fn density_map(&self) -> Option<&shadow::DensityMap> {
        self.lights.first().and_then(|l| l.method.density_map())
    }

    /// Lights.
    pub fn light_count(&self) -> usize {
        self.lights.len()
    }

    /// Stage 1: samples the hair (and the head) from each light: for the
    /// density map, fits the map to them and fills it. Returns the samples
    /// over all lights.
    pub fn density(&mut self, hair: &Hair) -> Result<FillStats, EngineError> {
        let strands = Strands::Here { hair, posed: None };
        self.shadow_density(strands, None, &mut LocalExecutor)
    }

    /// [`Self::density_with`] for the frame's shadows (not a fill for the
    /// self-collisions alone): with hair here, also prepares the density
    /// map's contact shadows from it ([`Self::contact`]).
    pub fn shadow_density(
        &mut self,
        strands: Strands<'_>,
        extents: Option<(Vec3, &[Extent])>,
        ex: &mut dyn Executor,
    ) -> Result<FillStats, EngineError> {
        let stats = self.density_with(strands, extents, ex)?;
        if let Strands::Here { hair, .. } = strands {
            self.contact(hair)?;
        }
        Ok(stats)
    }

    /// The density map's contact shadows (`shadow.contact`), after
    /// [`Self::density_with`] filled the maps of the frame's shadows:
    /// prepares each light's contact rays from `hair`, every drawn
    /// strand; nothing without them. Part of the density stage.
    pub fn contact(&mut self, hair: &Hair) -> Result<(), EngineError> {
        for l in &mut self.lights {
            if let ShadowMethod::DensityMap(m) = &mut l.method
                && m.contact() > 0.0
            {
                m.contact_with(&ShadowInput {
                    light: &l.light,
                    hair,
                    fiber: &self.fiber,
                    occluders: &self.occluders,
                    extent: None,
                })?;
            }
        }
        Ok(())
    }

    /// [`Self::density`] of `strands` with the density map filled through
    /// `ex` (see [`Executor::density`]); the maps are fitted to `extents`
    /// (one per light, measured from the anchor) when given, else to the
    /// hair's points (hair held elsewhere needs its extents, and the
    /// density map's method).
    pub fn density_with(
        &mut self,
        strands: Strands<'_>,
        extents: Option<(Vec3, &[Extent])>,
        ex: &mut dyn Executor,
    ) -> Result<FillStats, EngineError> {
        let mut total = FillStats::default();
        for (i, l) in self.lights.iter_mut().enumerate() {
            let extent = extents.map(|(a, e)| (a, e[i]));
            let (fiber, occluders) = (&self.fiber, &self.occluders[..]);
            let stats = match (&mut l.method, strands) {
                (ShadowMethod::DensityMap(m), _) => {
                    let frame = match (extent, strands) {
                        (Some(e), _) => shadow::fit_to_extent(&l.light, occluders, e, m.cells())?,
                        (None, Strands::Here { hair, .. }) => ShadowInput {
                            light: &l.light,
                            hair,
                            fiber,
                            occluders,
                            extent: None,
                        }
                        .fit(m.cells())?,
                        (None, Strands::Held { .. }) => return Err(held_needs("its extents")),
                    };
                    // Contact shadows read every fiber near a drawn point.
                    if let Strands::Held { .. } = strands
                        && m.contact() > 0.0
                    {
                        return Err(held_needs("no contact shadows (shadow.contact = 0)"));
                    }
                    m.density_with(frame, occluders, |map| ex.density(i, map, strands, fiber))?
                }
                (other, Strands::Here { hair, .. }) => other.density(&ShadowInput {
                    light: &l.light,
                    hair,
                    fiber,
                    occluders,
                    extent,
                })?,
                (_, Strands::Held { .. }) => return Err(held_needs("the density map method")),
            };
            if stats.out_of_map > 0 {
                tracing::warn!(
                    out_of_map = stats.out_of_map,
                    samples = stats.samples,
                    "density samples fell outside the map and were dropped"
                );
            }
            total = total + stats;
        }
        Ok(total)
    }

    /// Stage 2: for the density map, sweeps every column of every light's map.
    pub fn transmittance(&mut self) -> Result<(), EngineError> {
        self.transmittance_with(&mut LocalExecutor)
    }

    /// [`Self::transmittance`] with the columns swept through `ex`.
    pub fn transmittance_with(&mut self, ex: &mut dyn Executor) -> Result<(), EngineError> {
        for (i, l) in self.lights.iter_mut().enumerate() {
            match &mut l.method {
                ShadowMethod::DensityMap(m) => {
                    m.transmittance_with(|map| ex.transmittance(i, map))?
                }
                other => other.transmittance(),
            }
        }
        Ok(())
    }

    /// The camera's eye, for the methods that start a fiber's rays where
    /// the camera's rays meet its surface ([`ShadowMethod::set_eye`]).
    pub fn set_eye(&mut self, eye: Option<Vec3>) {
        for l in &mut self.lights {
            l.method.set_eye(eye);
        }
    }

    /// Stage 3 for light `l` at `points`, into `out`.
    pub fn filter_light(&self, l: usize, points: &[Vec3], out: &mut [f32]) {
        self.lights[l].method.filter(points, out);
    }

    /// Stage 3: transmittance of every light at every point; `out[l][p]`.
    pub fn filter(&self, points: &[Vec3], out: &mut [Vec<f32>]) {
        assert_eq!(out.len(), self.lights.len());
        for (l, o) in self.lights.iter().zip(out) {
            o.resize(points.len(), 0.0);
            l.method.filter(points, o);
        }
    }

    /// Transmittance of light `l` at a point `p` of an opaque surface (the
    /// head) of unit normal `n`, looked up off the surface, at
    ///
    /// ```text
    /// p' = p + ds (HEAD_NORMAL_BIAS n - HEAD_LIGHT_BIAS L)
    /// ```
    ///
    /// with `L` the light's direction into the map and `ds` its cell size.
    /// The surface's own opaque deposit starts where each column enters
    /// it, and the lookup blends four columns: on a surface sloped to the
    /// light a neighbour column enters up to `ds tan(theta)` nearer the
    /// light, and a lookup at `p` itself reads that deposit as a pattern of
    /// dots and stripes (shadow acne). Off the surface along its normal,
    /// every column the lookup blends enters behind `p'`, so only the
    /// hair's shadow is read, smooth at the map's resolution.
    pub fn transmittance_off_surface(&self, l: usize, p: Vec3, n: Vec3) -> f32 {
        let m = &self.lights[l].method;
        let f = m.frame().expect("density runs before lookups");
        // With contact shadows the hair near the surface is tested
        // exactly: no deposit of the head's to keep clear of there.
        let scale = match m {
            ShadowMethod::DensityMap(d) if d.contact() > 0.0 => HEAD_CONTACT_SCALE,
            _ => 1.0,
        };
        m.transmittance_at_surface(p, off_surface(f, p, n, scale))
    }

    /// The frame of light `l`'s last map (methods that keep one).
    pub fn frame(&self, l: usize) -> Option<&shadow::LightFrame> {
        self.lights.get(l).and_then(|x| x.method.frame())
    }

    /// Light `l`'s swept map and whether its lookups filter it, for the
    /// method that keeps one (the paper's).
    pub fn swept(&self, l: usize) -> Option<(&shadow::Transmittance, bool)> {
        self.lights.get(l).and_then(|x| x.method.swept())
    }

    /// The lights, in scene order.
    pub fn lights(&self) -> impl Iterator<Item = &Light> {
        self.lights.iter().map(|l| &l.light)
    }

    /// All three stages: transmittance of each light at `points` for `hair`.
    pub fn run(&mut self, hair: &Hair, points: &[Vec3]) -> Result<Vec<Vec<f32>>, EngineError> {
        self.density(hair)?;
        self.transmittance()?;
        let mut out = vec![Vec::new(); self.lights.len()];
        self.filter(points, &mut out);
        Ok(out)
    }
}

/// The point a surface point `p` of normal `n` looks its transmittance up
/// at in a map of frame `f`: see
/// [`ShadowPipeline::transmittance_off_surface`]; `scale` times as far
/// off with contact shadows ([`HEAD_CONTACT_SCALE`]), else 1.
pub(crate) fn off_surface(f: &shadow::LightFrame, p: Vec3, n: Vec3, scale: f32) -> Vec3 {
    let n = n.normalize_or_zero();
    match &f.fan {
        None => p + (n * HEAD_NORMAL_BIAS - f.axes[0] * HEAD_LIGHT_BIAS) * f.ds * scale,
        Some(fan) => {
            // Along the ray through p, by the cell's size there.
            let ray = (p - fan.source).normalize_or(f.axes[0]);
            let width = f.cell_width(f.to_cells(p).x).max(f.ds);
            p + (n * HEAD_NORMAL_BIAS - ray * HEAD_LIGHT_BIAS) * width * scale
        }
    }
}

/// Transmittance of swept map `m` at a point `p` of normal `n` on the
/// head's surface, its lookup moved off it as [`off_surface`] says
/// ([`shadow::Transmittance::surface_transmittance`]): what
/// [`ShadowPipeline::transmittance_off_surface`] gives without contact
/// shadows, from a map held here.
pub(crate) fn surface_transmittance(
    m: &shadow::Transmittance,
    p: Vec3,
    n: Vec3,
    trilinear: bool,
) -> f32 {
    m.surface_transmittance(p, off_surface(m.frame(), p, n, 1.0), trilinear)
}

/// The hair is held elsewhere, and a map of it needs `what`.
fn held_needs(what: &str) -> EngineError {
    EngineError::executor(format!("a shadow map of hair held elsewhere needs {what}"))
}

/// The physically based fiber (Chiang et al. 2016) across its width, as
/// the exact reference weighs its rays by: the luminance of `f(w_o, w_i)`
/// at [`FiberWidth::NODES`] even offsets `h`, summed over those in a
/// ray's part of the width.
#[derive(Debug)]
struct FiberWidth {
    nodes: Vec<(f32, raster::Chiang)>,
}

impl FiberWidth {
    /// Offsets across the width: 8 in each quarter, finer than the
    /// model's lobes (about 0.12 across at the default roughness).
    const NODES: usize = 32;

    fn new(optics: &raster::FiberOptics) -> FiberWidth {
        let nodes = (0..Self::NODES)
            .map(|i| {
                let h = 2.0 * (i as f32 + 0.5) / Self::NODES as f32 - 1.0;
                (h, raster::Chiang::new(optics, h))
            })
            .collect();
        FiberWidth { nodes }
    }
}

impl shadow::AcrossFiber for FiberWidth {
    fn weight(&self, wo: Vec3, wi: Vec3, h0: f32, h1: f32) -> f32 {
        // Rec. 709 luminance, as the pictures are compared.
        const LUMA: Vec3 = Vec3::new(0.2126, 0.7152, 0.0722);
        self.nodes
            .iter()
            .filter(|(h, _)| (h0..h1).contains(h))
            .map(|(_, c)| c.f(wo, wi).dot(LUMA))
            .sum()
    }
}
