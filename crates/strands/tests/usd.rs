//! USD grooms read back: a `.usda` written here, the same stage as
//! `.usdc` and inside a `.usdz`, transforms, widths, time samples, and
//! refusals. The expected points are computed by hand.

use std::path::Path;

use glam::Vec3;
use strands::{Hair, load_bytes};

/// Two curves under a transformed parent: `/Groom` translates by
/// (1, 2, 3) and turns 90 degrees about y (USD's op order: the last op
/// applies first, so the turn comes first); `/Groom/Hair` scales x by 2.
/// `points` has a default and two time samples, 10 and 20.
const GROOM: &str = r#"#usda 1.0
(
    defaultPrim = "Groom"
)

def Xform "Groom"
{
    double3 xformOp:translate = (1, 2, 3)
    float xformOp:rotateY = 90
    uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateY"]

    def BasisCurves "Hair"
    {
        uniform token type = "linear"
        int[] curveVertexCounts = [3, 2]
        point3f[] points = [(0, 0, 0), (0, 1, 0), (0, 2, 0), (1, 0, 0), (1, 1, 0)]
        point3f[] points.timeSamples = {
            10: [(0, 0, 0), (0, 1, 0), (0, 2, 0), (1, 0, 0), (1, 1, 0)],
            20: [(0, 0, 1), (0, 1, 1), (0, 2, 1), (1, 0, 1), (1, 1, 1)],
        }
        float[] widths = [0.01, 0.02, 0.03, 0.04, 0.06] (interpolation = "vertex")
        double3 xformOp:scale = (2, 1, 1)
        uniform token[] xformOpOrder = ["xformOp:scale"]
    }

    def Mesh "Head"
    {
        point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
    }
}
"#;

/// Where a point of the groom lands: scale x by 2, turn 90 degrees about
/// y, `(x, y, z) -> (z, y, -x)`, move by (1, 2, 3).
fn placed(p: Vec3) -> Vec3 {
    let s = p * Vec3::new(2.0, 1.0, 1.0);
    Vec3::new(s.z, s.y, -s.x) + Vec3::new(1.0, 2.0, 3.0)
}

fn check(h: &Hair, dz: f32) {
    let want: Vec<Vec3> = [(0.0, 0.0), (0.0, 1.0), (0.0, 2.0), (1.0, 0.0), (1.0, 1.0)]
        .iter()
        .map(|&(x, y)| placed(Vec3::new(x, y, dz)))
        .collect();
    assert_eq!(h.strand_count(), 2);
    assert_eq!(h.offsets(), &[0, 3, 5]);
    for (k, (a, b)) in h.points().iter().zip(&want).enumerate() {
        assert!((*a - *b).length() < 1e-5, "point {k}: {a} against {b}");
    }
    // Widths per vertex, each strand's mean, scaled by the transform's
    // cube root of |det| (2).
    let w = h.widths().unwrap();
    let s = 2f32.cbrt();
    assert!(
        (w[0] - 0.02 * s).abs() < 1e-6 && (w[1] - 0.05 * s).abs() < 1e-6,
        "{w:?}"
    );
}

fn usdc() -> Vec<u8> {
    let data = openusd::usda::parse(GROOM).unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    openusd::usdc::CrateWriter::write(&data, &mut out).unwrap();
    out.into_inner()
}

#[test]
fn a_usda_groom_is_placed_by_its_transforms_at_each_time_sample() {
    let read = |sample| load_bytes(Path::new("groom.usda"), GROOM.as_bytes(), sample);
    check(&read(0).unwrap(), 0.0);
    check(&read(1).unwrap(), 1.0);
    let e = read(2).unwrap_err();
    assert_eq!(
        e.to_string(),
        "groom.usda: USD: sample 2 asked for, but the curves' points have 2 time samples (0 to 1)"
    );
}

#[test]
fn the_same_stage_as_usdc_and_inside_a_usdz_reads_the_same() {
    let crate_bytes = usdc();
    assert!(crate_bytes.starts_with(b"PXR-USDC"));
    check(
        &load_bytes(Path::new("groom.usdc"), &crate_bytes, 1).unwrap(),
        1.0,
    );
    // `.usd` holds either: this one the binary crate.
    check(
        &load_bytes(Path::new("groom.usd"), &crate_bytes, 0).unwrap(),
        0.0,
    );
    let mut z = openusd::usdz::ArchiveWriter::new(std::io::Cursor::new(Vec::new()));
    z.add_layer("groom.usdc", &crate_bytes).unwrap();
    let package = z.finish().unwrap().into_inner();
    check(
        &load_bytes(Path::new("groom.usdz"), &package, 1).unwrap(),
        1.0,
    );
}

