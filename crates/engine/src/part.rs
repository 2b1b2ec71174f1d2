//! The stages that run per drawn vertex (filter, shade) and the
//! rasterization of some drawn hair: all of it in one process, or a
//! cluster worker's share. The same code either way, so the same bytes.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::Vec3;
use raster::{
    Camera, Canvas, DualTable, FiberOptics, FiberTable, HairLook, Shading, ShadingModel, Sphere,
    kajiya_kay,
};
use rayon::prelude::*;
use shadow::Light;
use strands::Hair;

use crate::bounce::{HairIn, HeadLight, Through};
use crate::{HairSource, Head, Scene};

/// Hair colour when neither the style nor the file gives one (linear RGB).
pub const DEFAULT_HAIR_COLOR: Vec3 = Vec3::new(0.30, 0.17, 0.08);

/// The per-vertex results of some drawn hair, kept between its stages.
#[derive(Debug, Default, Clone)]
pub struct HairPart {
    /// Transmittance of each light at each vertex: `[light][vertex]`.
    trans: Vec<Vec<f32>>,
    /// The head's irradiance at each vertex and its transmittance there,
    /// when the head lights the hair ([`Self::filter_head`]).
    head_in: Vec<Through>,
    /// That head's light: its centre for the shading, and the sky over
    /// the head's own pixels ([`Self::sky_over_head`]).
    head: Option<HeadLight>,
    /// The shaded linear colour of each vertex.
    colors: Vec<Vec3>,
    /// The fiber tables made so far, by the optics they tabulate (one per
    /// strand colour when the absorption follows the colour).
    tables: Vec<(FiberOptics, Tables)>,
}

/// What shading with one fiber needs: its single scattering, and its
/// dual scattering once multiple scattering is asked for.
#[derive(Debug, Clone)]
struct Tables {
    single: Arc<FiberTable>,
    dual: Option<Arc<DualTable>>,
}

/// Vertices of a strand between two lookups of the head's light
/// ([`HairPart::filter_head`]).
pub(crate) const HEAD_STRIDE: usize = 4;

/// The most fiber tables kept: a groom of more distinct strand colours
/// than this has them rounded to fewer (see [`HairPart::shade`]).
const MAX_TABLES: usize = 64;

impl HairPart {
    /// Transmittance of each light at each vertex of the last
    /// [`Self::filter`]: `[light][vertex]`.
    pub fn transmittance(&self) -> &[Vec<f32>] {
        &self.trans
    }

    /// The shaded colour of each vertex in the last [`Self::shade`].
    pub fn colors(&self) -> &[Vec3] {
        &self.colors
    }

    /// Shadow stage 3: the transmittance of each of `lights` lights at
    /// every vertex of `hair`, `lookup(light, points, out)` filling `out`.
    pub fn filter(
        &mut self,
        hair: &Hair,
        lights: usize,
        lookup: impl Fn(usize, &[Vec3], &mut [f32]),
    ) {
        // The head's light of this hair, if any, comes after
        // (`filter_head`).
        self.head_in.clear();
        self.head = None;
        self.trans.resize(lights, Vec::new());
        for (l, t) in self.trans.iter_mut().enumerate() {
            t.resize(hair.point_count(), 0.0);
            lookup(l, hair.points(), t);
        }
    }

    /// The light the head sends to every vertex of `hair`, `head`'s (see
    /// the engine's `bounce` module): its irradiance there, its transmittance through
    /// the hair between, and the cone it comes from. It changes slowly
    /// along a strand (over the head's size): looked up at every
    /// fourth vertex of each strand (`HEAD_STRIDE`) and its last, linear
    /// between.
    pub(crate) fn filter_head(&mut self, hair: &Hair, head: HeadLight) {
        let (points, offsets) = (hair.points(), hair.offsets());
        self.head_in.clear();
        self.head_in.resize(points.len(), Through::NONE);
        let mut strands: Vec<&mut [Through]> = Vec::with_capacity(hair.strand_count());
        let mut rest = &mut self.head_in[..];
        for w in offsets.windows(2) {
            let (a, b) = rest.split_at_mut((w[1] - w[0]) as usize);
            strands.push(a);
            rest = b;
        }
        strands
            .into_par_iter()
            .enumerate()
            .with_min_len(64)
            .for_each(|(s, out)| {
                let pts = &points[offsets[s] as usize..][..out.len()];
                along_strand(
                    out,
                    |i| head.through_at(pts[i]).unwrap_or(Through::NONE),
                    Through::lerp,
                );
            });
        self.head = Some(head);
    }

