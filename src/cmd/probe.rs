//! `wisplight probe`: transmittance at given points.

use std::io::{BufWriter, Write};
use std::path::PathBuf;

use anyhow::Context;
use engine::ShadowPipeline;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file (TOML).
    scene: PathBuf,
    /// CSV file of points: a header line `x,y,z`, then one point per line.
    #[arg(long, value_name = "POINTS.csv")]
    points: PathBuf,
    #[command(flatten)]
    method: super::MethodArg,
    #[command(flatten)]
    pub threads: super::Threads,
}

/// Prints `x,y,z,transmittance` (one column per light when there are
/// several) for every input point, in order.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut scene = super::load_scene(Some(&args.scene))?;
    args.method.apply(&mut scene);
    let points = crate::csv::read_points(&args.points)?;
    let hair = super::build_hair(&scene)?;
    let mut pipeline = ShadowPipeline::new(&scene)?;
    let t = pipeline.run(&hair, &points)?;

    let mut out = BufWriter::new(std::io::stdout().lock());
    let header = if t.len() == 1 {
        "transmittance".to_string()
    } else {
        (0..t.len())
            .map(|l| format!("transmittance_{l}"))
            .collect::<Vec<_>>()
            .join(",")
    };
    writeln!(out, "x,y,z,{header}")?;
    for (i, p) in points.iter().enumerate() {
        write!(out, "{},{},{}", p.x, p.y, p.z)?;
        for light in &t {
            write!(out, ",{}", light[i])?;
        }
        writeln!(out)?;
    }
    out.flush().context("cannot write to stdout")
}
