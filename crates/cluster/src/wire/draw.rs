//! What crosses the wire for drawing on the workers: pose plans and their
//! reports, the columns a worker's lookups read, the draw job with the
//! swept columns it needs, and partial pictures. Everything received is
//! checked before use.

use engine::{DrawJob, PosePlan, PoseReport};
use glam::{Affine3A, Vec3};
use raster::{Camera, HairLook, Shading, ShadingModel};
use shadow::{ColumnSlab, Extent, Light, LightFrame, MAX_CELLS, Span};
use strands::Bounds;

use super::{
    CELLS_PER_CHUNK, Malformed, Runs, affines_from_floats, bad, bodies_from_floats,
    bodies_to_floats, column_count, frame_from_pb, frame_to_pb, unpack_runs,
};
use crate::pb;

mod picture;
mod segments;

pub(crate) use picture::*;
pub(crate) use segments::*;

/// The most lights one scene may have on the wire.
pub(crate) const MAX_LIGHTS: usize = 64;

/// Pixels per partial-picture chunk: about 300 KB, so that a picture
/// streams (and is decoded) while the rest of it is encoded and sent.
pub(crate) const PIXELS_PER_CHUNK: usize = 16 * 1024;

/// A vector of `n` floats, each finite.
fn floats<const N: usize>(what: &str, f: &[f32]) -> Result<[f32; N], Malformed> {
    let a: [f32; N] = f
        .try_into()
        .map_err(|_| bad(format!("{what}: {} values, expected {N}", f.len())))?;
    if a.iter().any(|v| !v.is_finite()) {
        return Err(bad(format!("{what} is not finite")));
    }
    Ok(a)
}

pub(crate) fn one_affine(what: &str, f: &[f32]) -> Result<Affine3A, Malformed> {
    let a = affines_from_floats(f)?;
    match a.as_slice() {
        [one] => Ok(*one),
        _ => Err(bad(format!("{what}: {} transforms, expected 1", a.len()))),
    }
}

/// Floats per light on the wire (see `Light` in worker.proto).
const LIGHT_FLOATS: usize = 10;

fn lights_to_floats(lights: &[Light]) -> Vec<f32> {
    lights
        .iter()
        .flat_map(|l| {
            let (kind, p, d, cone, falloff, i) = match *l {
                Light::Directional { direction } => (0.0, Vec3::ZERO, direction, 0.0, 0.0, 0.0),
                Light::Point {
                    position,
                    intensity,
                } => (1.0, position, Vec3::ZERO, 0.0, 0.0, intensity),
                Light::Spot {
                    position,
                    direction,
                    cone_deg,
                    falloff_deg,
                    intensity,
                } => (2.0, position, direction, cone_deg, falloff_deg, intensity),
            };
            [kind, p.x, p.y, p.z, d.x, d.y, d.z, cone, falloff, i]
        })
        .collect()
}

/// Lights as sent: at most [`MAX_LIGHTS`], each valid as its constructor
/// checks, with a unit direction (taken as sent, bit for bit).
fn lights_from_floats(f: &[f32]) -> Result<Vec<Light>, Malformed> {
    if !f.len().is_multiple_of(LIGHT_FLOATS) || f.len() / LIGHT_FLOATS > MAX_LIGHTS {
        return Err(bad(format!(
            "{} light values: not {LIGHT_FLOATS} a light, or more than {MAX_LIGHTS} lights",
            f.len()
        )));
    }
    f.chunks_exact(LIGHT_FLOATS)
        .map(|v| {
            let (p, d) = (Vec3::from_slice(&v[1..4]), Vec3::from_slice(&v[4..7]));
            let unit = |d: Vec3| {
                if d.is_finite() && (d.length() - 1.0).abs() <= 1e-3 {
                    Ok(d)
                } else {
                    Err(bad(format!("light direction {d} is not a unit vector")))
                }
            };
            let checked = |l: Result<Light, shadow::ShadowError>| l.map_err(|e| bad(e.to_string()));
            let light = match v[0] {
                0.0 => Light::Directional {
                    direction: unit(d)?,
                },
                1.0 => checked(Light::point(p, v[9]))?,
                2.0 => {
                    // Validated by the constructor, the direction kept as sent.
                    checked(Light::spot(p, unit(d)?, v[7], v[8], v[9]))?;
                    Light::Spot {
                        position: p,
                        direction: d,
                        cone_deg: v[7],
                        falloff_deg: v[8],
                        intensity: v[9],
                    }
                }
                k => return Err(bad(format!("light kind {k}"))),
            };
            Ok(light)
        })
        .collect()
}

