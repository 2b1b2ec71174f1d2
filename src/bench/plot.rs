//! Charts for the benchmarks, drawn with plotters as a picture and as
//! SVG from the same drawing code ([`Chart::png`], [`Chart::svg`]): error
//! against time for `bench accuracy` (a log time axis fitted to the data,
//! each point labelled with its setting, the Pareto front marked, a legend
//! of methods) and frame times for `bench scaling` (bars with their
//! values). Text is set in DejaVu Sans Condensed, built into the program
//! (`src/bench/fonts/`, with its licence), so no font needs to be installed.

use std::sync::Once;

use anyhow::anyhow;
use image::RgbImage;
use plotters::coord::Shift;
use plotters::drawing::DrawingAreaErrorKind;
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

/// One point of the scatter plot.
#[derive(Debug, Clone)]
pub struct Point {
    pub x_ms: f64,
    pub y: f64,
    /// Index into the series (legend entries).
    pub series: usize,
    /// What the point is (its setting), written beside it.
    pub label: String,
}

/// Distinct colours for up to eight series.
const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

const W: u32 = 1100;
const H: u32 = 680;
const FONT: &str = "sans-serif";

/// Registers the built-in font once.
fn font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let bytes: &'static [u8] = include_bytes!("fonts/DejaVuSansCondensed.ttf");
        // The font is part of the program: it parses.
        let _ = register_font(FONT, FontStyle::Normal, bytes);
    });
}

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

/// A chart, drawn as a picture or as SVG.
#[derive(Debug, Clone)]
pub enum Chart {
    /// See [`scatter`].
    Scatter {
        title: String,
        x_label: String,
        y_label: String,
        series: Vec<String>,
        points: Vec<Point>,
    },
    /// See [`bars`].
    Bars {
        title: String,
        y_label: String,
        labels: Vec<String>,
        values: Vec<f64>,
    },
}

impl Chart {
    /// The chart as a `W x H` picture.
    pub fn png(&self) -> anyhow::Result<RgbImage> {
        font();
        let mut buf = vec![0u8; (W * H * 3) as usize];
        self.draw(BitMapBackend::with_buffer(&mut buf, (W, H)).into_drawing_area())?;
        RgbImage::from_raw(W, H, buf).ok_or_else(|| anyhow!("plot: picture of the wrong size"))
    }

    /// The chart as an SVG document of the picture's size (text as text,
    /// in the viewer's sans-serif font).
    pub fn svg(&self) -> anyhow::Result<String> {
        font();
        let mut out = String::new();
        self.draw(SVGBackend::with_string(&mut out, (W, H)).into_drawing_area())?;
        Ok(out)
    }

    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> anyhow::Result<()> {
        root.fill(&WHITE).map_err(|e| anyhow!("plot: {e}"))?;
        match self {
            Chart::Scatter {
                title,
                x_label,
                y_label,
                series,
                points,
            } => draw_scatter(&root, title, x_label, y_label, series, points)?,
            Chart::Bars {
                title,
                y_label,
                labels,
                values,
            } => draw_bars(&root, title, y_label, labels, values)?,
        }
        root.present().map_err(|e| anyhow!("plot: {e}"))
    }
}

/// Error against time: one colour per series (`series` names them in the
/// legend), each point labelled, the Pareto front joined and ringed; the
/// time axis logarithmic, both axes fitted to the points.
pub fn scatter(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[String],
    points: &[Point],
) -> Chart {
    Chart::Scatter {
        title: title.to_owned(),
        x_label: x_label.to_owned(),
        y_label: y_label.to_owned(),
        series: series.to_vec(),
        points: points.to_vec(),
    }
}

