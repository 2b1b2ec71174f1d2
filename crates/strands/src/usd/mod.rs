//! USD grooms: the `BasisCurves` of a `.usda`, `.usdc` or `.usdz` stage,
//! placed by their prims' transforms, at one time sample.
//!
//! Read with the openusd crate (a pure-Rust USD, the stage composed as
//! USD composes it). The stage is opened from the file's bytes alone:
//! layers it references or sublayers are not read (they would be other
//! files, which a cluster's workers do not have), and are named in the
//! error; flatten such a stage into one file first (`usdcat --flatten`).
//!
//! Each `BasisCurves` prim gives its `points`, `curveVertexCounts`,
//! `widths` (constant, uniform, varying or vertex), `type`, `basis` and
//! `wrap`; its transform is the product of its own and its ancestors'
//! `xformOp`s up to a `!resetXformStack!`. Sample `k` is the `k`-th time
//! of the curves' `points` time samples and of their transform ops (all
//! curves prims' times, merged);
//! a stage with none holds one sample, its default values. `NurbsCurves`
//! are read as their control polygon, with a warning; other geometry is
//! passed over with a warning, and a stage of none but such prims is
//! refused naming them.

use glam::{DMat4, DVec3};
use openusd::schemas::geom::{Curves, Imageable, PointBased, Xformable};
use openusd::usd::{Prim, SchemaBase, SchemaKind, Stage, TimeCode};
use openusd::{ar, sdf, usd};

use crate::Hair;

mod guard;

/// The largest layer read out of a `.usdz` package: a groom file's limit
/// (`MAX_FILE_BYTES`), so that a package's compressed entry cannot grow
/// past what a file may hold.
const MAX_LAYER_BYTES: u64 = 256 << 20;

/// What is wrong in a USD file, naming the prim.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum UsdError {
    /// The USD reader could not open the stage.
    #[error("not a USD stage wisplight can read: {0}")]
    Open(String),
    /// The stage composes other files.
    #[error(
        "the stage composes other files ({0}), which are not read; flatten it into one file first (usdcat --flatten)"
    )]
    Composed(String),
    /// A curves prim wisplight cannot read.
    #[error("{prim}: {why}")]
    Unreadable {
        /// The prim's path.
        prim: String,
        /// Why.
        why: String,
    },
    /// No curves on the stage.
    #[error("holds no BasisCurves{}", if others.is_empty() { String::new() } else { format!(" (it holds {others})") })]
    NoCurves {
        /// The other geometry found, listed.
        others: String,
    },
    /// A sample past the last.
    #[error("sample {asked} asked for, but the curves' points have {count} time sample{} (0 to {})",
        if *count == 1 { "" } else { "s" }, count.saturating_sub(1))]
    Sample {
        /// The sample asked for.
        asked: u32,
        /// The samples there are.
        count: u32,
    },
}

/// Serves the one file, from memory, under the name `root`.
struct OneFile {
    root: String,
    bytes: Vec<u8>,
    /// The layers that passed [`guard::check_layer`]: the reader opens a
    /// layer more than once (a peek at a `.usd`'s first bytes, then the
    /// read), and a crate's check parses it whole.
    passed: std::sync::Mutex<std::collections::BTreeSet<String>>,
}

impl ar::Resolver for OneFile {
    fn create_identifier(&self, asset_path: &str, _anchor: Option<&ar::ResolvedPath>) -> String {
        asset_path.to_owned()
    }
    fn resolve(&self, asset_path: &str) -> Option<ar::ResolvedPath> {
        (asset_path == self.root || self.inner(asset_path).is_some())
            .then(|| ar::ResolvedPath::new(asset_path))
    }
    fn resolve_for_new_asset(&self, _asset_path: &str) -> Option<ar::ResolvedPath> {
        None
    }
    fn open_asset(&self, resolved: &ar::ResolvedPath) -> std::io::Result<Box<dyn ar::Asset>> {
        let path = resolved.to_string_lossy();
        let checked = |bytes: Vec<u8>| -> std::io::Result<Box<dyn ar::Asset>> {
            let mut passed = self.passed.lock().unwrap_or_else(|e| e.into_inner());
            if !passed.contains(path.as_ref()) {
                guard::check_layer(&bytes)
                    .map_err(|why| std::io::Error::new(std::io::ErrorKind::InvalidData, why))?;
                passed.insert(path.to_string());
            }
            Ok(Box::new(std::io::Cursor::new(bytes)))
        };
        if path == self.root.as_str() {
            checked(self.bytes.clone())
        } else if let Some(inner) = self.inner(&path) {
            // A layer inside the `.usdz` package (a zip), read whole, at
            // most as large as a groom file may be.
            use std::io::Read;
            let mut zip = zip::ZipArchive::new(std::io::Cursor::new(&self.bytes[..]))
                .map_err(std::io::Error::other)?;
            let entry = zip.by_name(&inner).map_err(std::io::Error::other)?;
            let mut out = Vec::new();
            entry.take(MAX_LAYER_BYTES + 1).read_to_end(&mut out)?;
            if out.len() as u64 > MAX_LAYER_BYTES {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::FileTooLarge,
                    format!(
                        "{inner} in the package: more than {} bytes",
                        MAX_LAYER_BYTES
                    ),
                ));
            }
            checked(out)
        } else {
            Err(std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("{resolved}: only the groom file itself is read"),
            ))
        }
    }
}