    /// The sky's transmittance at the head's surface point `p`, through
    /// the hair over it, when the head's light was filtered this frame
    /// ([`HeadLight::sky_over`]).
    pub(crate) fn sky_over_head(&self, p: Vec3) -> Option<f32> {
        self.head.as_ref()?.sky_over(p)
    }

    /// Whether the head's light was filtered this frame.
    pub(crate) fn has_head_light(&self) -> bool {
        self.head.is_some()
    }

    /// Where the tables of `optics` are kept, made now (single
    /// scattering) if they were not, the oldest dropped past
    /// [`MAX_TABLES`].
    fn table_at(&mut self, optics: &FiberOptics) -> usize {
        if let Some(at) = self.tables.iter().position(|(k, _)| k == optics) {
            return at;
        }
        if self.tables.len() >= MAX_TABLES {
            self.tables.remove(0);
        }
        let single = Arc::new(FiberTable::new(optics));
        self.tables.push((*optics, Tables { single, dual: None }));
        self.tables.len() - 1
    }

    /// A fiber's tables with multiple scattering, for `optics`: what the
    /// head's own shading takes the light the hair scatters forward from
    /// (made once, kept with the strands' tables).
    pub fn dual_table(&mut self, optics: &FiberOptics) -> Arc<DualTable> {
        let at = self.table_at(optics);
        let t = &mut self.tables[at].1;
        t.dual
            .get_or_insert_with(|| Arc::new(DualTable::new(optics)))
            .clone()
    }

