//! `[hair]` from files and inline strands: the groom's unit, its placement.

use super::raw::RawHair;
use super::{
    DEFAULT_FOLLOW_RADIUS, DEFAULT_SUBDIVIDE, DEFAULT_TFX_FOLLOWERS, MAX_INLINE_POINTS, Validator,
};
use crate::{HairSource, Placement, SceneError};
use glam::Vec3;
use std::path::Path;
use strands::{FollowParams, Hair, Style, StyleParams};

impl Validator<'_> {
    /// The length unit the groom at `path`, placed by `place`, appears to
    /// be measured in, relative to the centimetres the length defaults
    /// (fiber width, follow radius) assume: with `L` the largest side of
    /// its bounds,
    ///
    /// ```text
    /// unit = 10^floor(log10(L / 10))
    /// ```
    ///
    /// 1 for a groom 10 to 100 units across (centimetres: a head is about
    /// 16 to 20 across, long hair under 100), 10 for 100 to 1000
    /// (millimetres), 0.01 for 0.1 to 1 (metres); at most 10^4 either way,
    /// 1 for an empty groom. Reads the groom at `sample` (from the
    /// scene's files when held there).
    /// Also gives the file's strand count, and the median of its widths
    /// when it gives widths (Alembic, USD; the file's units).
    pub(super) fn groom_unit(
        &self,
        path: &Path,
        sample: u32,
        place: &Placement,
    ) -> Result<(f32, u64, Option<f32>), SceneError> {
        let fail = |reason: String| self.invalid("hair.file", path.display(), reason);
        let hair = match self.files.get(path) {
            Some(b) => strands::load_bytes(path, b, sample),
            None => strands::load(path, sample),
        }
        .map_err(|e| fail(e.to_string()))?;
        let strands = hair.strand_count() as u64;
        let width = hair.median_width();
        let b = hair.bounds();
        if b.is_empty() {
            return Ok((1.0, strands, width));
        }
        let side = (b.size() * place.scale).max_element();
        if side.is_nan() || side <= 0.0 {
            return Ok((1.0, strands, width));
        }
        let e = (side / 10.0).log10().floor().clamp(-4.0, 4.0);
        Ok((10f32.powf(e), strands, width))
    }

    /// `hair.scale`, `hair.rotate_deg`, `hair.translate`: finite, the
    /// scale in (0, 1e6], the offset within 1e9 scene units.
    pub(super) fn placement(&self, h: &RawHair) -> Result<Placement, SceneError> {
        let scale = h.scale.unwrap_or(1.0);
        if !(scale > 0.0 && scale <= 1e6) {
            return Err(self.invalid("hair.scale", scale, "must be a number in (0, 1e6]"));
        }
        let three = |field: &'static str, v: Option<[f32; 3]>, max: f32| match v {
            Some(a) if !a.iter().all(|x| x.is_finite() && x.abs() <= max) => Err(self.invalid(
                field,
                format!("{a:?}"),
                format!("each component must be finite, within {max:e}"),
            )),
            v => Ok(Vec3::from_array(v.unwrap_or([0.0; 3]))),
        };
        Ok(Placement {
            scale,
            rotate_deg: three("hair.rotate_deg", h.rotate_deg, 1e6)?,
            translate: three("hair.translate", h.translate, 1e9)?,
        })
    }

    /// `hair.strands`: every coordinate finite, at most
    /// [`MAX_INLINE_POINTS`] points. Strands of one point or none are kept
    /// (they draw and shadow nothing).
    pub(super) fn inline_strands(&self, strands: &[Vec<[f32; 3]>]) -> Result<Hair, SceneError> {
        let points: usize = strands.iter().map(Vec::len).sum();
        if points > MAX_INLINE_POINTS {
            return Err(self.invalid(
                "hair.strands",
                format!("({points} points)"),
                format!("at most {MAX_INLINE_POINTS} points; use hair.file for larger hair"),
            ));
        }
        let mut hair = Hair::new();
        let mut buf = Vec::new();
        for (s, st) in strands.iter().enumerate() {
            buf.clear();
            buf.extend(st.iter().map(|&p| Vec3::from_array(p)));
            if let Some(i) = buf.iter().position(|p| !p.is_finite()) {
                return Err(self.invalid(
                    "hair.strands",
                    format!("{:?}", st[i]),
                    format!("strand {s}, point {i}: coordinates must be finite"),
                ));
            }
            hair.push_strand(&buf).map_err(|e| {
                self.invalid("hair.strands", format!("(strand {s})"), e.to_string())
            })?;
        }
        Ok(hair)
    }
}

/// The hair a scene's `[hair]` asks for, and which lengths follow a
/// groom file's unit once the rest is valid.
pub(super) struct Grown {
    pub(super) hair: HairSource,
    pub(super) subdivide: u32,
    /// The fiber width (not given) scales with the groom's unit.
    pub(super) scale_width: bool,
    /// The follow radius (not given) scales with it.
    pub(super) scale_follow: bool,
}

