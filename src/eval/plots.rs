//! Line plots of the evaluation (PNG, plotters' bitmap backend): one line with markers per
//! series, axis labels, a legend and a title.
//!
//! Text needs a TrueType font, loaded at run time (plotters is built without a system font
//! backend): the file named by the environment variable `MESHDECO_FONT`, else the first of
//! DejaVu Sans / Liberation Sans / FreeSans found in the usual font directories.
//! `MESHDECO_FONT=none`, or no font found, draws the plots without any text (a warning says so).
//! PNGs are rendered in memory and written atomically.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::prelude::*;

use crate::artifact::write_atomic;
use crate::error::{Error, Result};

/// One line of a plot: its legend label and (x, y) points (non-finite points are skipped).
#[derive(Debug, Clone)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

/// Plot size in pixels.
const SIZE: (u32, u32) = (900, 600);

const FONT_CANDIDATES: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "/usr/share/fonts/liberation/LiberationSans-Regular.ttf",
    "/usr/share/fonts/truetype/freefont/FreeSans.ttf",
    "/Library/Fonts/Arial.ttf",
    "/System/Library/Fonts/Supplemental/Arial.ttf",
    "C:\\Windows\\Fonts\\arial.ttf",
];

/// The font file that would be used (see the module docs), if any.
pub fn font_path() -> Option<PathBuf> {
    match std::env::var_os("MESHDECO_FONT") {
        Some(v) if v == "none" => None,
        Some(v) => {
            let p = PathBuf::from(v);
            p.is_file().then_some(p)
        }
        None => FONT_CANDIDATES.iter().map(PathBuf::from).find(|p| p.is_file()),
    }
}

/// Registers the font once per process; true when text can be drawn.
fn font_ready() -> bool {
    static READY: OnceLock<bool> = OnceLock::new();
    *READY.get_or_init(|| {
        let Some(p) = font_path() else {
            eprintln!("warning: no TrueType font found (set MESHDECO_FONT=<file.ttf>); plots are drawn without text");
            return false;
        };
        match std::fs::read(&p) {
            Ok(bytes) => {
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                if plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).is_ok() {
                    true
                } else {
                    eprintln!("warning: {} is not a usable TrueType font; plots are drawn without text", p.display());
                    false
                }
            }
            Err(e) => {
                eprintln!("warning: cannot read font {}: {e}; plots are drawn without text", p.display());
                false
            }
        }
    })
}

fn plot_err(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::Invalid(format!("drawing {}: {e}", path.display()))
}

const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

/// Draws `series` as lines with markers into the PNG `path` (written atomically). Axis ranges
/// cover every finite point with a 5 % margin (y from 0 when all values are non-negative).
pub fn line_plot(path: &Path, title: &str, x_label: &str, y_label: &str, series: &[Series]) -> Result<()> {
    let text = font_ready();
    let pts: Vec<(f64, f64)> =
        series.iter().flat_map(|s| s.points.iter().copied()).filter(|(x, y)| x.is_finite() && y.is_finite()).collect();
    let (mut x0, mut x1, mut y0, mut y1) = pts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY), |(a, b, c, d), &(x, y)| {
            (a.min(x), b.max(x), c.min(y), d.max(y))
        });
    if pts.is_empty() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    if y0 >= 0.0 {
        y0 = 0.0;
    }
    let (dx, dy) = ((x1 - x0).max(1e-9), (y1 - y0).max(1e-9));
    let (x0, x1, y0, y1) =
        (x0 - 0.05 * dx, x1 + 0.05 * dx, if y0 == 0.0 { 0.0 } else { y0 - 0.05 * dy }, y1 + 0.08 * dy);

    let mut buf = vec![255u8; (SIZE.0 * SIZE.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
        let mut builder = ChartBuilder::on(&root);
        builder.margin(20);
        if text {
            builder.caption(title, ("sans-serif", 26)).x_label_area_size(50).y_label_area_size(70);
        } else {
            builder.x_label_area_size(10).y_label_area_size(10);
        }
        let mut chart = builder.build_cartesian_2d(x0..x1, y0..y1).map_err(|e| plot_err(path, e))?;
        if text {
            chart
                .configure_mesh()
                .x_desc(x_label)
                .y_desc(y_label)
                .label_style(("sans-serif", 16))
                .axis_desc_style(("sans-serif", 18))
                .draw()
                .map_err(|e| plot_err(path, e))?;
        } else {
            chart.configure_mesh().x_labels(0).y_labels(0).draw().map_err(|e| plot_err(path, e))?;
        }
        for (i, s) in series.iter().enumerate() {
            let color = COLORS[i % COLORS.len()];
            let p: Vec<(f64, f64)> = s.points.iter().copied().filter(|(x, y)| x.is_finite() && y.is_finite()).collect();
            let line =
                chart.draw_series(LineSeries::new(p.clone(), color.stroke_width(2))).map_err(|e| plot_err(path, e))?;
            if text {
                line.label(s.label.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
            }
            chart.draw_series(p.iter().map(|&xy| Circle::new(xy, 4, color.filled()))).map_err(|e| plot_err(path, e))?;
        }
        if text && !series.is_empty() {
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 16))
                .draw()
                .map_err(|e| plot_err(path, e))?;
        }
        root.present().map_err(|e| plot_err(path, e))?;
    }
    let img = image::RgbImage::from_raw(SIZE.0, SIZE.1, buf)
        .ok_or_else(|| Error::Invalid(format!("{}: bitmap buffer size mismatch", path.display())))?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageOutputFormat::Png).map_err(|e| plot_err(path, e))?;
    write_atomic(path, &png)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_a_png_of_the_requested_size() {
        let dir = std::env::temp_dir().join(format!("meshdeco-plot-{}", std::process::id()));
        let path = dir.join("p.png");
        let s = vec![
            Series { label: "a".into(), points: vec![(5.0, 3.0), (10.0, 2.0), (20.0, 1.0)] },
            Series { label: "b".into(), points: vec![(5.0, 4.0), (10.0, f64::NAN), (20.0, 0.5)] },
        ];
        line_plot(&path, "t", "K", "Erms", &s).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), SIZE);
        // Something other than white was drawn.
        assert!(img.pixels().any(|p| p.0 != [255, 255, 255]));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