    /// Shading at every vertex of `hair` with its strand's colour, seen
    /// as `seen` says (strands a simplified look leaves out of the picture
    /// get no colour: black), lit by `lights` (each from its direction at the vertex,
    /// scaled by its falloff there, [`Light::falloff`]) through the
    /// transmittance of the last [`Self::filter`] (`shadows`) or by full
    /// light: Kajiya-Kay, or a physically based fiber (its
    /// [`FiberTable`]), as `shading.model` says. The ambient term is added
    /// once. With multiple scattering, the light the head sends is added
    /// where the last filter looked it up for this hair.
    pub fn shade(
        &mut self,
        hair: &Hair,
        seen: Seen<'_>,
        shading: &Shading,
        lights: &[Light],
        shadows: bool,
    ) {
        let eye = seen.camera.position;
        let points = hair.points();
        if shadows {
            assert!(
                self.trans.len() == lights.len()
                    && self.trans.iter().all(|t| t.len() == points.len()),
                "filter runs before shading with shadows"
            );
        }
        let fiber = match shading.model {
            ShadingModel::Marschner {
                optics,
                from_color,
                irradiance,
                multiple,
            } => {
                // Only with the shadow stages' transmittance to scatter.
                let multiple = multiple && shadows;
                Some((
                    self.fiber_tables(hair, &optics, from_color, multiple),
                    irradiance,
                ))
            }
            ShadingModel::KajiyaKay => None,
        };
        // The head's light is scattered light: with multiple scattering.
        let head = shadows
            && self.head_in.len() == points.len()
            && matches!(
                shading.model,
                ShadingModel::Marschner { multiple: true, .. }
            );
        let head_in = &self.head_in[..];
        let head_center = self.head.as_ref().map_or(Vec3::ZERO, HeadLight::center);
        self.colors.resize(points.len(), Vec3::ZERO);
        let offsets = hair.offsets();
        let strand_colors = hair.colors();
        let trans = &self.trans;
        // Strands in parallel; each writes its own vertices.
        let mut chunks: Vec<&mut [Vec3]> = Vec::with_capacity(hair.strand_count());
        let mut rest: &mut [Vec3] = &mut self.colors;
        for w in offsets.windows(2) {
            let (a, b) = rest.split_at_mut((w[1] - w[0]) as usize);
            chunks.push(a);
            rest = b;
        }
        let rest_lights = Shading {
            ambient: 0.0,
            ..*shading
        };
        chunks
            .into_par_iter()
            .enumerate()
            .with_min_len(64)
            .for_each(|(si, out)| {
                let base = offsets[si] as usize;
                let pts = &points[base..base + out.len()];
                let strand = seen.first_strand + si as u32;
                if !seen.look.may_draw_strand(seen.camera, pts, strand) {
                    out.fill(Vec3::ZERO);
                    return;
                }
                let strand_color = strand_colors.map_or(DEFAULT_HAIR_COLOR, |c| c[si]);
                let table = fiber
                    .as_ref()
                    .map(|((tables, of_strand), e)| (&tables[of_strand[si] as usize], *e));
                // Tangent by central differences (one-sided at the ends),
                // and the unit direction to the eye.
                let axes = |v: usize| {
                    let (a, b) = (pts[v.saturating_sub(1)], pts[(v + 1).min(pts.len() - 1)]);
                    let tangent = (b - a).normalize_or(Vec3::Y);
                    (tangent, (eye - pts[v]).normalize_or(Vec3::Z))
                };
                // The sky's transmittance: through the hair about the head
                // where the head's map holds it, else the lights' mean.
                let sky_t = |v: usize| {
                    if let Some(t) = head.then(|| head_in[base + v].sky).flatten() {
                        t
                    } else if !shadows || lights.is_empty() {
                        1.0
                    } else {
                        (0..lights.len()).map(|l| trans[l][base + v]).sum::<f32>()
                            / lights.len() as f32
                    }
                };
                // The head's light and the sky it hides, per vertex: at
                // every HEAD_STRIDE-th vertex and the last, linear between
                // (they change over the head's size, not a strand's step).
                let mut head_terms: Vec<(Vec3, Vec3)> = Vec::new();
                if let Some((tables, _)) = table
                    && head
                    && let Some(dual) = &tables.dual
                {
                    head_terms.resize(out.len(), (Vec3::ZERO, Vec3::ZERO));
                    along_strand(
                        &mut head_terms,
                        |v| {
                            let (tangent, to_eye) = axes(v);
                            head_term(
                                dual,
                                head_in[base + v],
                                (pts[v], head_center),
                                (tangent, to_eye),
                                sky_t(v),
                                shading.ambient,
                            )
                        },
                        |a, b, f| (a.0 + (b.0 - a.0) * f, a.1 + (b.1 - a.1) * f),
                    );
                }
                for (v, o) in out.iter_mut().enumerate() {
                    let (tangent, to_eye) = axes(v);
                    let p = pts[v];
                    // Each light's direction towards it and its falloff
                    // (1 for a directional light: the same bits).
                    let at = |l: &Light| (-l.direction_at(p), l.falloff(p));
                    let tr = |l: usize| if shadows { trans[l][base + v] } else { 1.0 };
                    *o = match table {
                        None => lights
                            .iter()
                            .enumerate()
                            .map(|(l, light)| {
                                let sh = if l == 0 { shading } else { &rest_lights };
                                let (to_light, scale) = at(light);
                                kajiya_kay(
                                    sh,
                                    strand_color,
                                    tangent,
                                    to_light,
                                    to_eye,
                                    tr(l) * scale,
                                )
                            })
                            .fold(Vec3::ZERO, |c, x| c + x),
                        Some((tables, irradiance)) => {
                            let uo = tangent.dot(to_eye).clamp(-1.0, 1.0);
                            // The sky: radiance `k_a` from every direction,
                            // shadowed by the same maps (their mean
                            // transmittance, so no light reaches the hair
                            // unshadowed), and scattered by the fiber as
                            // the lights are, multiple scattering
                            // included; where the head's light is known,
                            // less the cone of it the head hides (below).
                            let sky = sky_t(v);
                            let mut sky_light = match &tables.dual {
                                _ if shading.ambient <= 0.0 => Vec3::ZERO,
                                Some(dual) => shading.ambient * dual.sky(uo, sky),
                                None => shading.ambient * sky * tables.single.sky(uo),
                            };
                            let mut c = Vec3::ZERO;
                            let incidence =
                                |to_light: Vec3| incidence(tangent, to_light, to_eye, uo);
                            if let Some(&(from_head, hidden)) = head_terms.get(v) {
                                c += from_head;
                                sky_light -= hidden;
                            }
                            c += sky_light.max(Vec3::ZERO);
                            for (l, light) in lights.iter().enumerate() {
                                let (to_light, scale) = at(light);
                                let (ui, cos_phi) = incidence(to_light);
                                let single = tables.single.radiance(ui, uo, cos_phi);
                                match &tables.dual {
                                    Some(dual) => {
                                        let r = dual.radiance(single, tr(l), ui, uo, cos_phi);
                                        c += irradiance * scale * r;
                                    }
                                    None => c += tr(l) * scale * irradiance * single,
                                }
                            }
                            debug_assert!(c.is_finite());
                            c
                        }
                    };
                }
            });
    }