fn draw_scatter<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[String],
    points: &[Point],
) -> anyhow::Result<()> {
    let finite: Vec<&Point> = points
        .iter()
        .filter(|p| p.x_ms.is_finite() && p.x_ms > 0.0 && p.y.is_finite())
        .collect();
    let (lo, hi) = finite.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), p| {
        (lo.min(p.x_ms), hi.max(p.x_ms))
    });
    let (lo, hi) = if finite.is_empty() {
        (1.0, 10.0)
    } else {
        (lo / 1.3, hi * 1.6)
    };
    let y_top = finite.iter().map(|p| p.y).fold(0.0f64, f64::max).max(1e-3) * 1.12;
    let front = pareto_front(points);
    {
        let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("plot: {e}");
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FONT, 24))
            .margin(16)
            .x_label_area_size(52)
            .y_label_area_size(72)
            .margin_right(150)
            .build_cartesian_2d(
                (lo..hi).log_scale().with_key_points(ticks(lo, hi)),
                0.0..y_top,
            )
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .light_line_style(TRANSPARENT)
            .bold_line_style(RGBColor(225, 225, 225))
            .label_style((FONT, 15))
            .axis_desc_style((FONT, 17))
            .x_label_formatter(&|v| {
                format!("{v:.3}")
                    .trim_end_matches('0')
                    .trim_end_matches('.')
                    .to_string()
            })
            .draw()
            .map_err(err)?;
        // The front first, under the points.
        let line: Vec<(f64, f64)> = front
            .iter()
            .map(|&i| (points[i].x_ms, points[i].y))
            .collect();
        chart
            .draw_series(LineSeries::new(line.clone(), BLACK.stroke_width(1)))
            .map_err(err)?
            .label("Pareto front")
            .legend(|(x, y)| Circle::new((x + 10, y), 7, BLACK.stroke_width(1)));
        chart
            .draw_series(
                line.iter()
                    .map(|&p| Circle::new(p, 9, BLACK.stroke_width(1))),
            )
            .map_err(err)?;
        for (s, name) in series.iter().enumerate() {
            let color = COLORS[s % COLORS.len()];
            chart
                .draw_series(
                    points
                        .iter()
                        .filter(|p| p.series == s)
                        .map(|p| Circle::new((p.x_ms, p.y), 5, color.filled())),
                )
                .map_err(err)?
                .label(name.as_str())
                .legend(move |(x, y)| Circle::new((x + 10, y), 5, color.filled()));
        }
        // Labels where they overlap no other label and no point: the
        // front's first, then by time.
        let at = |p: &Point| chart.backend_coord(&(p.x_ms, p.y));
        let shown = |i: &usize| {
            let p = &points[*i];
            p.x_ms.is_finite() && p.x_ms > 0.0 && p.y.is_finite()
        };
        let mut order: Vec<usize> = front.iter().copied().filter(shown).collect();
        let mut rest: Vec<usize> = (0..points.len())
            .filter(|i| !front.contains(i) && shown(i))
            .collect();
        rest.sort_by(|&a, &b| points[a].x_ms.total_cmp(&points[b].x_ms));
        order.extend(rest);
        // A point's dot, or its ring on the front.
        let dots: Vec<Rect> = order
            .iter()
            .map(|&i| {
                let (x, y) = at(&points[i]);
                Rect::around(x, y, if front.contains(&i) { 10 } else { 6 })
            })
            .collect();
        let (x_range, y_range) = chart.plotting_area().get_pixel_range();
        let bounds = Rect {
            x0: x_range.start,
            y0: y_range.start,
            x1: x_range.end,
            y1: y_range.end,
        };
        let mut placed: Vec<Rect> = Vec::new();
        for (k, &i) in order.iter().enumerate() {
            let p = &points[i];
            let color = COLORS[p.series % COLORS.len()];
            let style = (FONT, 11).into_font().color(&color.mix(0.9));
            let (w, h) = root.estimate_text_size(&p.label, &style).map_err(err)?;
            let (x, y) = at(p);
            let rect = place_label(x, y, (w as i32, h as i32), bounds, (&dots, k), &placed);
            placed.push(rect);
            root.draw(&Text::new(p.label.clone(), (rect.x0, rect.y0), style))
                .map_err(err)?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT, 15))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .draw()
            .map_err(err)?;
        Ok(())
    }
}

/// Ticks of a log axis over `lo..hi`: 1, 2 and 5 times each power of ten.
fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    let mut out = Vec::new();
    let mut decade = 10f64.powf(lo.log10().floor());
    while decade <= hi {
        for m in [1.0, 2.0, 5.0] {
            let t = m * decade;
            if (lo..=hi).contains(&t) {
                out.push(t);
            }
        }
        decade *= 10.0;
    }
    out
}