/// A pose plan as sent.
pub(crate) fn pose_plan_to_pb(p: &PosePlan) -> pb::PosePlan {
    let mut out = pb::PosePlan {
        version: p.version,
        sample: p.sample,
        head: p.head.to_cols_array().to_vec(),
        anchor: p.anchor.to_array().to_vec(),
        ..Default::default()
    };
    bodies_to_floats(&p.drawn_bodies, &mut out.drawn_bodies);
    out.lights = lights_to_floats(&p.lights);
    out
}

/// A pose plan as sent: one finite head transform, bodies, at most
/// [`MAX_LIGHTS`] valid light directions, a finite anchor.
pub(crate) fn pose_plan_from_pb(p: &pb::PosePlan) -> Result<PosePlan, Malformed> {
    Ok(PosePlan {
        version: p.version,
        head: one_affine("pose head", &p.head)?,
        sample: p.sample,
        drawn_bodies: bodies_from_floats(&p.drawn_bodies)?,
        lights: lights_from_floats(&p.lights)?,
        anchor: Vec3::from_array(floats::<3>("pose anchor", &p.anchor)?),
    })
}

/// A pose report as sent.
pub(crate) fn report_to_pb(r: &PoseReport) -> pb::PoseReport {
    let six = |lo: Vec3, hi: Vec3| [lo.to_array(), hi.to_array()].concat();
    pb::PoseReport {
        bounds: if r.bounds.is_empty() {
            Vec::new()
        } else {
            six(r.bounds.min, r.bounds.max)
        },
        extents: r.extents.iter().flat_map(|e| six(e.lo, e.hi)).collect(),
    }
}

/// A report as sent, for a plan of `lights` lights: finite values, each
/// least corner no greater than its greatest (empty extents are all
/// infinities, as [`Extent::EMPTY`]).
pub fn report_from_pb(r: &pb::PoseReport, lights: usize) -> Result<PoseReport, Malformed> {
    let bounds = match r.bounds.as_slice() {
        [] => Bounds::empty(),
        b => {
            let b = floats::<6>("pose bounds", b)?;
            let (min, max) = (Vec3::from_slice(&b[..3]), Vec3::from_slice(&b[3..]));
            if !min.cmple(max).all() {
                return Err(bad(format!("pose bounds {min}..{max}")));
            }
            Bounds { min, max }
        }
    };
    if r.extents.len() != 6 * lights {
        return Err(bad(format!(
            "{} extent values for {lights} lights",
            r.extents.len()
        )));
    }
    let extents = r
        .extents
        .chunks_exact(6)
        .map(|e| {
            let (lo, hi) = (Vec3::from_slice(&e[..3]), Vec3::from_slice(&e[3..]));
            let fine = lo.is_finite() && hi.is_finite() && lo.cmple(hi).all();
            if !(fine || Extent { lo, hi } == Extent::EMPTY) {
                return Err(bad(format!("pose extent {lo}..{hi}")));
            }
            Ok(Extent { lo, hi })
        })
        .collect::<Result<_, _>>()?;
    Ok(PoseReport { bounds, extents })
}

/// A bitmap of a map's columns (as [`shadow::columns_read`] makes) in
/// 32-bit words, zero-run packed.
pub(crate) fn columns_to_pb(bits: &[u64]) -> Vec<u8> {
    let words: Vec<u32> = bits
        .iter()
        .flat_map(|w| [*w as u32, (*w >> 32) as u32])
        .collect();
    super::pack(&words)
}

