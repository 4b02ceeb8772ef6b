//! Learning-curve figures for the paper's experiments: mean ± standard error over seeds.
//!
//! [`mean_stderr`] reduces per-seed curves to a mean and a standard error per iteration;
//! [`plot_curves`] draws any number of such curves as a PNG (mean line, shaded ±SE band, and
//! error bars while there are few enough points to tell them apart).
//!
//! Builds with the Rust toolchain alone: plotters draws into an in-memory RGB buffer, text is
//! rasterised by the pure-Rust `ab_glyph` with the DejaVu Sans font bundled in
//! `learner/assets/` (licence beside it), and the `png` crate encodes the file. No system
//! fonts, fontconfig or freetype are used.

use std::fmt::Display;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use crate::io::IoError;

/// What stopped a figure (`learner plot`, the experiments' figures, the arm's pictures).
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// A picture size out of range.
    #[error(
        "plot {}: size {width}x{height} px is out of range (each side {MIN_SIDE}..={MAX_SIDE})",
        path.display()
    )]
    Size {
        /// The figure.
        path: PathBuf,
        /// Width (px).
        width: u32,
        /// Height (px).
        height: u32,
    },
    /// A figure of no panels.
    #[error("plot {}: no panels", path.display())]
    NoPanels {
        /// The figure.
        path: PathBuf,
    },
    /// Data a figure cannot show.
    #[error("plot {}", path.display())]
    In {
        /// The figure.
        path: PathBuf,
        /// What is wrong with the data.
        source: Box<PlotError>,
    },
    /// Drawing a panel failed.
    #[error("plot {}: drawing failed", path.display())]
    Drawing {
        /// The figure.
        path: PathBuf,
        /// Why.
        source: Box<PlotError>,
    },
    /// The font compiled into the program is not one (a broken build).
    #[error("the bundled DejaVuSans.ttf is not a valid font")]
    Font,
    /// No curves given.
    #[error("no series to plot")]
    NoSeries,
    /// A curve whose arrays differ in length.
    #[error(
        "series {label:?}: x, mean and stderr must have one length, got {}, {}, {}",
        lengths[0],
        lengths[1],
        lengths[2]
    )]
    Ragged {
        /// The curve.
        label: String,
        /// Lengths of x, mean and stderr.
        lengths: [usize; 3],
    },
    /// A negative standard error.
    #[error("series {label:?}: negative stderr {stderr} at index {index}")]
    NegativeStderr {
        /// The curve.
        label: String,
        /// The value.
        stderr: f64,
        /// Where.
        index: usize,
    },
    /// Curves without a single drawable point.
    #[error(
        "nothing to plot: no series has a point with finite x and mean{} (all empty or NaN)",
        if *log_y { " > 0" } else { "" }
    )]
    NothingToPlot {
        /// Logarithmic y axis (points need mean > 0).
        log_y: bool,
    },
    /// The plotting library's error.
    #[error("plotters: {0}")]
    Plotters(String),
    /// The PNG file cannot be created: check the folder.
    #[error("cannot create PNG file {}", path.display())]
    CreatePng {
        /// The file.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
    /// The PNG file cannot be written.
    #[error("cannot write PNG file {}", path.display())]
    WritePng {
        /// The file.
        path: PathBuf,
        /// What the encoder said.
        source: png::EncodingError,
    },
    /// Drawing the arm (`learner plot arm`).
    #[error("drawing the arm: {0}")]
    Arm(String),
    /// A run folder without the controllers of its iterations.
    #[error(
        "{}: no iter_NNN_table.npz (the folder of a `learner train` or `learner serve --algo \
         lqr-gaifo` run)",
        dir.display()
    )]
    NoTables {
        /// The folder.
        dir: PathBuf,
    },
    /// The animated GIF.
    #[error("writing the GIF")]
    Gif(#[from] gif::EncodingError),
    /// The files plotted.
    #[error(transparent)]
    Io(#[from] IoError),
    /// The arm the controllers are run on again.
    #[error(transparent)]
    Sim(#[from] hil_sim::SimError),
    /// Running a controller again, or the demonstrations' task.
    #[error(transparent)]
    Imitation(#[from] imitation::ImitationError),
}
use plotters::coord::Shift;
use plotters::prelude::*;

/// One curve: mean ± standard error over seeds, per x (iteration).
///
/// `x`, `mean` and `stderr` have the same length (one entry per point) and are in the units of
/// the plot's axes: `x` in the x-axis unit (e.g. iteration number), `mean` and `stderr` in the
/// y-axis unit (e.g. cost). A point whose `x` or `mean` is NaN or infinite is not drawn (the line
/// and band break there); a non-finite `stderr` draws the point without a band or error bar.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Abscissae, one per point.
    pub x: Vec<f64>,
    /// Mean over seeds, one per point.
    pub mean: Vec<f64>,
    /// Standard error of the mean (≥ 0), one per point.
    pub stderr: Vec<f64>,
}

/// Per-index mean and standard error (sample std / sqrt(n), 0 when n = 1) over runs; runs may
/// have different lengths: index i uses the runs that have it. NaN values are skipped.
///
/// `runs[r][i]` is run (seed) `r`'s value at index (iteration) `i`. Returns `(mean, stderr, n)`,
/// each of length `max_r runs[r].len()`: `n[i]` is the number of runs that have a non-NaN value
/// at `i`, the sample standard deviation uses the `n - 1` denominator, and an index with
/// `n[i] == 0` (every run that reaches it has NaN there) gets NaN mean and NaN stderr.
/// Infinite values are not skipped (they make that index's mean/stderr non-finite).
pub fn mean_stderr(runs: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>, Vec<usize> /* n per index */) {
    let len = runs.iter().map(Vec::len).max().unwrap_or(0);
    let mut mean = Vec::with_capacity(len);
    let mut stderr = Vec::with_capacity(len);
    let mut count = Vec::with_capacity(len);
    for i in 0..len {
        let values = || {
            runs.iter()
                .filter_map(|r| r.get(i).copied())
                .filter(|v| !v.is_nan())
        };
        let n = values().count();
        let (m, se) = match n {
            0 => (f64::NAN, f64::NAN),
            1 => (values().sum::<f64>(), 0.0),
            _ => {
                let nf = n as f64;
                let m = values().sum::<f64>() / nf;
                let var = values().map(|v| (v - m) * (v - m)).sum::<f64>() / (nf - 1.0);
                (m, (var / nf).sqrt())
            }
        };
        mean.push(m);
        stderr.push(se);
        count.push(n);
    }
    (mean, stderr, count)
}

/// Line plot of every series with error bars (or a shaded ±SE band plus the mean line), legend,
/// axis labels, title; PNG of width x height pixels.
///
/// `size` is `(width, height)` in pixels, each in `200..=16384`. Every series is drawn as its
/// mean line over a shaded mean ± stderr band; when the figure has at most
/// [`MAX_POINTS_FOR_ERROR_BARS`] points in all, each point also gets a marker and an error bar.
/// The x range spans the drawable points' `x` with a 2% margin; the y range spans their
/// `mean ± stderr` with a 5% margin (a zero-width range, e.g. a flat or single-point curve, is
/// widened by max(10% of the value, 0.5) each side). The legend goes in the corner with the
/// fewest data points.
///
/// Errors (never panics) when: `series` is empty; a series' `x`, `mean` and `stderr` lengths
/// differ; a `stderr` is negative; no series has a point with finite `x` and `mean`; the size
/// is out of range; or the file cannot be written (the message names `path`). The file is
/// written as PNG whatever `path`'s extension.
pub fn plot_curves(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    size: (u32, u32),
) -> Result<(), PlotError> {
    let panel = Panel {
        y_label,
        series,
        log_y: false,
    };
    plot_panels(path, title, x_label, &[panel], size)
}

/// One panel of [`plot_panels`]: its curves and y axis.
#[derive(Debug, Clone, Copy)]
pub struct Panel<'a> {
    /// y-axis label.
    pub y_label: &'a str,
    /// The curves ([`plot_curves`] gives the conventions).
    pub series: &'a [Series],
    /// Logarithmic y axis (base 10): only points with mean > 0 are drawn, and a band's lower
    /// edge mean − stderr ≤ 0 is drawn at the bottom of the axis.
    pub log_y: bool,
}

/// Panels stacked vertically under one title, sharing the x label (e.g. normalised performance
/// above final distance); each panel as in [`plot_curves`], with its own legend and y range.
/// Errors as [`plot_curves`], per panel, and when `panels` is empty.
pub fn plot_panels(
    path: &Path,
    title: &str,
    x_label: &str,
    panels: &[Panel<'_>],
    size: (u32, u32),
) -> Result<(), PlotError> {
    let (width, height) = size;
    if !(MIN_SIDE..=MAX_SIDE).contains(&width) || !(MIN_SIDE..=MAX_SIDE).contains(&height) {
        return Err(PlotError::Size {
            path: path.to_owned(),
            width,
            height,
        });
    }
    if panels.is_empty() {
        return Err(PlotError::NoPanels {
            path: path.to_owned(),
        });
    }
    let prepared = panels
        .iter()
        .map(|p| {
            let curves = prepare(p.series, p.log_y)?;
            let ranges = ranges(&curves);
            Ok((p, curves, ranges))
        })
        .collect::<Result<Vec<_>, PlotError>>()
        .map_err(|e| PlotError::In {
            path: path.to_owned(),
            source: Box::new(e),
        })?;
    register_font()?;

    let mut rgb = vec![0u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let title_px = (height / prepared.len() as u32 / 25).clamp(14, 28);
        let body = root
            .titled(title, (FONT, title_px).into_font().color(&BLACK))
            .map_err(plot_err)?;
        let areas = body.split_evenly((prepared.len(), 1));
        for (area, (panel, curves, (x_range, y_range))) in areas.iter().zip(&prepared) {
            draw(
                area,
                x_label,
                panel,
                curves,
                x_range.clone(),
                y_range.clone(),
            )
            .map_err(|e| PlotError::Drawing {
                path: path.to_owned(),
                source: Box::new(e),
            })?;
        }
        root.present().map_err(plot_err)?;
    }
    write_png(path, width, height, &rgb)
}

/// Above this many points in all (over every series), points get no marker or error bar, only
/// the shaded band: they would overlap into a smear.
pub const MAX_POINTS_FOR_ERROR_BARS: usize = 60;

pub(crate) const MIN_SIDE: u32 = 200;
pub(crate) const MAX_SIDE: u32 = 16384;

/// The family name the bundled font is registered under (plotters' default sans-serif name).
pub(crate) const FONT: &str = "sans-serif";
static DEJAVU_SANS: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// Registers the bundled DejaVu Sans with plotters' ab_glyph text backend, once per process.
pub(crate) fn register_font() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<Result<(), ()>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(FONT, FontStyle::Normal, DEJAVU_SANS).map_err(|_| ())
        })
        .map_err(|()| PlotError::Font)
}

