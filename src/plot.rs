//! A small scatter plot for `bench accuracy`: error against time on a log
//! axis, the Pareto front marked, a legend. Text comes from a built-in 5x7
//! pixel font (lowercase, digits and a little punctuation), so the picture
//! needs no font files.

use image::{Rgb, RgbImage};

/// One point of the plot.
#[derive(Debug, Clone)]
pub struct Point {
    pub x_ms: f64,
    pub y: f64,
    /// Index into the series (legend entries).
    pub series: usize,
}

/// Distinct colours for up to eight series.
const COLORS: [[u8; 3]; 8] = [
    [31, 119, 180],
    [214, 39, 40],
    [44, 160, 44],
    [255, 127, 14],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [23, 190, 207],
];

const W: u32 = 960;
const H: u32 = 600;
const LEFT: i32 = 90;
const RIGHT: i32 = 290;
const TOP: i32 = 50;
const BOTTOM: i32 = 70;

/// Indices of the points on the Pareto front (no other point is both
/// faster and at least as accurate), sorted by time.
pub fn pareto_front(points: &[Point]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len()).collect();
    idx.sort_by(|&a, &b| {
        points[a]
            .x_ms
            .total_cmp(&points[b].x_ms)
            .then(points[a].y.total_cmp(&points[b].y))
    });
    let mut front = Vec::new();
    let mut best = f64::INFINITY;
    for i in idx {
        if points[i].y < best {
            best = points[i].y;
            front.push(i);
        }
    }
    front
}

/// Draws the plot: `series` names the legend entries, `title` and the axis
/// labels are drawn lowercase.
pub fn scatter(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[String],
    points: &[Point],
) -> RgbImage {
    let mut img = RgbImage::from_pixel(W, H, Rgb([255, 255, 255]));
    let (x0, x1) = (LEFT, W as i32 - RIGHT);
    let (y0, y1) = (H as i32 - BOTTOM, TOP);
    let xs = points.iter().map(|p| p.x_ms.max(1e-6).log10());
    let lo = xs.clone().fold(f64::INFINITY, f64::min).floor();
    let hi = xs.fold(f64::NEG_INFINITY, f64::max).ceil().max(lo + 1.0);
    let ymax = nice_ceiling(points.iter().map(|p| p.y).fold(0.0, f64::max).max(1e-6));
    let px = |ms: f64| x0 + ((ms.max(1e-6).log10() - lo) / (hi - lo) * f64::from(x1 - x0)) as i32;
    let py = |y: f64| y0 - (y / ymax * f64::from(y0 - y1)) as i32;
    let grid = Rgb([225, 225, 225]);
    let ink = Rgb([40, 40, 40]);
    // Decades on x, with 2 and 5 between.
    let mut d = lo as i32;
    while f64::from(d) <= hi {
        for m in [1.0, 2.0, 5.0] {
            let v = m * 10f64.powi(d);
            if v.log10() > hi + 1e-9 {
                break;
            }
            let x = px(v);
            line(&mut img, (x, y0), (x, y1), grid);
            if m == 1.0 {
                let label = format_ms(v);
                text(&mut img, x - 6 * label.len() as i32, y0 + 8, &label, ink);
            }
        }
        d += 1;
    }
    y_grid(&mut img, (x0, x1), ymax, 3, &py);
    line(&mut img, (x0, y0), (x1, y0), ink);
    line(&mut img, (x0, y0), (x0, y1), ink);
    text(&mut img, x0, 4, title, ink);
    text(
        &mut img,
        (x0 + x1) / 2 - 6 * x_label.len() as i32,
        y0 + 35,
        x_label,
        ink,
    );
    text(&mut img, 8, TOP - 27, y_label, ink);
    // The Pareto front, then the points over it.
    let front = pareto_front(points);
    for w in front.windows(2) {
        let (a, b) = (&points[w[0]], &points[w[1]]);
        line(
            &mut img,
            (px(a.x_ms), py(a.y)),
            (px(b.x_ms), py(b.y)),
            Rgb([0, 0, 0]),
        );
    }
    for p in points {
        let c = COLORS[p.series % COLORS.len()];
        disc(&mut img, px(p.x_ms), py(p.y), 4, Rgb(c));
    }
    for &i in &front {
        let p = &points[i];
        ring(&mut img, px(p.x_ms), py(p.y), 7, Rgb([0, 0, 0]));
    }
    // Legend.
    let lx = x1 + 20;
    for (i, name) in series.iter().enumerate() {
        let y = TOP + 10 + 22 * i as i32;
        disc(&mut img, lx + 5, y + 6, 5, Rgb(COLORS[i % COLORS.len()]));
        text(&mut img, lx + 16, y, name, ink);
    }
    let y = TOP + 10 + 22 * series.len() as i32;
    ring(&mut img, lx + 5, y + 6, 7, Rgb([0, 0, 0]));
    text(&mut img, lx + 16, y, "pareto front", ink);
    img
}