    /// The fiber tables for shading `hair` with `optics` (its absorption
    /// following each strand's colour, `from_color`, rounded to steps of
    /// 1/32 so that a groom's colours make few tables), made now where not
    /// kept, and each strand's table; with the dual-scattering tables if
    /// `dual`. The same tables whichever strands a part holds: a strand's
    /// table depends on its colour alone.
    fn fiber_tables(
        &mut self,
        hair: &Hair,
        optics: &FiberOptics,
        from_color: bool,
        dual: bool,
    ) -> (Vec<Tables>, Vec<u32>) {
        // Each strand's key: its colour rounded (all alike when the colour
        // does not set the absorption); the optics only per distinct key.
        let colors = hair.colors();
        let key = |s: usize| {
            if from_color {
                let c = colors.map_or(DEFAULT_HAIR_COLOR, |c| c[s]);
                ((c * 32.0).round() / 32.0).to_array().map(f32::to_bits)
            } else {
                [0; 3]
            }
        };
        let mut keys: Vec<[u32; 3]> = Vec::new();
        let of_strand: Vec<u32> = (0..hair.strand_count())
            .map(|s| {
                let k = key(s);
                let i = keys.iter().position(|u| *u == k).unwrap_or_else(|| {
                    keys.push(k);
                    keys.len() - 1
                });
                i as u32
            })
            .collect();
        let used: Vec<FiberOptics> = keys
            .iter()
            .map(|k| {
                if from_color {
                    FiberOptics {
                        sigma_a: raster::sigma_a_from_color(
                            Vec3::from_array(k.map(f32::from_bits)),
                            optics.beta_n,
                        ),
                        ..*optics
                    }
                } else {
                    *optics
                }
            })
            .collect();
        let tables = used
            .iter()
            .map(|o| {
                let at = self.table_at(o);
                let t = &mut self.tables[at].1;
                if dual && t.dual.is_none() {
                    t.dual = Some(Arc::new(DualTable::new(o)));
                }
                t.clone()
            })
            .collect();
        (tables, of_strand)
    }

    /// Bins `hair` for drawing on `canvas` as `seen` says, with the
    /// colours of the last [`Self::shade`], in groups `groups` (strand
    /// boundaries, see [`Canvas::draw_hair`]).
    pub fn draw(&self, hair: &Hair, seen: Seen<'_>, groups: &[u32], canvas: &mut Canvas) {
        assert_eq!(
            self.colors.len(),
            hair.point_count(),
            "shade runs before draw"
        );
        canvas.draw_hair(
            seen.camera,
            hair.points(),
            hair.offsets(),
            &self.colors,
            seen.look,
            groups,
            seen.first_strand,
        );
    }
}

/// The picture a part is shaded for: the camera, the look (a simplified
/// look leaves strands out) and the index of the part's first strand in
/// the whole hair.
#[derive(Debug, Clone, Copy)]
pub struct Seen<'a> {
    /// The camera (its position is the eye).
    pub camera: &'a Camera,
    /// How the strands are drawn.
    pub look: &'a HairLook,
    /// The index of the part's first strand in the whole hair.
    pub first_strand: u32,
}

/// `sin theta_i` of light from `to_light` at a fiber of unit `tangent`,
/// and `cos phi` between its and the eye's directions across the fiber
/// (`uo = sin theta_o` of `to_eye`), from unit vectors: `(l . e - sin_i
/// sin_o) / (cos_i cos_o)`; 1 when either runs along the fiber.
#[inline]
fn incidence(tangent: Vec3, to_light: Vec3, to_eye: Vec3, uo: f32) -> (f32, f32) {
    let ui = tangent.dot(to_light).clamp(-1.0, 1.0);
    let d = ((1.0 - ui * ui) * (1.0 - uo * uo)).sqrt();
    let cos_phi = if d > 1e-6 {
        (to_light.dot(to_eye) - ui * uo) / d
    } else {
        1.0
    };
    (ui, cos_phi)
}

