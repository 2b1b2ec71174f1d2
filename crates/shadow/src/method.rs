//! One type for every shadow method: the paper's density map, the peer
//! methods it is compared with, and an exact reference.
//!
//! All of them estimate the same physical quantity from the same fiber
//! width `w` and opacity `alpha` (see [`crate::Fiber`]): the transmittance
//! `T(p) = exp(-D(p))` of light reaching `p`, where `D` is the optical depth
//! of the hair between `p` and the light. Each runs in three stages, named
//! after the density map's so that timings compare:
//!
//! 1. `build` (the "density" stage): sample the hair from the light;
//! 2. `prepare` (the "transmittance" stage): turn the samples into something
//!    to look up (a sweep, prefix sums, clustering, compression);
//! 3. `lookup` (the "filter" stage): transmittance at the drawn points.
//!
//! The set is closed: [`ShadowMethod`] is an enum, and a caller that works
//! on the density map itself (filling or sweeping it elsewhere) matches its
//! [`ShadowMethod::DensityMap`] variant.

use glam::Vec3;
use rayon::prelude::*;

use crate::Occluder;
use crate::config::MethodConfig;
use crate::contact::Contact;
use crate::footprint_reference::FootprintReference;
use crate::input::{OPAQUE_DEPTH, ShadowInput};
use crate::peers::{DeepOpacityMap, DeepShadowMap, DensityClustering, OpacityShadowMap};
use crate::reference::Reference;
use crate::{DensityMap, FillStats, LightFrame, ShadowError, Transmittance};

/// A shadow method with its settings and the results of its last build.
#[derive(Debug)]
pub enum ShadowMethod {
    /// Bertails, Ménier and Cani 2005: the light-oriented density map.
    DensityMap(DensityMapMethod),
    /// Kim and Neumann 2001 as Koster et al. 2004 describe it.
    OpacityShadowMap(OpacityShadowMap),
    /// Yuksel and Keyser 2008.
    DeepOpacityMap(DeepOpacityMap),
    /// Mertens et al. 2004.
    DensityClustering(DensityClustering),
    /// Lokovic and Veach 2000.
    DeepShadowMap(DeepShadowMap),
    /// The exact reference: rays from each fiber to the light, tested
    /// against the other fibers.
    Reference(Reference),
    /// Transmittance from the fiber geometry, averaged over a footprint.
    FootprintReference(FootprintReference),
}

/// Calls `$call` on whichever method `$self` holds.
macro_rules! each {
    ($self:expr, $m:ident => $call:expr) => {
        match $self {
            ShadowMethod::DensityMap($m) => $call,
            ShadowMethod::OpacityShadowMap($m) => $call,
            ShadowMethod::DeepOpacityMap($m) => $call,
            ShadowMethod::DensityClustering($m) => $call,
            ShadowMethod::DeepShadowMap($m) => $call,
            ShadowMethod::Reference($m) => $call,
            ShadowMethod::FootprintReference($m) => $call,
        }
    };
}

impl ShadowMethod {
    /// A fresh method with the settings `config`, once they validate.
    pub fn new(config: &MethodConfig) -> Result<ShadowMethod, ShadowError> {
        config.validate()?;
        Ok(match *config {
            MethodConfig::DensityMap {
                cells,
                trilinear,
                contact,
            } => ShadowMethod::DensityMap(
                DensityMapMethod::new(cells, trilinear)?.with_contact(contact)?,
            ),
            MethodConfig::OpacityShadowMap {
                resolution,
                slices,
                mode,
                offset,
                trilinear,
            } => ShadowMethod::OpacityShadowMap(OpacityShadowMap::new(
                resolution, slices, mode, offset, trilinear,
            )),
            MethodConfig::DeepOpacityMap {
                resolution,
                layers,
                layer_cells,
                beyond,
                trilinear,
            } => ShadowMethod::DeepOpacityMap(DeepOpacityMap::new(
                resolution,
                layers,
                layer_cells,
                beyond,
                trilinear,
            )),
            MethodConfig::DensityClustering {
                resolution,
                clusters,
                trilinear,
            } => ShadowMethod::DensityClustering(DensityClustering::new(
                resolution, clusters, trilinear,
            )),
            MethodConfig::DeepShadowMap {
                resolution,
                tolerance,
                trilinear,
            } => ShadowMethod::DeepShadowMap(DeepShadowMap::new(resolution, tolerance, trilinear)),
            MethodConfig::Reference { rays } => ShadowMethod::Reference(Reference::new(rays)),
            MethodConfig::FootprintReference { footprint, rays } => {
                ShadowMethod::FootprintReference(FootprintReference::new(footprint, rays))
            }
        })
    }

    /// Stage 1, density: samples the hair (and occluders) from the light.
    pub fn density(&mut self, input: &ShadowInput) -> Result<FillStats, ShadowError> {
        each!(self, m => m.density(input))
    }