/// A rectangle of pixels, `x0..x1` by `y0..y1`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Rect {
    x0: i32,
    y0: i32,
    x1: i32,
    y1: i32,
}

impl Rect {
    fn around(x: i32, y: i32, r: i32) -> Rect {
        Rect {
            x0: x - r,
            y0: y - r,
            x1: x + r,
            y1: y + r,
        }
    }

    /// Pixels shared with `o`.
    fn overlap(&self, o: &Rect) -> i64 {
        let w = (self.x1.min(o.x1) - self.x0.max(o.x0)).max(0);
        let h = (self.y1.min(o.y1) - self.y0.max(o.y0)).max(0);
        i64::from(w) * i64::from(h)
    }
}

/// Where a label of `size` goes beside the point at `(x, y)`: the first of
/// the spots around it (right, left, above, below, then further out) that
/// stays inside `bounds` and covers no point of `dots` (but its own, the
/// `own`th) and no label of `placed`; else the spot that covers least.
fn place_label(
    x: i32,
    y: i32,
    (w, h): (i32, i32),
    bounds: Rect,
    (dots, own): (&[Rect], usize),
    placed: &[Rect],
) -> Rect {
    let d0 = dots.get(own).map_or(6, |d| (d.x1 - d.x0) / 2) + 2;
    let mut spots = Vec::new();
    for step in 0..4 {
        let d = d0 + 14 * step;
        spots.extend([
            (x + d, y - h / 2),
            (x - d - w, y - h / 2),
            (x - w / 2, y - d - h),
            (x - w / 2, y + d),
            (x + d, y - h / 2 - d),
            (x + d, y - h / 2 + d),
            (x - d - w, y - h / 2 - d),
            (x - d - w, y - h / 2 + d),
        ]);
    }
    let cost = |r: &Rect| -> i64 {
        let outside = i64::from(w) * i64::from(h) - r.overlap(&bounds);
        let on_dots: i64 = dots
            .iter()
            .enumerate()
            .filter(|(k, _)| *k != own)
            .map(|(_, d)| r.overlap(d))
            .sum();
        let on_labels: i64 = placed.iter().map(|l| r.overlap(l)).sum();
        4 * outside + on_dots + on_labels
    };
    let mut best: Option<(i64, Rect)> = None;
    for (x0, y0) in spots {
        let r = Rect {
            x0,
            y0,
            x1: x0 + w,
            y1: y0 + h,
        };
        let c = cost(&r);
        if c == 0 {
            return r;
        }
        if best.is_none_or(|(b, _)| c < b) {
            best = Some((c, r));
        }
    }
    best.map_or(Rect::around(x, y, 0), |(_, r)| r)
}

/// A bar per label (named under it) with its value written above it,
/// under `title`.
pub fn bars(title: &str, y_label: &str, labels: &[String], values: &[f64]) -> Chart {
    Chart::Bars {
        title: title.to_owned(),
        y_label: y_label.to_owned(),
        labels: labels.to_vec(),
        values: values.to_vec(),
    }
}

