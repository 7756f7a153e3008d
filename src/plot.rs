//! PNG line plots for people (`sky atmosphere inspect --plot`), drawn with
//! plotters into memory and written atomically. Text uses the Ubuntu Light
//! font embedded by the `epaint_default_fonts` crate, so no system fonts are
//! needed.

use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

/// One named curve.
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    /// Dashed curves are drawn thinner, for fits and approximations.
    pub dashed: bool,
    /// Palette index; curves that belong together share one.
    pub color: usize,
}

impl Series {
    pub fn new(label: impl Into<String>, points: Vec<(f64, f64)>, color: usize) -> Series {
        Series { label: label.into(), points, dashed: false, color }
    }

    pub fn dashed(mut self) -> Series {
        self.dashed = true;
        self
    }
}

/// Splits a curve into runs of points that can be drawn on the axes (finite,
/// and positive where an axis is logarithmic), so gaps are not bridged.
fn drawable_runs(points: &[(f64, f64)], x: Scale, y: Scale) -> Vec<Vec<(f64, f64)>> {
    let ok = |v: f64, s: Scale| v.is_finite() && (s == Scale::Linear || v > 0.0);
    let mut runs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for &p in points {
        if ok(p.0, x) && ok(p.1, y) {
            runs.last_mut().unwrap().push(p);
        } else if !runs.last().unwrap().is_empty() {
            runs.push(Vec::new());
        }
    }
    runs.retain(|r| r.len() > 1);
    runs
}

fn tick_label(v: f64, s: Scale) -> String {
    match s {
        Scale::Log => {
            let e = v.log10().round();
            if (v.log10() - e).abs() < 1e-6 {
                format!("1e{e}")
            } else {
                format!("{v:.1e}")
            }
        }
        Scale::Linear => {
            if v.abs() >= 1e4 || (v != 0.0 && v.abs() < 1e-2) {
                format!("{v:.1e}")
            } else if (v - v.round()).abs() < 1e-9 {
                format!("{v:.0}")
            } else {
                format!("{v:.2}")
            }
        }
    }
}

/// Axis scaling.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    Linear,
    Log,
}

pub struct Axes<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub x_scale: Scale,
    pub y_scale: Scale,
}

const WIDTH: u32 = 900;
const HEIGHT: u32 = 600;

fn ensure_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, epaint_default_fonts::UBUNTU_LIGHT);
    });
}

fn palette(i: usize) -> RGBColor {
    const C: [RGBColor; 8] = [
        RGBColor(31, 119, 180),
        RGBColor(214, 39, 40),
        RGBColor(44, 160, 44),
        RGBColor(255, 127, 14),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
        RGBColor(227, 119, 194),
        RGBColor(23, 190, 207),
    ];
    C[i % C.len()]
}

fn bounds(series: &[Series], scale_x: Scale, scale_y: Scale) -> ((f64, f64), (f64, f64)) {
    let ok = |v: f64, s: Scale| v.is_finite() && (s == Scale::Linear || v > 0.0);
    let pts = series.iter().flat_map(|s| s.points.iter()).filter(|p| ok(p.0, scale_x) && ok(p.1, scale_y));
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for p in pts {
        x0 = x0.min(p.0);
        x1 = x1.max(p.0);
        y0 = y0.min(p.1);
        y1 = y1.max(p.1);
    }
    if !x0.is_finite() {
        return ((0.0, 1.0), (0.1, 1.0));
    }
    let pad = |a: f64, b: f64, s: Scale| -> (f64, f64) {
        match s {
            Scale::Log => (a / 1.3, b * 1.3),
            Scale::Linear if a == b => (a - 1.0, b + 1.0),
            Scale::Linear => (a - 0.03 * (b - a), b + 0.03 * (b - a)),
        }
    };
    (pad(x0, x1, scale_x), pad(y0, y1, scale_y))
}

macro_rules! draw_chart {
    ($root:expr, $axes:expr, $series:expr, $xr:expr, $yr:expr) => {{
        let mut chart = ChartBuilder::on($root)
            .caption($axes.title, ("sans-serif", 26))
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(80)
            .build_cartesian_2d($xr, $yr)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc($axes.x_label)
            .x_label_formatter(&|v| tick_label(*v, $axes.x_scale))
            .y_label_formatter(&|v| tick_label(*v, $axes.y_scale))
            .y_desc($axes.y_label)
            .label_style(("sans-serif", 16))
            .axis_desc_style(("sans-serif", 18))
            .draw()
            .map_err(|e| e.to_string())?;
        for s in $series.iter() {
            let color = palette(s.color);
            let width = if s.dashed { 1 } else { 2 };
            let style = color.stroke_width(width);
            for (j, pts) in drawable_runs(&s.points, $axes.x_scale, $axes.y_scale).into_iter().enumerate() {
                let drawn = if s.dashed {
                    chart.draw_series(DashedLineSeries::new(pts, 8, 5, style)).map_err(|e| e.to_string())?
                } else {
                    chart.draw_series(LineSeries::new(pts, style)).map_err(|e| e.to_string())?
                };
                if j == 0 {
                    drawn
                        .label(s.label.clone())
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(width)));
                }
            }
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 15))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| e.to_string())?;
    }};
}

/// Draws the series and writes a PNG to `path` (through a temporary file).
pub fn line_plot(path: &Path, axes: &Axes, series: &[Series]) -> Result<(), String> {
    ensure_font();
    let ((x0, x1), (y0, y1)) = bounds(series, axes.x_scale, axes.y_scale);
    let mut buf = vec![0u8; (WIDTH * HEIGHT * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        match (axes.x_scale, axes.y_scale) {
            (Scale::Linear, Scale::Linear) => draw_chart!(&root, axes, series, x0..x1, y0..y1),
            (Scale::Linear, Scale::Log) => draw_chart!(&root, axes, series, x0..x1, (y0..y1).log_scale()),
            (Scale::Log, Scale::Linear) => draw_chart!(&root, axes, series, (x0..x1).log_scale(), y0..y1),
            (Scale::Log, Scale::Log) => draw_chart!(&root, axes, series, (x0..x1).log_scale(), (y0..y1).log_scale()),
        }
        root.present().map_err(|e| e.to_string())?;
    }
    let img = image::RgbImage::from_raw(WIDTH, HEIGHT, buf).ok_or("bad image buffer")?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).map_err(|e| e.to_string())?;
    crate::mie::cache::write_atomic(path, &png).map_err(|e| format!("{}: {e}", path.display()))
}