impl OneFile {
    /// The layer `path` names inside the root package, `root[inner]`.
    fn inner(&self, path: &str) -> Option<String> {
        let (outer, inner) = ar::split_package_relative_path_outer(path)?;
        (outer == self.root).then_some(inner)
    }
}

/// A prim seen through the geometry schemas wisplight reads: its
/// `xformOp`s (none when it has none) give its transform, and a curves
/// prim's attributes its curves.
struct View(Prim);

impl SchemaBase for View {
    const KIND: SchemaKind = SchemaKind::AbstractTyped;
    fn prim(&self) -> &Prim {
        &self.0
    }
}
impl Imageable for View {}
impl Xformable for View {}
impl openusd::schemas::geom::Boundable for View {}
impl openusd::schemas::geom::Gprim for View {}
impl PointBased for View {}
impl Curves for View {}

/// Reads the curves of the USD file `bytes` (extension `ext`: `usd`,
/// `usda`, `usdc` or `usdz`) at sample `sample` into hair, with the
/// strands' widths when every curves prim has them.
pub fn parse_usd(bytes: &[u8], ext: &str, sample: u32) -> Result<Hair, UsdError> {
    read(bytes, ext, sample, true).map(|(hair, _)| hair)
}

/// [`parse_usd`] and the samples the curves have; `warn`: say what was
/// passed over (once a file, not again at each sample).
pub(crate) fn read(
    bytes: &[u8],
    ext: &str,
    sample: u32,
    warn: bool,
) -> Result<(Hair, u32), UsdError> {
    let root = format!("groom.{ext}");
    let resolver = OneFile {
        root: root.clone(),
        bytes: bytes.to_vec(),
        passed: Default::default(),
    };
    // The reader is large and young: a panic in it is this file's error,
    // not the program's end.
    let read = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        read_stage(resolver, &root, sample, warn)
    }));
    read.unwrap_or_else(|panic| {
        let why = panic
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| panic.downcast_ref::<&str>().copied())
            .unwrap_or("the reader failed");
        Err(UsdError::Open(format!(
            "the USD reader failed on it: {why}"
        )))
    })
}

fn open_error(e: impl std::fmt::Display) -> UsdError {
    UsdError::Open(e.to_string())
}