/// Matplotlib's "tab10" colours: distinct, and readable by most colour-blind readers.
pub(crate) const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// A point ready to draw in axis units: `(x, y, y_lo, y_hi)`, all finite, `y_lo <= y <= y_hi`
/// (mean, mean − stderr, mean + stderr; log10 of them on a log axis).
type Point = (f64, f64, f64, f64);

/// One series split at its non-finite points into contiguous drawable runs.
struct Curve<'a> {
    label: &'a str,
    segments: Vec<Vec<Point>>,
}

impl Curve<'_> {
    fn points(&self) -> impl Iterator<Item = &Point> {
        self.segments.iter().flatten()
    }
}

fn prepare(series: &[Series], log_y: bool) -> Result<Vec<Curve<'_>>, PlotError> {
    if series.is_empty() {
        return Err(PlotError::NoSeries);
    }
    let mut curves = Vec::with_capacity(series.len());
    for s in series {
        let (nx, nm, ns) = (s.x.len(), s.mean.len(), s.stderr.len());
        if nx != nm || nx != ns {
            return Err(PlotError::Ragged {
                label: s.label.clone(),
                lengths: [nx, nm, ns],
            });
        }
        let mut segments = vec![Vec::new()];
        for i in 0..nx {
            let (x, m, se) = (s.x[i], s.mean[i], s.stderr[i]);
            if se < 0.0 {
                return Err(PlotError::NegativeStderr {
                    label: s.label.clone(),
                    stderr: se,
                    index: i,
                });
            }
            let se = if se.is_finite() { se } else { 0.0 };
            let point = if !(x.is_finite() && m.is_finite()) || (log_y && m <= 0.0) {
                None
            } else if log_y {
                // A lower edge at or below 0 has no logarithm: NaN, drawn at the axis bottom.
                let lo = if m - se > 0.0 {
                    (m - se).log10()
                } else {
                    f64::NAN
                };
                Some((x, m.log10(), lo, (m + se).log10()))
            } else {
                Some((x, m, m - se, m + se))
            };
            match point {
                Some(p) => segments.last_mut().expect("never empty").push(p),
                None if !segments.last().expect("never empty").is_empty() => {
                    segments.push(Vec::new())
                }
                None => {}
            }
        }
        segments.retain(|seg| !seg.is_empty());
        curves.push(Curve {
            label: &s.label,
            segments,
        });
    }
    if curves.iter().all(|c| c.segments.is_empty()) {
        return Err(PlotError::NothingToPlot { log_y });
    }
    // Lower edges without a logarithm go to the bottom of the other points' range.
    if log_y {
        let floor = curves
            .iter()
            .flat_map(Curve::points)
            .flat_map(|&(_, y, lo, _)| [y, lo])
            .filter(|v| v.is_finite())
            .fold(f64::INFINITY, f64::min);
        for c in &mut curves {
            for p in c.segments.iter_mut().flatten() {
                if !p.2.is_finite() {
                    p.2 = floor;
                }
            }
        }
    }
    Ok(curves)
}