/// [`columns_to_pb`] undone for a map of `columns` columns; no bit beyond.
pub(crate) fn columns_from_pb(bytes: &[u8], columns: usize) -> Result<Vec<u64>, Malformed> {
    let words = columns.div_ceil(64);
    let mut w32 = Vec::new();
    unpack_runs(bytes, 2 * words, &mut w32)?;
    let bits: Vec<u64> = w32
        .chunks_exact(2)
        .map(|p| u64::from(p[0]) | u64::from(p[1]) << 32)
        .collect();
    let spare = words * 64 - columns;
    if spare > 0 && bits.last().is_some_and(|w| w >> (64 - spare) != 0) {
        return Err(bad(format!("a column past the map's {columns}")));
    }
    Ok(bits)
}

/// A draw job as sent.
pub fn job_to_pb(j: &DrawJob) -> pb::DrawJob {
    let c = &j.camera;
    pb::DrawJob {
        version: j.version,
        camera: [
            c.position.to_array().as_slice(),
            c.look_at().to_array().as_slice(),
            &[c.fov_deg()],
            c.up_hint().to_array().as_slice(),
        ]
        .concat(),
        width: c.width(),
        height: c.height(),
        fiber_width: j.look.fiber_width,
        hair_alpha: j.look.opacity,
        depth_ref: j.look.depth_ref,
        simplify: j.look.simplify,
        shading: {
            let (s, c) = (&j.shading, j.shading.specular_color);
            vec![s.ambient, s.diffuse, s.specular, s.shininess, c.x, c.y, c.z]
        },
        lights: lights_to_floats(&j.lights),
        shadows: j.shadows,
        trilinear: j.trilinear,
        head: j.head.to_cols_array().to_vec(),
        nearest: j.nearest,
        exchanged: false,
        shading_model: match j.shading.model {
            ShadingModel::KajiyaKay => 0,
            ShadingModel::Marschner { .. } => 1,
        },
        fiber: match j.shading.model {
            ShadingModel::KajiyaKay => Vec::new(),
            ShadingModel::Marschner {
                optics: o,
                from_color,
                irradiance,
                multiple,
            } => {
                let mut v = vec![
                    o.eta,
                    o.sigma_a.x,
                    o.sigma_a.y,
                    o.sigma_a.z,
                    o.beta_m,
                    o.beta_n,
                    o.alpha_deg,
                    irradiance,
                    if from_color { 1.0 } else { 0.0 },
                ];
                if multiple {
                    v.push(1.0);
                }
                v
            }
        },
    }
}

/// The shading model of a draw job as sent: Kajiya-Kay with no fiber
/// values, or a fiber whose settings are in range (nine values, and a
/// tenth, 1, with multiple scattering).
fn model_from_pb(j: &pb::DrawJob) -> Result<ShadingModel, Malformed> {
    match j.shading_model {
        0 if j.fiber.is_empty() => Ok(ShadingModel::KajiyaKay),
        1 if matches!(j.fiber.len(), 9 | 10) => {
            let multiple = match j.fiber.get(9) {
                Some(1.0) => true,
                Some(_) => return Err(bad(format!("draw fiber {:?} out of range", j.fiber))),
                None => false,
            };
            let [
                eta,
                r,
                g,
                b,
                beta_m,
                beta_n,
                alpha_deg,
                irradiance,
                from_color,
            ] = floats::<9>("draw fiber", &j.fiber[..9])?;
            let optics = raster::FiberOptics {
                eta,
                sigma_a: Vec3::new(r, g, b),
                beta_m,
                beta_n,
                alpha_deg,
            };
            // (floats::<9> refused any value that is not finite.)
            if !optics.is_valid() || irradiance < 0.0 || !(from_color == 0.0 || from_color == 1.0) {
                return Err(bad(format!("draw fiber {:?} out of range", j.fiber)));
            }
            Ok(ShadingModel::Marschner {
                optics,
                from_color: from_color == 1.0,
                irradiance,
                multiple,
            })
        }
        m => Err(bad(format!(
            "shading model {m} with {} fiber values",
            j.fiber.len()
        ))),
    }
}