fn read_stage(
    resolver: OneFile,
    root: &str,
    sample: u32,
    warn: bool,
) -> Result<(Hair, u32), UsdError> {
    let stage = Stage::builder()
        .resolver(resolver)
        .open(root)
        .map_err(|e| UsdError::Open(format!("{e:#}")))?;
    let mut paths = Vec::new();
    stage
        .traverse(usd::PrimPredicate::DEFAULT, |p| paths.push(p.clone()))
        .map_err(open_error)?;
    // Composition errors (a layer referenced that is not this file) are
    // known once the prims are composed.
    let errors = stage.composition_errors();
    if !errors.is_empty() {
        let list: Vec<String> = errors.iter().take(3).map(ToString::to_string).collect();
        return Err(UsdError::Composed(list.join("; ")));
    }
    let (mut curves, mut others) = (Vec::new(), Vec::new());
    for path in paths {
        let prim = stage.prim(path.clone());
        let kind = prim.type_name().map_err(open_error)?;
        match kind.as_ref().map(|t| t.as_str()) {
            Some("BasisCurves") => curves.push((prim, false)),
            Some("NurbsCurves") => curves.push((prim, true)),
            Some(t @ ("Mesh" | "Points" | "HermiteCurves" | "NurbsPatch" | "TetMesh")) => {
                others.push(format!("{path}, a {t}"))
            }
            _ => {}
        }
    }
    if curves.is_empty() {
        return Err(UsdError::NoCurves {
            others: list(&others),
        });
    }
    if warn && !others.is_empty() {
        tracing::warn!("USD: passed over what is not curves: {}", list(&others));
    }
    // The sample's time: the k-th of every curves prim's points' times
    // and of the transform ops above them.
    let mut times: Vec<f64> = Vec::new();
    for (prim, _) in &curves {
        let t = View(prim.clone())
            .points_attr()
            .time_sample_times()
            .map_err(open_error)?;
        times.extend(t);
        let mut at = Some(prim.clone());
        while let Some(p) = at {
            let ops = View(p.clone()).xform_op_order().map_err(open_error)?;
            for op in ops.unwrap_or_default() {
                if op.starts_with("xformOp:") {
                    times.extend(
                        p.attribute(op.as_str())
                            .time_sample_times()
                            .map_err(open_error)?,
                    );
                }
            }
            at = p
                .path()
                .parent()
                .filter(|q| !q.is_abs_root())
                .map(|q| stage.prim(q));
        }
    }
    times.sort_by(f64::total_cmp);
    times.dedup();
    let time = if times.is_empty() {
        if sample > 0 {
            return Err(UsdError::Sample {
                asked: sample,
                count: 1,
            });
        }
        None
    } else {
        Some(TimeCode::new(*times.get(sample as usize).ok_or(
            UsdError::Sample {
                asked: sample,
                count: times.len() as u32,
            },
        )?))
    };
    let mut hair = Hair::new();
    let mut widths = Some(Vec::new());
    for (prim, nurbs) in curves {
        let name = prim.path().to_string();
        let c = read_curves(&stage, View(prim), nurbs, warn, time)?;
        for strand in c.hair.strands() {
            hair.push_strand(strand).map_err(|e| UsdError::Unreadable {
                prim: name.clone(),
                why: e.to_string(),
            })?;
        }
        widths = match (widths, c.widths) {
            (Some(mut all), Some(w)) => {
                all.extend(w);
                Some(all)
            }
            _ => None,
        };
    }
    if let Some(w) = widths {
        hair.set_widths(w);
    }
    Ok((hair, times.len() as u32))
}

fn list(others: &[String]) -> String {
    let mut s: Vec<String> = others.iter().take(4).cloned().collect();
    if others.len() > 4 {
        s.push(format!("and {} more", others.len() - 4));
    }
    s.join("; ")
}

/// One curves prim read.
struct Read {
    hair: Hair,
    widths: Option<Vec<f32>>,
}

/// The prim's local-to-world transform at `time`, column vectors: its
/// and its ancestors' `xformOp`s, up to a `!resetXformStack!`.
fn world(stage: &Stage, prim: &Prim, time: TimeCode) -> Result<DMat4, UsdError> {
    let mut m = DMat4::IDENTITY;
    let mut at = Some(prim.clone());
    while let Some(p) = at {
        let x = View(p.clone());
        // openusd's matrices are USD's: row vectors, row-major, so the
        // same 16 numbers are column-major for column vectors.
        let local = x
            .local_to_parent_transform(time)
            .map_err(|e| UsdError::Unreadable {
                prim: p.path().to_string(),
                why: format!("{e:#}"),
            })?;
        m = DMat4::from_cols_array(&local.0) * m;
        if x.resets_xform_stack().unwrap_or(false) {
            break;
        }
        at = p
            .path()
            .parent()
            .filter(|q| !q.is_abs_root())
            .map(|q| stage.prim(q));
    }
    Ok(m)
}

/// A token attribute's value, or `default`.
fn token(attr: usd::Attribute, default: &str) -> String {
    match attr.get::<sdf::Value>() {
        Ok(Some(sdf::Value::Token(t))) => t.as_str().to_owned(),
        Ok(Some(sdf::Value::String(s))) => s,
        _ => default.to_owned(),
    }
}