/// Axis ranges: x over the data with a 2% margin (so edge error bars are not clipped), y over
/// mean ± stderr with a 5% margin; a zero-width range is widened around its value.
fn ranges(curves: &[Curve<'_>]) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let points = || curves.iter().flat_map(Curve::points);
    let fold = |f: &dyn Fn(&Point) -> (f64, f64)| {
        points()
            .map(f)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (a, b)| {
                (lo.min(a), hi.max(b))
            })
    };
    let (x_lo, x_hi) = fold(&|&(x, _, _, _)| (x, x));
    let (y_lo, y_hi) = fold(&|&(_, _, lo, hi)| (lo, hi));
    (pad(x_lo, x_hi, 0.02), pad(y_lo, y_hi, 0.05))
}

fn pad(lo: f64, hi: f64, frac: f64) -> std::ops::Range<f64> {
    let span = hi - lo;
    let margin = if span > 0.0 && span.is_finite() {
        span * frac
    } else {
        (lo.abs() * 0.1).max(0.5)
    };
    let (lo, hi) = (lo - margin, hi + margin);
    if lo.is_finite() && hi.is_finite() && lo < hi {
        lo..hi
    } else {
        // Values near f64::MAX: fall back to something drawable rather than fail.
        -1.0..1.0
    }
}