/// A draw job as sent: a camera [`Camera::new`] takes (within the
/// renderer's picture limits), finite settings, unit light directions.
pub(crate) fn job_from_pb(j: &pb::DrawJob) -> Result<DrawJob, Malformed> {
    let c = floats::<10>("draw camera", &j.camera)?;
    if u64::from(j.width) * u64::from(j.height) > raster::MAX_PIXELS
        || j.width == 0
        || j.height == 0
        || j.width > raster::canvas_max_side()
        || j.height > raster::canvas_max_side()
    {
        return Err(bad(format!("a picture of {}x{}", j.width, j.height)));
    }
    let camera = Camera::new(
        Vec3::from_slice(&c[..3]),
        Vec3::from_slice(&c[3..6]),
        c[6],
        j.width,
        j.height,
    )
    .map_err(|e| bad(e.to_string()))?;
    let up = Vec3::from_slice(&c[7..]);
    let camera = if up == Vec3::Y {
        camera
    } else {
        camera.with_up(up).map_err(|e| bad(e.to_string()))?
    };
    let [ambient, diffuse, specular, shininess, sr, sg, sb] =
        floats::<7>("draw shading", &j.shading)?;
    let look = [j.fiber_width, j.hair_alpha, j.depth_ref];
    if look.iter().any(|v| !v.is_finite() || *v < 0.0) {
        return Err(bad(format!("hair look {look:?}")));
    }
    if !(0.0..=HairLook::MAX_SIMPLIFY).contains(&j.simplify) {
        return Err(bad(format!(
            "simplify {} outside 0..={} pixels",
            j.simplify,
            HairLook::MAX_SIMPLIFY
        )));
    }
    let lights = lights_from_floats(&j.lights)?;
    Ok(DrawJob {
        version: j.version,
        camera,
        look: HairLook {
            fiber_width: j.fiber_width,
            opacity: j.hair_alpha,
            depth_ref: j.depth_ref,
            simplify: j.simplify,
        },
        shading: Shading {
            ambient,
            diffuse,
            specular,
            shininess,
            specular_color: Vec3::new(sr, sg, sb),
            model: model_from_pb(j)?,
        },
        lights,
        shadows: j.shadows,
        trilinear: j.trilinear,
        head: one_affine("draw head", &j.head)?,
        nearest: if j.nearest as usize <= raster::MAX_NEAREST {
            j.nearest
        } else {
            return Err(bad(format!(
                "nearest {}: at most {} fragments a pixel",
                j.nearest,
                raster::MAX_NEAREST
            )));
        },
    })
}

/// The columns of `slabs` (contiguous, swept in `frame`) whose bits are
/// set in `keep` (all when `None`), as Draw chunks of light `light`, the
/// first carrying the frame.
pub(crate) fn draw_columns(
    light: u32,
    frame: &LightFrame,
    slabs: &[ColumnSlab],
    keep: Option<&[u64]>,
) -> Vec<pb::DrawChunk> {
    let new = |with_frame: bool| pb::DrawChunk {
        light,
        map: with_frame.then(|| frame_to_pb(frame)),
        ..Default::default()
    };
    let mut out = Vec::new();
    let mut chunk = new(true);
    let (mut cells, mut runs, mut last) = (0usize, Runs::default(), 0u32);
    for slab in slabs {
        for (col, s) in slab.columns.clone().zip(&slab.spans) {
            let kept = keep.is_none_or(|k| {
                k.get(col as usize / 64)
                    .is_some_and(|w| w >> (col % 64) & 1 == 1)
            });
            if s.is_empty() || !kept {
                continue;
            }
            if cells > 0 && cells + s.len() > CELLS_PER_CHUNK {
                runs.finish(&mut chunk.depth_steps);
                out.push(std::mem::replace(&mut chunk, new(false)));
                cells = 0;
            }
            // The first column of each chunk counts from 0.
            let step = if chunk.column_steps.is_empty() {
                col
            } else {
                col - last
            };
            chunk.column_steps.push(step);
            last = col;
            chunk.lo.push(u32::from(s.lo));
            chunk.hi.push(u32::from(s.hi));
            chunk.front.push(s.front);
            let mut prev = 0u32;
            for &d in &slab.depth[s.start as usize..s.start as usize + s.len()] {
                runs.push(d - prev, &mut chunk.depth_steps);
                prev = d;
            }
            cells += s.len();
        }
    }
    runs.finish(&mut chunk.depth_steps);
    out.push(chunk);
    out
}