    /// Stage 2, transmittance: makes the samples ready for lookups. Panics
    /// before [`Self::density`].
    pub fn transmittance(&mut self) {
        each!(self, m => m.transmittance())
    }

    /// The camera's eye, for the methods that start a fiber's rays where
    /// the camera's rays meet its surface (the exact reference, the
    /// density map's contact rays); the others ignore it.
    pub fn set_eye(&mut self, eye: Option<Vec3>) {
        match self {
            ShadowMethod::Reference(r) => r.set_eye(eye),
            ShadowMethod::DensityMap(m) => m.eye = eye.filter(|e| e.is_finite()),
            _ => {}
        }
    }

    /// How a fiber's light is spread across its width, for the methods
    /// that weigh a fiber's rays by it (the exact reference, with the
    /// camera known); the others ignore it.
    pub fn set_across(&mut self, across: Option<std::sync::Arc<dyn crate::AcrossFiber>>) {
        if let ShadowMethod::Reference(r) = self {
            r.set_across(across);
        }
    }

    /// `T(p)` in [0, 1] at one point. Panics before [`Self::transmittance`].
    /// With the density map's contact shadows the point is a probe (its
    /// ray from the point itself, every fiber it crosses counted): only
    /// [`Self::filter`] knows points as the drawn hair's.
    pub fn transmittance_at(&self, p: Vec3) -> f32 {
        each!(self, m => m.transmittance_at(p))
    }

    /// `T` at a point `p` on a drawn opaque surface (the head's), `off`
    /// the point off it that the caller moved it to, clear of the
    /// surface's own deposit: the density map reads the bodies' shadow at
    /// `off` as it reads drawn fibers ([`crate::LIT_EDGE_OFFSET`] nearer
    /// the light) and the hair's down to `p` itself
    /// ([`Transmittance::surface_depth`]), or with contact shadows all of
    /// it from `off`; the other methods read `off` as any point.
    pub fn transmittance_at_surface(&self, p: Vec3, off: Vec3) -> f32 {
        match self {
            ShadowMethod::DensityMap(m) => m.transmittance_at_surface(p, off),
            _ => self.transmittance_at(off),
        }
    }

    /// Stage 3, filter: `T` at many points, in parallel; the same values
    /// as [`Self::transmittance_at`] one by one, except for the density
    /// map's contact shadows, which take the `i`-th point to be the `i`-th
    /// drawn point of the hair they were prepared from (where it is: its
    /// own fiber not counted, its ray from the camera's side of it).
    pub fn filter(&self, points: &[Vec3], out: &mut [f32]) {
        assert_eq!(points.len(), out.len());
        if let ShadowMethod::DensityMap(m) = self {
            return m.filter(points, out);
        }
        out.par_chunks_mut(2048)
            .zip(points.par_chunks(2048))
            .for_each(|(o, p)| {
                for (o, &p) in o.iter_mut().zip(p) {
                    *o = self.transmittance_at(p);
                }
            });
    }

    /// The frame of the last build: its first axis is the light direction
    /// and `ds` its resolution, for biasing lookups on surfaces.
    pub fn frame(&self) -> Option<&LightFrame> {
        each!(self, m => m.frame())
    }

    /// The swept map of the last build and whether lookups filter it, for
    /// the method that keeps one (the paper's).
    pub fn swept(&self) -> Option<(&Transmittance, bool)> {
        match self {
            ShadowMethod::DensityMap(m) => m.trans.as_ref().map(|t| (t, m.trilinear)),
            _ => None,
        }
    }

    /// The density map of the last build, for the method that fills one
    /// (the simulation's self-collisions read it too).
    pub fn density_map(&self) -> Option<&DensityMap> {
        match self {
            ShadowMethod::DensityMap(m) => m.map(),
            _ => None,
        }
    }
}

/// The paper's method: a density map swept into transmittance.
#[derive(Debug)]
pub struct DensityMapMethod {
    cells: u32,
    trilinear: bool,
    /// Contact distance, cells (0: none).
    contact: f32,
    eye: Option<Vec3>,
    map: Option<DensityMap>,
    trans: Option<Transmittance>,
    near: Option<Box<Contact>>,
}

impl DensityMapMethod {
    /// A map of `cells` a side, its lookups filtered trilinearly or not.
    pub fn new(cells: u32, trilinear: bool) -> Result<DensityMapMethod, ShadowError> {
        MethodConfig::DensityMap {
            cells,
            trilinear,
            contact: 0.0,
        }
        .validate()?;
        Ok(DensityMapMethod {
            cells,
            trilinear,
            contact: 0.0,
            eye: None,
            map: None,
            trans: None,
            near: None,
        })
    }

    /// With contact shadows of `cells` cells (see
    /// [`MethodConfig::DensityMap`]); 0: none.
    pub fn with_contact(mut self, cells: f32) -> Result<DensityMapMethod, ShadowError> {
        MethodConfig::DensityMap {
            cells: self.cells,
            trilinear: self.trilinear,
            contact: cells,
        }
        .validate()?;
        self.contact = cells;
        Ok(self)
    }

