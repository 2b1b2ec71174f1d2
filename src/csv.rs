//! The point CSV of `wisplight probe`: a header `x,y,z`, then one point a row.

use std::path::Path;

use anyhow::{Context, bail};
use glam::Vec3;

/// Reads points, naming the file, line and field of anything malformed.
pub fn read_points(path: &Path) -> anyhow::Result<Vec<Vec3>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read points {}", path.display()))?;
    parse_points(&text).with_context(|| path.display().to_string())
}

pub fn parse_points(text: &str) -> anyhow::Result<Vec<Vec3>> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let Some((_, header)) = lines.next() else {
        bail!("empty file, expected a header line x,y,z")
    };
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    if names != ["x", "y", "z"] {
        bail!("line 1: header is {header:?}, expected x,y,z");
    }
    let mut points = Vec::new();
    for (i, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != 3 {
            bail!(
                "line {}: {} fields, expected 3 (x,y,z)",
                i + 1,
                fields.len()
            );
        }
        let mut v = [0f32; 3];
        for ((name, field), out) in ["x", "y", "z"].iter().zip(&fields).zip(&mut v) {
            let x: f32 = field.parse().map_err(|_| {
                anyhow::anyhow!("line {}: {name} = {field:?} is not a number", i + 1)
            })?;
            if !x.is_finite() {
                bail!("line {}: {name} = {field} is not finite", i + 1);
            }
            *out = x;
        }
        points.push(Vec3::from_array(v));
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_points_and_names_bad_fields() {
        let p = parse_points("x, y, z\n1,2,3\n\n-1.5, 0, 1e3\n").unwrap();
        assert_eq!(
            p,
            vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(-1.5, 0.0, 1000.0)]
        );
        assert_eq!(
            parse_points("x,y,z\n1,2,nan\n").unwrap_err().to_string(),
            "line 2: z = nan is not finite"
        );
        assert_eq!(
            parse_points("x,y,z\n1,abc,3\n").unwrap_err().to_string(),
            "line 2: y = \"abc\" is not a number"
        );
        assert_eq!(
            parse_points("x,y,z\n1,2\n").unwrap_err().to_string(),
            "line 2: 2 fields, expected 3 (x,y,z)"
        );
        assert!(
            parse_points("a,b,c\n")
                .unwrap_err()
                .to_string()
                .contains("expected x,y,z")
        );
        assert!(parse_points("").is_err());
    }
}