pub(crate) fn plot_err<E: Display>(e: E) -> PlotError {
    PlotError::Plotters(e.to_string())
}

fn draw(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    x_label: &str,
    panel: &Panel<'_>,
    curves: &[Curve<'_>],
    x_range: std::ops::Range<f64>,
    y_range: std::ops::Range<f64>,
) -> Result<(), PlotError> {
    let (_, height) = area.dim_in_pixel();
    let text_px = (height / 36).clamp(11, 20);

    let mut chart = ChartBuilder::on(area)
        .margin(12)
        .x_label_area_size(text_px * 3)
        .y_label_area_size(text_px * 5 + 10)
        .build_cartesian_2d(x_range.clone(), y_range.clone())
        .map_err(plot_err)?;
    let x_span = x_range.end - x_range.start;
    let y_span = y_range.end - y_range.start;
    let log_y = panel.log_y;
    let x_fmt = |v: &f64| tick_label(*v, x_span);
    let y_fmt = |v: &f64| {
        if log_y {
            log_tick_label(*v)
        } else {
            tick_label(*v, y_span)
        }
    };
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(panel.y_label)
        .x_label_formatter(&x_fmt)
        .y_label_formatter(&y_fmt)
        .max_light_lines(1)
        .label_style((FONT, text_px))
        .axis_desc_style((FONT, text_px + 2))
        .bold_line_style(RGBColor(220, 220, 220))
        .light_line_style(RGBColor(242, 242, 242))
        .draw()
        .map_err(plot_err)?;

    let total_points: usize = curves.iter().map(|c| c.points().count()).sum();
    let markers = total_points <= MAX_POINTS_FOR_ERROR_BARS;

    // Bands first, so no band covers another series' line.
    for (i, curve) in curves.iter().enumerate() {
        let band = PALETTE[i % PALETTE.len()].mix(0.18).filled();
        for seg in curve.segments.iter().filter(|seg| seg.len() > 1) {
            let outline: Vec<(f64, f64)> = seg
                .iter()
                .map(|&(x, _, _, hi)| (x, hi))
                .chain(seg.iter().rev().map(|&(x, _, lo, _)| (x, lo)))
                .collect();
            chart
                .draw_series(std::iter::once(Polygon::new(outline, band)))
                .map_err(plot_err)?;
        }
    }
    for (i, curve) in curves.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let line = color.stroke_width(2);
        for seg in &curve.segments {
            if markers || seg.len() == 1 {
                chart
                    .draw_series(seg.iter().map(|&(x, m, lo, hi)| {
                        ErrorBar::new_vertical(x, lo, m, hi, color.stroke_width(1), 8)
                    }))
                    .map_err(plot_err)?;
                chart
                    .draw_series(
                        seg.iter()
                            .map(|&(x, m, _, _)| Circle::new((x, m), 3, color.filled())),
                    )
                    .map_err(plot_err)?;
            }
            chart
                .draw_series(LineSeries::new(
                    seg.iter().map(|&(x, m, _, _)| (x, m)),
                    line,
                ))
                .map_err(plot_err)?;
        }
        // A legend entry per series, even one with nothing drawable (an empty line series).
        chart
            .draw_series(LineSeries::new(std::iter::empty::<(f64, f64)>(), line))
            .map_err(plot_err)?
            .label(curve.label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 22, y)], color.stroke_width(3))
            });
    }

    chart
        .configure_series_labels()
        .position(legend_corner(curves, &x_range, &y_range))
        .margin(10)
        .label_font((FONT, text_px))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .draw()
        .map_err(plot_err)?;
    Ok(())
}