fn read_curves(
    stage: &Stage,
    c: View,
    nurbs: bool,
    warn: bool,
    time: Option<TimeCode>,
) -> Result<Read, UsdError> {
    let name = c.prim().path().to_string();
    let unreadable = |why: String| UsdError::Unreadable {
        prim: name.clone(),
        why,
    };
    let at = |attr: usd::Attribute| -> Result<Option<sdf::Value>, UsdError> {
        attr.get_at::<sdf::Value>(time)
            .map_err(|e| unreadable(format!("{e:#}")))
    };
    let points: Vec<DVec3> = match at(c.points_attr())? {
        Some(sdf::Value::Vec3fVec(v)) => v
            .iter()
            .map(|p| DVec3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z)))
            .collect(),
        Some(sdf::Value::Vec3dVec(v)) => v.iter().map(|p| DVec3::new(p.x, p.y, p.z)).collect(),
        None => return Err(unreadable("curves without points; nothing to read".into())),
        Some(other) => return Err(unreadable(format!("points of {other:?}"))),
    };
    let counts: Vec<usize> = match at(c.curve_vertex_counts_attr())? {
        Some(sdf::Value::IntVec(v)) => v
            .iter()
            .map(|&n| {
                usize::try_from(n).map_err(|_| unreadable(format!("a curve of {n} vertices")))
            })
            .collect::<Result<_, _>>()?,
        None => return Err(unreadable("curves without curveVertexCounts".into())),
        Some(other) => return Err(unreadable(format!("curveVertexCounts of {other:?}"))),
    };
    let total: usize = counts.iter().sum();
    if total != points.len() {
        return Err(unreadable(format!(
            "curveVertexCounts add up to {total} points, but points holds {}",
            points.len()
        )));
    }
    if nurbs && warn {
        tracing::warn!("USD {name}: NURBS curves read as their control polygon");
    }
    let kind = token(c.prim().attribute("type"), "cubic");
    let basis = token(c.prim().attribute("basis"), "bezier");
    let wrap = token(c.prim().attribute("wrap"), "nonperiodic");
    let cubic = match (nurbs, kind.as_str()) {
        (true, _) | (false, "linear") => None,
        (false, "cubic") => Some(match basis.as_str() {
            "bezier" => crate::cubic::Basis::Bezier,
            "bspline" => crate::cubic::Basis::BSpline,
            "catmullRom" => crate::cubic::Basis::CatmullRom,
            b => {
                return Err(unreadable(format!(
                    "cubic curves of basis {b}, not read; export them linear, bezier, bspline or catmullRom"
                )));
            }
        }),
        (false, k) => return Err(unreadable(format!("curves of type {k}"))),
    };
    if wrap == "periodic" && cubic.is_some() {
        return Err(unreadable(
            "periodic (closed) cubic curves, not strands of hair".into(),
        ));
    }
    let time_code = time.unwrap_or(TimeCode::new(0.0));
    let world = world(stage, c.prim(), time_code)?;
    let widths = match at(c.widths_attr())? {
        Some(sdf::Value::FloatVec(w)) => Some(w),
        Some(sdf::Value::DoubleVec(w)) => Some(w.iter().map(|&x| x as f32).collect()),
        _ => None,
    };
    let widths = widths
        .map(|w| crate::cubic::strand_widths(&w, &counts, cubic))
        .transpose()
        .map_err(unreadable)?;
    let width_scale = world.determinant().abs().cbrt() as f32;

    let mut hair = Hair::with_capacity(counts.len(), points.len());
    let (mut cv, mut along) = (Vec::new(), Vec::new());
    let mut start = 0;
    for (s, &n) in counts.iter().enumerate() {
        cv.clear();
        cv.extend(
            points[start..start + n]
                .iter()
                .map(|&p| world.transform_point3(p)),
        );
        start += n;
        if wrap == "periodic" && n > 1 {
            cv.push(cv[0]);
        }
        if wrap == "pinned" && n >= 2 {
            pin(&mut cv, cubic);
        }
        crate::cubic::push_curve(&mut hair, &cv, cubic, &mut along)
            .map_err(|e| unreadable(format!("curve {s}: {e}")))?;
    }
    Ok(Read {
        hair,
        widths: widths.map(|w| w.into_iter().map(|x| x * width_scale).collect()),
    })
}

/// USD's `pinned` wrap: a B-spline or Catmull-Rom curve reaches its end
/// points, as if its ends had phantom points (the end point repeated
/// twice more for a B-spline, the end reflected across it, `2 P_0 - P_1`,
/// for a Catmull-Rom spline).
fn pin(cv: &mut Vec<DVec3>, cubic: Option<crate::cubic::Basis>) {
    let (first, last) = (cv[0], cv[cv.len() - 1]);
    match cubic {
        Some(crate::cubic::Basis::BSpline) => {
            cv.splice(0..0, [first, first]);
            cv.extend([last, last]);
        }
        Some(crate::cubic::Basis::CatmullRom) => {
            let (second, before) = (cv[1], cv[cv.len() - 2]);
            cv.insert(0, 2.0 * first - second);
            cv.push(2.0 * last - before);
        }
        _ => {}
    }
}