fn format_ms(v: f64) -> String {
    if v >= 1.0 {
        format!("{v:.0} ms")
    } else {
        format!("{v} ms")
    }
}

/// The smallest of 1, 2, 5 times a power of ten at or above `v`.
/// Six horizontal grid lines from 0 to `ymax` across `x0..x1`, labelled
/// with `decimals` digits on the left.
fn y_grid(
    img: &mut RgbImage,
    (x0, x1): (i32, i32),
    ymax: f64,
    decimals: usize,
    py: &dyn Fn(f64) -> i32,
) {
    let (grid, ink) = (Rgb([225, 225, 225]), Rgb([40, 40, 40]));
    for i in 0..=5 {
        let v = ymax * f64::from(i) / 5.0;
        let y = py(v);
        line(img, (x0, y), (x1, y), grid);
        let label = format!("{v:.decimals$}");
        text(img, x0 - 8 - 12 * label.len() as i32, y - 7, &label, ink);
    }
}

fn nice_ceiling(v: f64) -> f64 {
    let p = 10f64.powf(v.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|&c| c >= v)
        .unwrap_or(10.0 * p)
}

fn put(img: &mut RgbImage, x: i32, y: i32, c: Rgb<u8>) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, c);
    }
}

fn line(img: &mut RgbImage, (x0, y0): (i32, i32), (x1, y1): (i32, i32), c: Rgb<u8>) {
    let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
    let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
    let (mut x, mut y, mut err) = (x0, y0, dx + dy);
    loop {
        put(img, x, y, c);
        if x == x1 && y == y1 {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += sx;
        }
        if e2 <= dx {
            err += dx;
            y += sy;
        }
    }
}

fn disc(img: &mut RgbImage, cx: i32, cy: i32, r: i32, c: Rgb<u8>) {
    for y in -r..=r {
        for x in -r..=r {
            if x * x + y * y <= r * r {
                put(img, cx + x, cy + y, c);
            }
        }
    }
}

fn ring(img: &mut RgbImage, cx: i32, cy: i32, r: i32, c: Rgb<u8>) {
    for y in -r..=r {
        for x in -r..=r {
            let d = x * x + y * y;
            if d <= r * r && d >= (r - 1) * (r - 1) {
                put(img, cx + x, cy + y, c);
            }
        }
    }
}

/// Draws `s` (lowercased) at 2x scale from its top-left corner; characters
/// the font lacks are drawn as blanks.
pub fn text(img: &mut RgbImage, x: i32, y: i32, s: &str, c: Rgb<u8>) {
    for (i, ch) in s.chars().enumerate() {
        let rows = glyph(ch.to_ascii_lowercase());
        let gx = x + 12 * i as i32;
        for (r, bits) in rows.iter().enumerate() {
            for col in 0..5 {
                if bits & (0b10000 >> col) != 0 {
                    for (sx, sy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        put(img, gx + 2 * col + sx, y + 2 * r as i32 + sy, c);
                    }
                }
            }
        }
    }
}