/// A tick value without float noise or needless zeros ("2", "0.25", "1.5e-6"); `span` is the
/// axis range, below whose 1e-9 a value is taken for 0.
fn tick_label(v: f64, span: f64) -> String {
    if v.abs() <= span.abs() * 1e-9 {
        return "0".to_string();
    }
    let trim = |s: &str| s.trim_end_matches('0').trim_end_matches('.').to_string();
    if (1e-4..1e7).contains(&v.abs()) {
        trim(&format!("{v:.6}"))
    } else {
        let s = format!("{v:.3e}");
        let (mantissa, exp) = s.split_once('e').unwrap_or((&s, "0"));
        format!("{}e{exp}", trim(mantissa))
    }
}

/// The tick label of log10-axis value `v`: 10^v to two significant digits ("0.32", "0.0032",
/// "3.2"; three at 100 and above: "316").
fn log_tick_label(v: f64) -> String {
    let x = 10f64.powf(v);
    let digits = (1.0 - x.log10().floor()).max(0.0) as usize;
    let s = format!("{x:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// The plot corner whose box (40% of the width, a line of height per series) holds the fewest
/// mean ± stderr points, so the legend hides as little data as possible; ties go in reading
/// order from the upper right.
fn legend_corner(
    curves: &[Curve<'_>],
    x_range: &std::ops::Range<f64>,
    y_range: &std::ops::Range<f64>,
) -> SeriesLabelPosition {
    let fx = |x: f64| (x - x_range.start) / (x_range.end - x_range.start);
    let fy = |y: f64| (y - y_range.start) / (y_range.end - y_range.start);
    let box_h = (0.08 * curves.len() as f64 + 0.06).min(0.9);
    let corners = [
        (SeriesLabelPosition::UpperRight, true, true),
        (SeriesLabelPosition::UpperLeft, false, true),
        (SeriesLabelPosition::LowerRight, true, false),
        (SeriesLabelPosition::LowerLeft, false, false),
    ];
    let hits = |right: bool, upper: bool| {
        let in_x = |x: f64| if right { fx(x) >= 0.6 } else { fx(x) <= 0.4 };
        let in_y = |y: f64| {
            if upper {
                fy(y) >= 1.0 - box_h
            } else {
                fy(y) <= box_h
            }
        };
        curves
            .iter()
            .flat_map(Curve::points)
            .map(|&(x, m, lo, hi)| usize::from(in_x(x) && (in_y(m) || in_y(hi) || in_y(lo))))
            .sum::<usize>()
    };
    corners
        .into_iter()
        .min_by_key(|&(_, right, upper)| hits(right, upper))
        .map(|(pos, _, _)| pos)
        .unwrap_or(SeriesLabelPosition::UpperRight)
}

/// Writes the RGB buffer `rgb` (`width` × `height`, 8 bits per channel) as a PNG file.
pub(crate) fn write_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), PlotError> {
    let file = File::create(path).map_err(|source| PlotError::CreatePng {
        path: path.to_owned(),
        source,
    })?;
    let mut out = BufWriter::new(file);
    let mut encoder = png::Encoder::new(&mut out, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let write = || -> Result<(), png::EncodingError> {
        let mut writer = encoder.write_header()?;
        writer.write_image_data(rgb)?;
        writer.finish()?;
        Ok(())
    };
    write()
        .and_then(|()| out.flush().map_err(Into::into))
        .map_err(|source| PlotError::WritePng {
            path: path.to_owned(),
            source,
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;
    use std::sync::atomic::{AtomicUsize, Ordering};

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * (1.0 + a.abs().max(b.abs()))
    }

    /// A fresh path in the system temp dir. Set LEARNER_PLOT_KEEP=1 to keep the files for a look.
    fn temp_png(name: &str) -> PathBuf {
        static NEXT: AtomicUsize = AtomicUsize::new(0);
        let k = NEXT.fetch_add(1, Ordering::Relaxed);
        std::env::temp_dir().join(format!(
            "learner-plot-{}-{k}-{name}.png",
            std::process::id()
        ))
    }

    fn cleanup(path: &Path) {
        if std::env::var_os("LEARNER_PLOT_KEEP").is_some() {
            eprintln!("kept {}", path.display());
        } else {
            let _ = std::fs::remove_file(path);
        }
    }

    #[test]
    fn mean_stderr_hand_computed_unequal_lengths_and_nan() {
        let runs = vec![
            vec![1.0, 2.0, 3.0],
            vec![3.0, 4.0],
            vec![5.0, f64::NAN, 7.0, 10.0],
        ];
        let (mean, se, n) = mean_stderr(&runs);
        assert_eq!(n, vec![3, 2, 2, 1]);
        // i=0: {1,3,5}: mean 3, sample var (4+0+4)/2 = 4, se = 2/sqrt(3).
        // i=1: {2,4} (NaN skipped): mean 3, var (1+1)/1 = 2, se = sqrt(2)/sqrt(2) = 1.
        // i=2: {3,7}: mean 5, var (4+4)/1 = 8, se = sqrt(8)/sqrt(2) = 2.
        // i=3: {10}: one run, se 0.
        let want_mean = [3.0, 3.0, 5.0, 10.0];
        let want_se = [2.0 / 3f64.sqrt(), 1.0, 2.0, 0.0];
        for i in 0..4 {
            assert!(close(mean[i], want_mean[i]), "mean[{i}] = {}", mean[i]);
            assert!(close(se[i], want_se[i]), "se[{i}] = {}", se[i]);
        }
    }

    #[test]
    fn log_tick_labels_have_two_significant_digits() {
        assert_eq!(log_tick_label(-0.5), "0.32");
        assert_eq!(log_tick_label(-2.5), "0.0032");
        assert_eq!(log_tick_label(-2.0), "0.01");
        assert_eq!(log_tick_label(0.5), "3.2");
        assert_eq!(log_tick_label(2.5), "316");
    }

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(tick_label(110.0, 100.0), "110");
        assert_eq!(tick_label(0.30000000000000004, 1.0), "0.3");
        assert_eq!(tick_label(-2.5, 10.0), "-2.5");
        assert_eq!(tick_label(1e-17, 1.0), "0");
        assert_eq!(tick_label(1.5e-6, 1e-5), "1.5e-6");
        assert_eq!(tick_label(2e8, 1e9), "2e8");
    }

    #[test]
    fn mean_stderr_edge_cases() {
        assert_eq!(mean_stderr(&[]), (vec![], vec![], vec![]));
        let (m, s, n) = mean_stderr(&[vec![], vec![]]);
        assert!(m.is_empty() && s.is_empty() && n.is_empty());
        // Only NaN at an index: no data there.
        let (m, s, n) = mean_stderr(&[vec![f64::NAN, 1.0], vec![f64::NAN, 3.0]]);
        assert_eq!(n, vec![0, 2]);
        assert!(m[0].is_nan() && s[0].is_nan());
        assert!(close(m[1], 2.0) && close(s[1], 1.0));
        // Identical runs: zero spread.
        let (m, s, _) = mean_stderr(&[vec![0.5; 3], vec![0.5; 3]]);
        assert_eq!((m, s), (vec![0.5; 3], vec![0.0; 3]));
    }

    fn example_series() -> Vec<Series> {
        let runs_a: Vec<Vec<f64>> = (0..5)
            .map(|seed| {
                (0..12)
                    .map(|i| 100.0 * (-0.3 * i as f64).exp() + 4.0 * ((seed * 7 + i) % 5) as f64)
                    .collect()
            })
            .collect();
        let runs_b: Vec<Vec<f64>> = (0..4)
            .map(|seed| {
                (0..10 + seed)
                    .map(|i| 90.0 - 4.0 * i as f64 + 6.0 * ((seed * 3 + i) % 4) as f64)
                    .collect()
            })
            .collect();
        [("LQR+GAIfO", runs_a), ("PPO baseline", runs_b)]
            .into_iter()
            .map(|(label, runs)| {
                let (mean, stderr, _) = mean_stderr(&runs);
                Series {
                    label: label.to_string(),
                    x: (0..mean.len()).map(|i| i as f64).collect(),
                    mean,
                    stderr,
                }
            })
            .collect()
    }

    fn decode(bytes: &[u8]) -> (png::OutputInfo, Vec<u8>) {
        let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
            .read_info()
            .unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        buf.truncate(info.buffer_size());
        (info, buf)
    }

    #[test]
    fn plot_curves_writes_png_of_requested_size() {
        let path = temp_png("curves");
        let series = example_series();
        plot_curves(
            &path,
            "Cost vs iteration (mean ± SE, 5 seeds)",
            "iteration",
            "cost",
            &series,
            (800, 500),
        )
        .unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
        assert_eq!(&bytes[12..16], b"IHDR");
        let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
        let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
        assert_eq!((w, h), (800, 500));

        // Not blank: a fair share of non-white pixels, and both series' colours are drawn.
        let (info, rgb) = decode(&bytes);
        assert_eq!(
            (info.width, info.height, info.color_type),
            (800, 500, png::ColorType::Rgb)
        );
        let pixels: Vec<[u8; 3]> = rgb.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
        let non_white = pixels.iter().filter(|p| **p != [255, 255, 255]).count();
        assert!(
            non_white > pixels.len() / 50,
            "only {non_white} non-white pixels"
        );
        for c in &PALETTE[..2] {
            let want = [c.0, c.1, c.2];
            let hits = pixels.iter().filter(|p| **p == want).count();
            assert!(hits > 200, "colour {want:?} drawn on only {hits} pixels");
        }
        // Text (black glyphs) is rendered.
        let dark = pixels.iter().filter(|p| p.iter().all(|&v| v < 60)).count();
        assert!(dark > 500, "only {dark} dark pixels: text missing?");
        cleanup(&path);
    }

    #[test]
    fn plot_curves_many_points_band_only() {
        // 3 x 150 points: past MAX_POINTS_FOR_ERROR_BARS, so lines over bands, no markers.
        let path = temp_png("many");
        let series: Vec<Series> = (0..3)
            .map(|k| {
                let runs: Vec<Vec<f64>> = (0..8)
                    .map(|seed| {
                        (0..150)
                            .map(|i| {
                                let t = i as f64 / 150.0;
                                (1.0 + k as f64) * (-3.0 * t).exp()
                                    + 0.8 * ((seed * 13 + i * 7 + k) % 11) as f64 / 11.0
                            })
                            .collect()
                    })
                    .collect();
                let (mean, stderr, _) = mean_stderr(&runs);
                Series {
                    label: format!("variant {k}"),
                    x: (0..150).map(|i| i as f64).collect(),
                    mean,
                    stderr,
                }
            })
            .collect();
        plot_curves(
            &path,
            "Many iterations",
            "iteration",
            "normalised cost",
            &series,
            (900, 550),
        )
        .unwrap();
        assert!(std::fs::metadata(&path).unwrap().len() > 5000);
        cleanup(&path);
    }

    #[test]
    fn plot_curves_degenerate_but_drawable() {
        // One point, a flat line, NaN gaps, and an all-NaN series alongside a drawable one.
        let path = temp_png("degenerate");
        let series = vec![
            Series {
                label: "one point".into(),
                x: vec![2.0],
                mean: vec![1.5],
                stderr: vec![0.25],
            },
            Series {
                label: "flat with gap".into(),
                x: vec![0.0, 1.0, 2.0, 3.0, 4.0],
                mean: vec![1.0, 1.0, f64::NAN, 1.0, 1.0],
                stderr: vec![0.0, 0.0, f64::NAN, f64::NAN, 0.0],
            },
            Series {
                label: "no data".into(),
                x: vec![0.0],
                mean: vec![f64::NAN],
                stderr: vec![f64::NAN],
            },
        ];
        plot_curves(&path, "degenerate", "x", "y", &series, (400, 300)).unwrap();
        assert!(std::fs::metadata(&path).unwrap().len() > 1000);
        cleanup(&path);
    }

    #[test]
    fn plot_curves_into_missing_directory_is_an_error_naming_the_path() {
        let dir = std::env::temp_dir().join(format!("learner-plot-missing-{}", std::process::id()));
        let path = dir.join("sub").join("fig.png");
        let err = plot_curves(&path, "t", "x", "y", &example_series(), (400, 300)).unwrap_err();
        let msg = crate::error::line(&err);
        assert!(msg.contains(&path.display().to_string()), "{msg}");
        assert!(!path.exists());
    }

    #[test]
    fn plot_curves_rejects_what_it_cannot_draw() {
        let path = temp_png("rejected");
        let msg = |series: &[Series], size| {
            crate::error::line(&plot_curves(&path, "t", "x", "y", series, size).unwrap_err())
        };
        assert!(msg(&[], (400, 300)).contains("no series"));
        let nan = Series {
            label: "nan".into(),
            x: vec![0.0, 1.0],
            mean: vec![f64::NAN; 2],
            stderr: vec![0.0; 2],
        };
        let empty = Series {
            label: "empty".into(),
            x: vec![],
            mean: vec![],
            stderr: vec![],
        };
        assert!(msg(&[nan, empty], (400, 300)).contains("nothing to plot"));
        let ragged = Series {
            label: "ragged".into(),
            x: vec![0.0, 1.0],
            mean: vec![1.0],
            stderr: vec![0.0],
        };
        let m = msg(&[ragged], (400, 300));
        assert!(m.contains("ragged") && m.contains("2, 1, 1"), "{m}");
        let negative = Series {
            label: "neg".into(),
            x: vec![0.0],
            mean: vec![1.0],
            stderr: vec![-1.0],
        };
        assert!(msg(&[negative], (400, 300)).contains("negative stderr"));
        assert!(msg(&example_series(), (0, 300)).contains("out of range"));
        assert!(!path.exists());
    }
}