/// `out[v] = term(v)` at every [`HEAD_STRIDE`]-th vertex of a strand and
/// its last, `lerp(a, b, f)` of the two about it between: what changes
/// over the head's size, not a strand's step.
fn along_strand<T: Copy>(out: &mut [T], term: impl Fn(usize) -> T, lerp: impl Fn(T, T, f32) -> T) {
    let Some(first) = out.first_mut() else {
        return;
    };
    let mut a = term(0);
    *first = a;
    let mut i = 0;
    while i + 1 < out.len() {
        let j = (i + HEAD_STRIDE).min(out.len() - 1);
        let b = term(j);
        for (k, o) in out[i + 1..j].iter_mut().enumerate() {
            *o = lerp(a, b, (k + 1) as f32 / (j - i) as f32);
        }
        out[j] = b;
        (i, a) = (j, b);
    }
}

/// At a vertex `p` of unit tangent and direction to the eye `axes`, with
/// the head's light `head` ([`HeadLight::through_at`]: `E_h`, `T_h`,
/// `sin alpha`) from the head centred at `center`: the radiance the fiber
/// sends to the eye of it (the cone's light as from its mean angle along
/// the fiber, the lobes spread as the cone is, [`raster::cone_light`]),
/// and of the sky of radiance `ambient` the head hides over that cone,
/// `Omega = 2 pi (1 - cos alpha)` of it: through the hair between as the
/// head's light comes where the head's map gives the sky's transmittance
/// (the sky behind the head would cross that hair), else at the sky's
/// transmittance `sky_t`.
fn head_term(
    dual: &DualTable,
    head: Through,
    (p, center): (Vec3, Vec3),
    (tangent, to_eye): (Vec3, Vec3),
    sky_t: f32,
    ambient: f32,
) -> (Vec3, Vec3) {
    let Through {
        e,
        t,
        sin_alpha,
        sky,
    } = head;
    if sin_alpha.is_nan() || sin_alpha <= 0.0 || (ambient <= 0.0 && e.max_element() <= 0.0) {
        return (Vec3::ZERO, Vec3::ZERO);
    }
    let to_head = (center - p).normalize_or_zero();
    let uo = tangent.dot(to_eye).clamp(-1.0, 1.0);
    let (ui, cos_phi) = incidence(tangent, to_head, to_eye, uo);
    let cone = raster::cone_light(sin_alpha, ui);
    let at = (cone.sin_theta, uo, cos_phi);
    let omega = 2.0 * PI * (1.0 - (1.0 - sin_alpha * sin_alpha).max(0.0).sqrt());
    if ambient <= 0.0 || sky.is_some() {
        // The hidden sky, if any, crosses the head's light's hair.
        let [from_head] = dual.radiance_spread([t], at, cone.spread, cone.across);
        let r = cone.factor * from_head;
        (e * r, ambient.max(0.0) * omega * r)
    } else {
        let [from_head, hidden] = dual.radiance_spread([t, sky_t], at, cone.spread, cone.across);
        (
            e * cone.factor * from_head,
            ambient * omega * cone.factor * hidden,
        )
    }
}

/// A point of the head's surface as [`head_lambert`] shades it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HeadPoint {
    pub(crate) p: Vec3,
    /// Its unit normal.
    pub(crate) n: Vec3,
    /// The sky's transmittance through the hair over it, where the head's
    /// map gives it ([`HairPart::sky_over_head`]).
    pub(crate) sky: Option<f32>,
}