/// The most workers one Draw round composites among.
pub(crate) const MAX_WORKERS: usize = 256;

/// The longest worker address or session a plan may name, bytes.
pub(crate) const MAX_ADDR_BYTES: usize = 256;

/// How one Draw round's picture is composited on the workers: the band
/// plan, the round, and where each worker is.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Bands {
    /// The round, counted by the coordinator.
    pub round: u64,
    /// Which worker owns which rows.
    pub plan: engine::BandPlan,
    /// Each worker: its address and its session of this coordinator.
    pub peers: Vec<(String, String)>,
    /// How long a worker waits for the others' stripes.
    pub wait: std::time::Duration,
    /// The name workers check each other's certificates for, with TLS.
    pub tls_domain: Option<String>,
}

impl Bands {
    /// The plan as sent.
    pub(crate) fn to_pb(&self) -> pb::BandPlan {
        pb::BandPlan {
            round: self.round,
            cuts: self.plan.cuts.clone(),
            own: self.plan.own as u32,
            peers: self.peers.iter().map(|p| p.0.clone()).collect(),
            sessions: self.peers.iter().map(|p| p.1.clone()).collect(),
            wait_ms: self.wait.as_millis().min(u128::from(u32::MAX)) as u32,
            tls_domain: self.tls_domain.clone().unwrap_or_default(),
            sort_middle: self.plan.sort == engine::Sort::Middle,
        }
    }

    /// A band plan as sent, for a picture of `height` rows: whole bands,
    /// 2 to [`MAX_WORKERS`] workers each with an address and a session, a
    /// wait of at most ten minutes.
    pub(crate) fn from_pb(b: &pb::BandPlan, height: u32) -> Result<Bands, Malformed> {
        let n = b.peers.len();
        if !(2..=MAX_WORKERS).contains(&n) || b.sessions.len() != n {
            return Err(bad(format!(
                "a band plan of {n} workers and {} sessions (2 to {MAX_WORKERS} workers, a session each)",
                b.sessions.len()
            )));
        }
        let plan = engine::BandPlan {
            cuts: b.cuts.clone(),
            workers: n,
            own: b.own as usize,
            sort: if b.sort_middle {
                engine::Sort::Middle
            } else {
                engine::Sort::Last
            },
        };
        plan.check(height).map_err(|e| bad(e.to_string()))?;
        let long = |v: &String| v.is_empty() || v.len() > MAX_ADDR_BYTES;
        if b.peers.iter().chain(&b.sessions).any(long) || b.tls_domain.len() > 256 {
            return Err(bad("a worker's address or session is empty or too long"));
        }
        if b.wait_ms > 600_000 {
            return Err(bad(format!("a wait of {} ms for the stripes", b.wait_ms)));
        }
        Ok(Bands {
            round: b.round,
            plan,
            peers: b
                .peers
                .iter()
                .cloned()
                .zip(b.sessions.iter().cloned())
                .collect(),
            wait: std::time::Duration::from_millis(u64::from(b.wait_ms)),
            tls_domain: (!b.tls_domain.is_empty()).then(|| b.tls_domain.clone()),
        })
    }
}

/// Receives the swept columns of a Draw call, light by light, into slabs
/// of every column (those not sent empty).
#[derive(Debug)]
pub(crate) struct ColumnsReader {
    lights: Vec<Option<(LightFrame, ColumnSlab)>>,
    /// The last column received of the current light.
    next: Option<u32>,
    current: Option<u32>,
}

impl ColumnsReader {
    /// For a job of `lights` lights.
    pub(crate) fn new(lights: usize) -> ColumnsReader {
        ColumnsReader {
            lights: vec![None; lights],
            next: None,
            current: None,
        }
    }