fn draw_bars<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    y_label: &str,
    labels: &[String],
    values: &[f64],
) -> anyhow::Result<()> {
    let n = labels.len().min(values.len());
    let top = values
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        .max(1e-3)
        * 1.15;
    {
        let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("plot: {e}");
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FONT, 24))
            .margin(16)
            .x_label_area_size(50)
            .y_label_area_size(72)
            .build_cartesian_2d(-0.5..n as f64 - 0.5, 0.0..top)
            .map_err(err)?;
        // Each bar's name under it (at whole numbers).
        let name = |v: &f64| {
            let i = v.round();
            if (v - i).abs() < 1e-6 && i >= 0.0 {
                labels.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        };
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(n.max(1))
            .light_line_style(TRANSPARENT)
            .bold_line_style(RGBColor(225, 225, 225))
            .x_label_formatter(&name)
            .y_desc(y_label)
            .label_style((FONT, 15))
            .axis_desc_style((FONT, 17))
            .draw()
            .map_err(err)?;
        for (i, &v) in values.iter().take(n).enumerate() {
            let color = COLORS[i % COLORS.len()];
            let x = i as f64;
            let v = if v.is_finite() { v } else { 0.0 };
            chart
                .draw_series([Rectangle::new(
                    [(x - 0.35, 0.0), (x + 0.35, v)],
                    color.filled(),
                )])
                .map_err(err)?;
            chart
                .draw_series([Text::new(
                    format!("{v:.1}"),
                    (x - 0.08, v + top * 0.04),
                    (FONT, 15),
                )])
                .map_err(err)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x_ms: f64, y: f64, series: usize) -> Point {
        Point {
            x_ms,
            y,
            series,
            label: format!("{x_ms}"),
        }
    }

    #[test]
    fn labels_go_where_they_cover_no_other_label_or_point() {
        let bounds = Rect {
            x0: 0,
            y0: 0,
            x1: 400,
            y1: 300,
        };
        let size = (60, 12);
        // Two points a few pixels apart: the second label does not cover
        // the first, nor the first point.
        let dots = [Rect::around(100, 100, 6), Rect::around(104, 102, 6)];
        let a = place_label(100, 100, size, bounds, (&dots, 0), &[]);
        let b = place_label(104, 102, size, bounds, (&dots, 1), &[a]);
        assert_eq!(a.overlap(&b), 0, "{a:?} {b:?}");
        assert_eq!(b.overlap(&dots[0]), 0, "{b:?}");
        assert_eq!(a.overlap(&dots[1]), 0, "{a:?}");
        // By the right edge, the label goes to the left of its point.
        let c = place_label(390, 150, size, bounds, (&[], 0), &[]);
        assert!(c.x1 <= 390 && c.x0 >= 0, "{c:?}");
    }

    #[test]
    fn the_front_keeps_only_points_no_other_point_beats() {
        let pts = [
            p(1.0, 0.5, 0),
            p(2.0, 0.6, 0),
            p(3.0, 0.1, 0),
            p(0.5, 0.9, 0),
            p(10.0, 0.1, 0),
        ];
        assert_eq!(pareto_front(&pts), vec![3, 0, 2]);
    }

    #[test]
    fn charts_draw_their_points_and_bars_in_colour_with_text() {
        let series = vec!["a".to_string(), "b".to_string()];
        let img = scatter("T", "x", "y", &series, &[p(6.0, 0.1, 0), p(130.0, 0.05, 1)])
            .png()
            .unwrap();
        let colored =
            |img: &RgbImage, c: RGBColor| img.pixels().filter(|q| q.0 == [c.0, c.1, c.2]).count();
        assert!(colored(&img, COLORS[0]) > 20 && colored(&img, COLORS[1]) > 20);
        // Text is drawn (dark pixels beyond the axes' lines).
        let dark = img.pixels().filter(|q| q.0.iter().all(|&v| v < 80)).count();
        assert!(dark > 500, "{dark}");
        let img = bars(
            "frame ms",
            "ms",
            &["1 process".into(), "3 workers, workers drawing".into()],
            &[120.0, 80.0],
        )
        .png()
        .unwrap();
        assert!(colored(&img, COLORS[0]) > 1000 && colored(&img, COLORS[1]) > 1000);
    }

    #[test]
    fn the_svg_is_the_same_chart_as_the_picture() {
        let series = vec!["density map".to_string(), "reference".to_string()];
        let chart = scatter(
            "error vs time",
            "ms",
            "RMS",
            &series,
            &[p(6.0, 0.1, 0), p(130.0, 0.05, 1)],
        );
        let svg = chart.svg().unwrap();
        assert!(
            svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"),
            "{svg}"
        );
        assert!(svg.contains(r#"width="1100" height="680""#), "{svg}");
        // The title, the legend and each point's label, as text.
        for text in ["error vs time", "density map", "reference", "6", "130"] {
            assert!(svg.lines().any(|l| l.trim() == text), "{text} missing");
        }
        // A dot in each series' colour.
        for c in &COLORS[..2] {
            let hex = format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2);
            assert!(svg.to_uppercase().contains(&hex), "{hex} missing");
        }
    }
}