impl Validator<'_> {
    /// `[hair]`: a style, a groom file or inline strands, each refusing
    /// the keys of the others; `width_unset` when `fiber.width` is not
    /// given (a groom's unit then sets it).
    pub(super) fn hair(&self, h: &RawHair, width_unset: bool) -> Result<Grown, SceneError> {
        let subdivide = self.int("hair.subdivide", h.subdivide, DEFAULT_SUBDIVIDE, 1..=64)?;
        let seed = h.seed.unwrap_or(1);
        let given = [h.style.is_some(), h.file.is_some(), h.strands.is_some()];
        if given.iter().filter(|&&g| g).count() > 1 {
            return Err(self.invalid(
                "hair",
                "(style, file, strands)",
                "give one of hair.style, hair.file and hair.strands",
            ));
        }
        // Keys of follow strands, which only hair from files grows.
        let follow_keys = [
            ("hair.followers", h.followers.is_some()),
            ("hair.follow_radius", h.follow_radius.is_some()),
            ("hair.tip_spread", h.tip_spread.is_some()),
        ];
        let place = self.placement(h)?;
        if h.file.is_none() {
            self.refuse_set(
                &[("hair.sample", h.sample.is_some())],
                "applies to hair.file only",
            )?;
        }
        // Length defaults in centimetres that follow a groom file's unit
        // (set once the rest is valid): the fiber width, the follow radius.
        let mut scale_width = false;
        let mut scale_follow = false;
        let hair = match (&h.strands, &h.file) {
            (Some(strands), _) => {
                self.refuse_set(&follow_keys, "does not apply to hair.strands")?;
                self.refuse_set(
                    &[("hair.seed", h.seed.is_some())],
                    "does not apply to hair.strands",
                )?;
                let mut hair = self.inline_strands(strands)?;
                place.apply(&mut hair);
                HairSource::Inline(hair)
            }
            (None, Some(file)) => {
                let path = self.relative(file);
                let tfx = path
                    .extension()
                    .is_some_and(|e| e.eq_ignore_ascii_case("tfx"));
                let followers = self.int(
                    "hair.followers",
                    h.followers,
                    if tfx { DEFAULT_TFX_FOLLOWERS } else { 0 },
                    0..=1000,
                )?;
                let sample = h
                    .sample
                    .map(|_| self.int("hair.sample", h.sample, 0, 0..=1_000_000))
                    .transpose()?;
                if sample.is_some_and(|s| s > 0) && !strands::is_animated_groom_path(&path) {
                    return Err(self.invalid(
                        "hair.sample",
                        sample.unwrap_or(0),
                        "applies to Alembic (.abc) and USD files, which hold samples",
                    ));
                }
                scale_width = width_unset;
                scale_follow = followers > 0 && h.follow_radius.is_none();
                let radius =
                    self.positive("hair.follow_radius", h.follow_radius, DEFAULT_FOLLOW_RADIUS)?;
                let tip_spread = self.positive("hair.tip_spread", h.tip_spread, 1.5)?;
                let follow = (followers > 0).then_some(FollowParams {
                    followers,
                    radius,
                    tip_spread,
                    seed,
                });
                HairSource::File {
                    path,
                    sample,
                    follow,
                    place,
                }
            }
            (None, None) => {
                self.refuse_set(
                    &[
                        ("hair.scale", h.scale.is_some()),
                        ("hair.rotate_deg", h.rotate_deg.is_some()),
                        ("hair.translate", h.translate.is_some()),
                    ],
                    "places a groom from hair.file or hair.strands; a style grows on the head",
                )?;
                let name = h.style.as_deref().unwrap_or("smooth");
                let style = Style::from_name(name).ok_or_else(|| {
                    self.invalid(
                        "hair.style",
                        format!("{name:?}"),
                        "expected \"smooth\" or \"curly\"",
                    )
                })?;
                self.refuse_set(&follow_keys, "applies to hair.file only")?;
                let mut p = StyleParams::new(style);
                p.seed = seed;
                p.strands_per_wisp = self.int(
                    "hair.strands_per_wisp",
                    h.strands_per_wisp,
                    p.strands_per_wisp,
                    1..=2000,
                )?;
                p.parting = h.parting.unwrap_or(false);
                if h.color.is_some() {
                    p.color = Some(self.color("hair.color", h.color, [0.0; 3])?);
                }
                HairSource::Style(p)
            }
        };
        if !matches!(hair, HairSource::Style(_)) {
            self.refuse_set(
                &[
                    ("hair.strands_per_wisp", h.strands_per_wisp.is_some()),
                    ("hair.parting", h.parting.is_some()),
                    ("hair.color", h.color.is_some()),
                ],
                "applies to hair.style only",
            )?;
        }
        Ok(Grown {
            hair,
            subdivide,
            scale_width,
            scale_follow,
        })
    }
}

/// A real hair's width, cm (70 um): a groom file's default fiber width,
/// in its unit, when it has a real head's strands (see
/// [`groom_fiber_width`]).
pub(crate) const HUMAN_HAIR_WIDTH_CM: f32 = 0.007;
/// The strands of a real head of hair: a groom with fewer draws each wider,
/// so that it covers as much (see [`groom_fiber_width`]).
pub(crate) const HEAD_OF_HAIR_STRANDS: f32 = 100_000.0;

/// A groom file's default fiber width, its scene units: a real hair's
/// width in the groom's length `unit` (units per cm: 1 for cm, 10 for mm), widened for
/// a groom of fewer strands than a head of hair so that it covers as much
/// (the summed width of the strands `N w` held at a real head's):
///
/// ```text
/// w = unit * min(w_styles, w_hair * max(1, N_head / N))
/// ```
///
/// with `w_hair` = 70 um ([`HUMAN_HAIR_WIDTH_CM`]), `N_head` = 100,000
/// ([`HEAD_OF_HAIR_STRANDS`]), `N` the strands drawn (the file's times one
/// plus the followers of each) and at most the styles' 1 mm
/// (`DEFAULT_FIBER_WIDTH`, reached below 7,000 strands).
pub(super) fn groom_fiber_width(unit: f32, strands: u64) -> f32 {
    let sparse = HEAD_OF_HAIR_STRANDS / (strands.max(1) as f32);
    unit * (HUMAN_HAIR_WIDTH_CM * sparse.max(1.0)).min(super::DEFAULT_FIBER_WIDTH)
}