    /// The most bytes [`add`](Self::add)ing `c` allocates, for a budget
    /// to admit before: 8 a depth (the depth and its step, unpacked), and
    /// for a light's frame a span per column.
    pub(crate) fn bytes_to_add(c: &pb::DrawChunk) -> u64 {
        let cells: u64 =
            c.lo.iter()
                .zip(&c.hi)
                .map(|(&lo, &hi)| u64::from(hi.saturating_sub(lo)) + 1)
                .sum();
        let side = c.map.as_ref().map_or(0, |m| m.n_cells.min(MAX_CELLS)) as u64;
        cells * 8 + side * side * std::mem::size_of::<Span>() as u64
    }

    /// Adds a chunk's columns, checked.
    pub(crate) fn add(&mut self, c: &pb::DrawChunk) -> Result<(), Malformed> {
        self.add_within(c, 0..usize::MAX)
    }

    /// [`add`](Self::add), refusing a column outside `allowed`.
    pub(crate) fn add_within(
        &mut self,
        c: &pb::DrawChunk,
        allowed: std::ops::Range<usize>,
    ) -> Result<(), Malformed> {
        let l = c.light as usize;
        if l >= self.lights.len() {
            return Err(bad(format!(
                "columns of light {l} in a job of {} lights",
                self.lights.len()
            )));
        }
        if c.map.is_some() {
            if self.lights[l].is_some() {
                return Err(bad(format!("light {l}'s frame comes twice")));
            }
            let frame = frame_from_pb(c.map.as_ref())?;
            let columns = frame.columns() as u32;
            self.lights[l] = Some((
                frame,
                ColumnSlab {
                    columns: 0..columns,
                    spans: vec![Span::EMPTY; columns as usize],
                    depth: Vec::new(),
                },
            ));
            self.current = Some(c.light);
            self.next = None;
        } else if self.current != Some(c.light) {
            return Err(bad(format!("columns of light {l} before its frame")));
        }
        let (frame, slab) = self.lights[l].as_mut().expect("set above");
        let n = frame.n_cells as usize;
        let count = column_count(&c.column_steps, &c.lo, &c.hi, &c.front)?;
        let mut need = 0usize;
        let mut col = 0u64;
        let mut cols = Vec::with_capacity(count);
        for i in 0..count {
            col = if i == 0 {
                u64::from(c.column_steps[0])
            } else if c.column_steps[i] == 0 {
                return Err(bad(format!("column {col} comes twice")));
            } else {
                col + u64::from(c.column_steps[i])
            };
            let (lo, hi) = (c.lo[i] as usize, c.hi[i] as usize);
            if col >= (n * n) as u64
                || !allowed.contains(&(col as usize))
                || self.next.is_some_and(|p| col <= u64::from(p))
                || lo > hi
                || hi >= n
            {
                return Err(bad(format!(
                    "column {col} with cells {lo}..={hi} out of order or out of a map of {n} a side"
                )));
            }
            need += hi - lo + 1;
            cols.push(col as u32);
            if i + 1 == count {
                self.next = Some(col as u32);
            }
        }
        if slab.depth.len() + need > n * n * n {
            return Err(bad("more depths than the map has cells"));
        }
        let mut steps = Vec::new();
        unpack_runs(&c.depth_steps, need, &mut steps)?;
        let mut at = 0;
        for (i, &col) in cols.iter().enumerate() {
            let (lo, hi) = (c.lo[i] as u16, c.hi[i] as u16);
            let len = usize::from(hi - lo) + 1;
            slab.spans[col as usize] = Span {
                lo,
                hi,
                start: slab.depth.len() as u32,
                front: c.front[i],
            };
            let mut depth = 0u32;
            for &s in &steps[at..at + len] {
                depth = depth
                    .checked_add(s)
                    .ok_or_else(|| bad(format!("a depth past 2^32 steps in column {col}")))?;
                slab.depth.push(depth);
            }
            at += len;
        }
        Ok(())
    }

    /// The transmittance of every light, once each light's frame came (the
    /// spans are checked as the map's own are).
    pub(crate) fn finish(self) -> Result<Vec<shadow::Transmittance>, Malformed> {
        self.lights
            .into_iter()
            .enumerate()
            .map(|(l, x)| {
                let (frame, slab) = x.ok_or_else(|| bad(format!("no columns of light {l}")))?;
                shadow::Transmittance::assemble(frame, [slab]).map_err(|e| bad(e.to_string()))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests;