    /// The contact distance, cells (0: none). A caller that fills the map
    /// itself ([`Self::density_with`]) then hands the hair to
    /// [`Self::contact_with`].
    pub fn contact(&self) -> f32 {
        self.contact
    }

    /// Prepares the contact rays of this frame's hair (part of the density
    /// stage), after [`Self::density_with`]; nothing without contact
    /// shadows. `input`'s hair is every drawn strand, in this process.
    pub fn contact_with(&mut self, input: &ShadowInput) -> Result<(), ShadowError> {
        self.near = None;
        if self.contact > 0.0 {
            let ds = self
                .map
                .as_ref()
                .expect("the map is filled before its contact rays are prepared")
                .frame()
                .ds;
            // Columns as wide as the map's cells: a ray tests the
            // capsules of one column within reach of it.
            self.near = Some(Box::new(Contact::new(
                input,
                self.cells,
                self.contact * ds,
            )?));
        }
        Ok(())
    }

    /// The map of the last build.
    pub fn map(&self) -> Option<&DensityMap> {
        self.map.as_ref()
    }

    /// Its cells a side.
    pub fn cells(&self) -> u32 {
        self.cells
    }

    /// Stage 1 (density) with the hair's density filled by `fill`: empties
    /// the map in `frame` (fitted by [`ShadowInput::fit`] or
    /// [`fit_to_extent`](crate::fit_to_extent)), lets `fill` add the
    /// density of every strand to it, then adds the `occluders`.
    pub fn density_with<E>(
        &mut self,
        frame: LightFrame,
        occluders: &[Occluder],
        fill: impl FnOnce(&mut DensityMap) -> Result<FillStats, E>,
    ) -> Result<FillStats, E> {
        let map = match &mut self.map {
            Some(m) => {
                m.set_frame(frame);
                m
            }
            None => self.map.insert(DensityMap::new(frame)),
        };
        self.trans = None;
        self.near = None;
        let stats = fill(map)?;
        for o in occluders {
            map.deposit_body(o, OPAQUE_DEPTH);
        }
        Ok(stats)
    }

    /// Stage 2 (transmittance) with the columns swept by `sweep`.
    pub fn transmittance_with<E>(
        &mut self,
        sweep: impl FnOnce(&DensityMap) -> Result<Transmittance, E>,
    ) -> Result<(), E> {
        let map = self
            .map
            .as_ref()
            .expect("the density stage runs before the transmittance stage");
        self.trans = Some(sweep(map)?);
        Ok(())
    }

    fn density(&mut self, input: &ShadowInput) -> Result<FillStats, ShadowError> {
        // The map is already empty: deposit, without clearing it again.
        let all = 0..input.hair.strand_count();
        let frame = input.fit(self.cells)?;
        let stats = self.density_with(frame, input.occluders, |map| {
            Ok::<_, ShadowError>(map.deposit(input.hair, all, input.fiber))
        })?;
        self.contact_with(input)?;
        Ok(stats)
    }

    fn transmittance(&mut self) {
        let map = self
            .map
            .as_ref()
            .expect("the density stage runs before the transmittance stage");
        self.trans = Some(Transmittance::compute(map));
    }

    fn transmittance_at(&self, p: Vec3) -> f32 {
        let trans = self
            .trans
            .as_ref()
            .expect("the transmittance stage runs before lookups");
        match &self.near {
            Some(c) => c.at(p, |q| trans.transmittance_at(q, self.trilinear)),
            None => trans.transmittance_at(p, self.trilinear),
        }
    }

    /// [`ShadowMethod::transmittance_at_surface`].
    fn transmittance_at_surface(&self, p: Vec3, off: Vec3) -> f32 {
        let trans = self
            .trans
            .as_ref()
            .expect("the transmittance stage runs before lookups");
        match &self.near {
            Some(c) => c.at(off, |q| trans.transmittance_at_drawn(q, self.trilinear)),
            None => trans.surface_transmittance(p, off, self.trilinear),
        }
    }

    fn filter(&self, points: &[Vec3], out: &mut [f32]) {
        let trans = self
            .trans
            .as_ref()
            .expect("the transmittance stage runs before lookups");
        let Some(near) = &self.near else {
            return trans.filter(points, self.trilinear, out);
        };
        const CHUNK: usize = 2048;
        out.par_chunks_mut(CHUNK)
            .zip(points.par_chunks(CHUNK))
            .enumerate()
            .for_each(|(c, (o, p))| {
                for (i, (o, &p)) in o.iter_mut().zip(p).enumerate() {
                    *o = near.at_drawn(c * CHUNK + i, p, self.eye, |q| {
                        trans.transmittance_at_drawn(q, self.trilinear)
                    });
                }
            });
    }

    fn frame(&self) -> Option<&LightFrame> {
        self.map.as_ref().map(|m| m.frame())
    }
}