/// The head's colour at a surface point `p` of unit normal `n`: Lambert
/// under the hair's shadow,
///
/// ```text
/// Phi = k_a T_sky C + sum_l s E_l T_l C max(n . L_l, 0)
/// ```
///
/// with `C` the head's linear colour, `k_a` the ambient share, `L_l` the
/// unit direction towards light `l` at `p`, `E_l` its falloff there
/// ([`Light::falloff`], 1 for a directional light) and `T_l` its
/// transmittance there, `trans(l)` (asked where the light reaches the
/// surface, and for the sky). With Kajiya-Kay `s = 1 - k_a` (the paper's
/// split) and `T_sky = 1`; with the physically based fiber `s = E / pi`,
/// a diffuse surface of albedo `C` under the irradiance `E` that lights
/// the hair (radiance `C E cos / pi`, as a path tracer's diffuse surface
/// under a sun of strength `E`), and the sky of radiance `k_a` through
/// the hair over the point, `T_sky` the point's `sky`
/// ([`crate::bounce::surface_sky_transmittance`]), or where the head's
/// map does not give it, the lights' mean transmittance (as the hair's).
///
/// With `forward` (multiple scattering), the light the hair scatters
/// forward reaches the head too: `T_l` becomes the hair's forward
/// transmittance `T_f >= T_l` of that fiber ([`DualTable::forward_transmittance`],
/// at normal incidence), the light a diffuse surface under the hair
/// gathers whatever direction the hair turned it.
pub(crate) fn head_lambert(
    color: Vec3,
    shading: &Shading,
    lights: &[Light],
    at: HeadPoint,
    forward: Option<&DualTable>,
    trans: impl Fn(usize) -> f32,
) -> Vec3 {
    let HeadPoint {
        p,
        n,
        sky: sky_over,
    } = at;
    let ambient = shading.ambient;
    let s = match shading.model {
        ShadingModel::KajiyaKay => 1.0 - ambient,
        ShadingModel::Marschner { irradiance, .. } => irradiance / std::f32::consts::PI,
    };
    let through = |l: usize| {
        let t = trans(l);
        forward.map_or(Vec3::splat(t), |f| {
            f.forward_transmittance(t, 0.0).max(Vec3::splat(t))
        })
    };
    // The sky: Kajiya-Kay's ambient term unshadowed, as the paper has
    // it; under the physically based fiber, radiance `k_a` from every
    // direction (radiance `C k_a` off a diffuse surface), through the
    // hair over the point (`sky_over`, from the head's map), else
    // shadowed by the lights' mean transmittance.
    let shadowed_sky = matches!(shading.model, ShadingModel::Marschner { .. })
        && ambient > 0.0
        && !lights.is_empty();
    // Every light's transmittance, lit or not, only for their mean.
    let mean_sky = shadowed_sky && sky_over.is_none();
    let (mut c, mut sky) = (Vec3::ZERO, Vec3::ZERO);
    for (l, light) in lights.iter().enumerate() {
        let lambert = n.dot(-light.direction_at(p)).max(0.0);
        let scale = light.falloff(p);
        let lit = lambert > 0.0 && scale > 0.0;
        if !(lit || mean_sky) {
            continue;
        }
        let t = through(l);
        sky += t;
        if lit {
            c += t * scale * lambert * s * color;
        }
    }
    let sky = match (shadowed_sky, sky_over) {
        (true, Some(t)) => Vec3::splat(t),
        (true, None) => sky / lights.len() as f32,
        (false, _) => Vec3::ONE,
    };
    c += ambient * sky * color;
    c
}

/// The fiber the head's light is scattered by on its way to the head,
/// when `scene` has the head light the hair: multiple scattering with the
/// fiber model and self-shadowing, a head, and `effects.head_bounce`. The
/// scene's fiber; where the strands' colours set the absorption, the
/// style's colour (the default hair colour for files).
pub(crate) fn head_optics(scene: &Scene) -> Option<FiberOptics> {
    let ShadingModel::Marschner {
        optics, from_color, ..
    } = scene.shading.model
    else {
        return None;
    };
    let e = &scene.effects;
    if !(e.multiple_scattering && e.self_shadow && e.head_bounce && scene.head.is_some()) {
        return None;
    }
    if !from_color {
        return Some(optics);
    }
    let color = match &scene.hair {
        HairSource::Style(p) => p.color.unwrap_or(DEFAULT_HAIR_COLOR),
        _ => DEFAULT_HAIR_COLOR,
    };
    Some(FiberOptics {
        sigma_a: raster::sigma_a_from_color(color, optics.beta_n),
        ..optics
    })
}