fn glyph(c: char) -> [u8; 7] {
    match c {
        '0' => [14, 17, 19, 21, 25, 17, 14],
        '1' => [4, 12, 4, 4, 4, 4, 14],
        '2' => [14, 17, 1, 2, 4, 8, 31],
        '3' => [31, 2, 4, 2, 1, 17, 14],
        '4' => [2, 6, 10, 18, 31, 2, 2],
        '5' => [31, 16, 30, 1, 1, 17, 14],
        '6' => [6, 8, 16, 30, 17, 17, 14],
        '7' => [31, 1, 2, 4, 8, 8, 8],
        '8' => [14, 17, 17, 14, 17, 17, 14],
        '9' => [14, 17, 17, 15, 1, 2, 12],
        'a' => [0, 0, 14, 1, 15, 17, 15],
        'b' => [16, 16, 22, 25, 17, 17, 30],
        'c' => [0, 0, 14, 16, 16, 17, 14],
        'd' => [1, 1, 13, 19, 17, 17, 15],
        'e' => [0, 0, 14, 17, 31, 16, 14],
        'f' => [6, 9, 8, 28, 8, 8, 8],
        'g' => [0, 15, 17, 17, 15, 1, 14],
        'h' => [16, 16, 22, 25, 17, 17, 17],
        'i' => [4, 0, 12, 4, 4, 4, 14],
        'j' => [2, 0, 6, 2, 2, 18, 12],
        'k' => [16, 16, 18, 20, 24, 20, 18],
        'l' => [12, 4, 4, 4, 4, 4, 14],
        'm' => [0, 0, 26, 21, 21, 17, 17],
        'n' => [0, 0, 22, 25, 17, 17, 17],
        'o' => [0, 0, 14, 17, 17, 17, 14],
        'p' => [0, 0, 30, 17, 30, 16, 16],
        'q' => [0, 0, 13, 19, 15, 1, 1],
        'r' => [0, 0, 22, 25, 16, 16, 16],
        's' => [0, 0, 14, 16, 14, 1, 30],
        't' => [8, 8, 28, 8, 8, 9, 6],
        'u' => [0, 0, 17, 17, 17, 19, 13],
        'v' => [0, 0, 17, 17, 17, 10, 4],
        'w' => [0, 0, 17, 17, 21, 21, 10],
        'x' => [0, 0, 17, 10, 4, 10, 17],
        'y' => [0, 0, 17, 17, 15, 1, 14],
        'z' => [0, 0, 31, 2, 4, 8, 31],
        '.' => [0, 0, 0, 0, 0, 12, 12],
        '-' => [0, 0, 0, 31, 0, 0, 0],
        '=' => [0, 0, 31, 0, 31, 0, 0],
        '(' => [2, 4, 8, 8, 8, 4, 2],
        ')' => [8, 4, 2, 2, 2, 4, 8],
        '/' => [0, 1, 2, 4, 8, 16, 0],
        ':' => [0, 12, 12, 0, 12, 12, 0],
        ',' => [0, 0, 0, 0, 12, 4, 8],
        '^' => [4, 10, 17, 0, 0, 0, 0],
        '%' => [24, 25, 2, 4, 8, 19, 3],
        '_' => [0, 0, 0, 0, 0, 0, 31],
        '+' => [0, 4, 4, 31, 4, 4, 0],
        _ => [0; 7],
    }
}

/// A bar chart: one bar per label, its value printed above it; the y axis
/// starts at 0.
pub fn bars(title: &str, y_label: &str, labels: &[String], values: &[f64]) -> RgbImage {
    let mut img = RgbImage::from_pixel(W, H, Rgb([255, 255, 255]));
    let (x0, x1) = (LEFT, W as i32 - 40);
    let (y0, y1) = (H as i32 - BOTTOM, TOP);
    let ymax = nice_ceiling(values.iter().copied().fold(0.0, f64::max).max(1e-6));
    let py = |y: f64| y0 - (y / ymax * f64::from(y0 - y1)) as i32;
    let ink = Rgb([40, 40, 40]);
    y_grid(&mut img, (x0, x1), ymax, 1, &py);
    let n = labels.len().max(1) as i32;
    let slot = (x1 - x0) / n;
    for (i, (label, &v)) in labels.iter().zip(values).enumerate() {
        let cx = x0 + slot * i as i32 + slot / 2;
        let half = (slot / 3).max(2);
        let top = py(v);
        let c = Rgb(COLORS[i % COLORS.len()]);
        for x in cx - half..=cx + half {
            line(&mut img, (x, y0), (x, top), c);
        }
        let value = format!("{v:.1}");
        text(&mut img, cx - 6 * value.len() as i32, top - 20, &value, ink);
        text(&mut img, cx - 6 * label.len() as i32, y0 + 10, label, ink);
    }
    line(&mut img, (x0, y0), (x1, y0), ink);
    line(&mut img, (x0, y0), (x0, y1), ink);
    text(&mut img, x0, 4, title, ink);
    text(&mut img, 8, TOP - 27, y_label, ink);
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_front_keeps_only_points_no_other_point_beats() {
        let p = |x_ms, y| Point { x_ms, y, series: 0 };
        let pts = [
            p(1.0, 0.5),
            p(2.0, 0.6),
            p(3.0, 0.1),
            p(0.5, 0.9),
            p(10.0, 0.1),
        ];
        assert_eq!(pareto_front(&pts), vec![3, 0, 2]);
    }
}