#[test]
fn cubic_bases_and_pinned_ends_follow_usd() {
    let curve = |basis: &str, wrap: &str| {
        format!(
            r#"#usda 1.0
def BasisCurves "C"
{{
    uniform token type = "cubic"
    uniform token basis = "{basis}"
    uniform token wrap = "{wrap}"
    int[] curveVertexCounts = [5]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0), (4, 0, 0)]
}}
"#
        )
    };
    let xs = |text: String| -> Vec<f32> {
        load_bytes(Path::new("c.usda"), text.as_bytes(), 0)
            .unwrap()
            .points()
            .iter()
            .map(|p| p.x)
            .collect()
    };
    // A B-spline of points on a line runs from 1 to 3; pinned, 0 to 4.
    let open = xs(curve("bspline", "nonperiodic"));
    assert!((open[0] - 1.0).abs() < 1e-6 && (open[open.len() - 1] - 3.0).abs() < 1e-6);
    let pinned = xs(curve("bspline", "pinned"));
    assert!(pinned[0].abs() < 1e-6 && (pinned[pinned.len() - 1] - 4.0).abs() < 1e-6);
    let pinned = xs(curve("catmullRom", "pinned"));
    assert!(pinned[0].abs() < 1e-6 && (pinned[pinned.len() - 1] - 4.0).abs() < 1e-6);
    // Periodic cubic curves are not hair.
    let e = load_bytes(
        Path::new("c.usda"),
        curve("bspline", "periodic").as_bytes(),
        0,
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("/C: periodic (closed) cubic curves"),
        "{e}"
    );
}

#[test]
fn what_cannot_be_read_is_refused_naming_it() {
    let err = |name: &str, bytes: &[u8]| {
        load_bytes(Path::new(name), bytes, 0)
            .unwrap_err()
            .to_string()
    };
    // A stage of no curves names what it holds.
    let mesh = "#usda 1.0\ndef Mesh \"Head\"\n{\n    point3f[] points = [(0, 0, 0)]\n}\n";
    assert_eq!(
        err("m.usda", mesh.as_bytes()),
        "m.usda: USD: holds no BasisCurves (it holds /Head, a Mesh)"
    );
    // Counts that do not add up.
    let bad = GROOM.replace(
        "int[] curveVertexCounts = [3, 2]",
        "int[] curveVertexCounts = [3, 3]",
    );
    let e = err("g.usda", bad.as_bytes());
    assert!(
        e.contains("/Groom/Hair: curveVertexCounts add up to 6 points, but points holds 5"),
        "{e}"
    );
    // A stage that references another file.
    let refs = "#usda 1.0\ndef Xform \"G\" (\n    references = @other.usda@\n)\n{\n}\n";
    let e = err("r.usda", refs.as_bytes());
    assert!(
        e.contains("composes other files") && e.contains("other.usda"),
        "{e}"
    );
    // Not USD at all, empty, truncated.
    assert!(err("x.usda", b"not usd").starts_with("x.usda: USD: not a USD stage"));
    assert!(err("x.usdc", b"").starts_with("x.usdc: USD: not a USD stage"));
    let c = usdc();
    for cut in [8, 64, c.len() / 2, c.len() - 1] {
        assert!(
            load_bytes(Path::new("x.usdc"), &c[..cut], 0).is_err(),
            "cut at {cut}"
        );
    }
    assert!(err("x.usdz", b"PK\x03\x04 not a zip").starts_with("x.usdz: USD: not a USD stage"));
}

#[test]
fn files_written_by_pixars_usd_read_the_same() {
    // Made by tests/data/make_pixar_usd.py with PyPI usd-core 26.11: the
    // same groom, written by Pixar's own USD as a crate and a package.
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    for name in ["pixar-groom.usdc", "pixar-groom.usdz"] {
        let path = data.join(name);
        let bytes = std::fs::read(&path).unwrap();
        check(&load_bytes(&path, &bytes, 0).unwrap(), 0.0);
        check(&load_bytes(&path, &bytes, 1).unwrap(), 1.0);
    }
}

#[test]
fn a_stage_nested_past_any_groom_is_refused_before_it_is_read() {
    // 20,000 prims each inside the last: the USD reader's parser recurses
    // a level a prim and overflowed the stack (an abort) before the
    // nesting was bounded, and a crate of prims 3,000 deep took over a
    // minute to compose. The crate here (written by Pixar's USD) nests
    // 100 deep, past the bound.
    let n = 20_000;
    let text: String = "#usda 1.0\n".to_owned()
        + &(0..n)
            .map(|i| format!("def Xform \"a{i}\" {{\n"))
            .collect::<String>()
        + &"}\n".repeat(n);
    let e = load_bytes(Path::new("deep.usda"), text.as_bytes(), 0).unwrap_err();
    assert!(e.to_string().contains("nested deeper than 64"), "{e}");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/pixar-deep.usdc");
    let e = load_bytes(&path, &std::fs::read(&path).unwrap(), 0).unwrap_err();
    assert!(e.to_string().contains("prims nested 100 deep"), "{e}");
}

#[test]
fn an_animated_transform_over_still_curves_gives_the_samples() {
    let usda = r#"#usda 1.0
def Xform "Groom"
{
    double3 xformOp:translate.timeSamples = { 1: (0, 0, 0), 2: (0, 0, 5) }
    uniform token[] xformOpOrder = ["xformOp:translate"]

    def BasisCurves "Hair"
    {
        uniform token type = "linear"
        int[] curveVertexCounts = [2]
        point3f[] points = [(0, 0, 0), (0, -1, 0)]
    }
}
"#;
    let z = |sample| {
        load_bytes(Path::new("g.usda"), usda.as_bytes(), sample)
            .unwrap()
            .points()[0]
            .z
    };
    assert_eq!((z(0), z(1)), (0.0, 5.0));
    assert_eq!(
        strands::groom_samples(Path::new("g.usda"), usda.as_bytes()).unwrap(),
        2
    );
}