/// The head's light for this frame, through the hair between: `head` as
/// posed, shaded as its pixels are (the lights and the sky),
/// `trans(light, x, n)` its transmittance at its point
/// `x` of normal `n`, `forward` the fiber that scatters the light on its
/// way; the hair between as the map of the first of `lights` (not empty)
/// has it, in `frame`, read as `hair` says (a method without a map:
/// unattenuated).
pub(crate) fn head_light(
    head: &Head,
    shading: &Shading,
    lights: &[Light],
    forward: &DualTable,
    frame: Option<&shadow::LightFrame>,
    trans: impl Fn(usize, Vec3, Vec3) -> f32,
    hair: HairIn<'_>,
) -> HeadLight {
    let color = head.settings().color;
    // The head sends back what lights it: the lights and the sky, as it
    // is drawn.
    // The head's map first: the sky over the head, that it sends back.
    let mut light = head_map(head, lights, frame, hair);
    let caps = light.caps_of(|x, n| {
        let at = HeadPoint {
            p: x,
            n,
            sky: light.sky_over(x),
        };
        head_lambert(color, shading, lights, at, Some(forward), |l| {
            trans(l, x, n)
        })
    });
    light.light_with(caps);
    light
}

/// The head's map alone (see [`head_light`]): the hair between the head
/// and the open sky, for the sky over the head's own pixels; the head
/// sends no light.
pub(crate) fn head_map(
    head: &Head,
    lights: &[Light],
    frame: Option<&shadow::LightFrame>,
    hair: HairIn<'_>,
) -> HeadLight {
    let mut light = HeadLight::unlit(head.shape());
    if let Some(f) = frame {
        light.through_hair(&lights[0], f.ds, f.n_cells, hair);
    }
    light
}

/// Draws `head` into `canvas`'s opaque layer, `shade(point, normal)`
/// giving the colour of a visible surface point (the hair drawn after it
/// is hidden where the head is in front, whatever the colour).
pub fn draw_head(
    canvas: &mut Canvas,
    camera: &Camera,
    head: &Head,
    shade: impl Fn(Vec3, Vec3) -> Vec3 + Sync,
) {
    match head.mesh() {
        Some(m) => canvas.draw_mesh(camera, m.positions(), m.normals(), m.triangles(), shade),
        None => canvas.draw_sphere(
            camera,
            &Sphere {
                center: head.center(),
                radius: head.settings().radius,
            },
            shade,
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn multiple_scattering_runs_only_when_asked_for_and_with_the_shadow() {
        let mut hair = Hair::new();
        hair.push_strand(&[Vec3::ZERO, Vec3::Y, Vec3::new(0.0, 2.0, 0.3)])
            .unwrap();
        let shading = |multiple| Shading {
            model: ShadingModel::Marschner {
                optics: FiberOptics::default(),
                from_color: false,
                irradiance: 5.0,
                multiple,
            },
            ..Shading::default()
        };
        let camera = Camera::new(Vec3::new(0.0, 1.0, 10.0), Vec3::ZERO, 30.0, 64, 48).unwrap();
        let look = HairLook {
            fiber_width: 0.1,
            opacity: 0.85,
            depth_ref: 10.0,
            simplify: 0.0,
        };
        let seen = Seen {
            camera: &camera,
            look: &look,
            first_strand: 0,
        };
        let lights = [Light::directional(-Vec3::new(1.0, 0.2, 0.1)).unwrap()];
        let shaded = |multiple, shadows| {
            let mut part = HairPart::default();
            part.filter(&hair, 1, |_, _, t| t.fill(0.2));
            part.shade(&hair, seen, &shading(multiple), &lights, shadows);
            let duals = part.tables.iter().filter(|(_, t)| t.dual.is_some()).count();
            (part.colors().to_vec(), duals)
        };
        let (single, none) = shaded(false, true);
        assert_eq!(none, 0, "no dual-scattering table without the effect");
        let (multiple, one) = shaded(true, true);
        assert_eq!(one, 1);
        assert!(multiple.iter().zip(&single).all(|(m, s)| m.cmpge(*s).all()) && multiple != single);
        // Without the shadow stages there is nothing to scatter.
        let (unshadowed, none) = shaded(true, false);
        assert_eq!(none, 0);
        assert_eq!(unshadowed, shaded(false, false).0);
    }
}
