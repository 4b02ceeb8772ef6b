//! Pictures of motions (docs/design.md §4.15): a grid of panels, one a motion, in the style of
//! the LASA handwriting figures: the demonstrations in grey, the imitations in colour, the goal
//! marked. Each panel has equal scales on its two axes, so a shape is not distorted; its range
//! is the panel's own (every drawn point and the goal, padded). Coordinates are in the plane
//! of the motion (e.g. cm along the two axes of `learner dataset lasa`'s plane); the caller
//! projects them. Drawn by plotters into memory and written as PNG ([`crate::plot`]).

use std::path::Path;

use plotters::prelude::*;

use crate::plot::{
    plot_err, register_font, write_png, PlotError, FONT, MAX_SIDE, MIN_SIDE, PALETTE,
};

/// One panel: a motion's demonstrations and imitations in the plane.
#[derive(Clone, Debug, PartialEq)]
pub struct PathPanel {
    /// The panel's caption (e.g. the shape and its path RMSE over the spread).
    pub title: String,
    /// The demonstrations' paths (drawn grey), points in the plane's units.
    pub demos: Vec<Vec<[f64; 2]>>,
    /// The imitations' paths (drawn in colour, one colour each), same units.
    pub imitations: Vec<Vec<[f64; 2]>>,
    /// The goal (a black dot ringed).
    pub goal: [f64; 2],
}

/// The grey of the demonstrations.
const GREY: RGBColor = RGBColor(160, 160, 160);

/// Writes `panels` as a PNG at `path`: `columns` panels a row, each `panel_px` square, under
/// `title`; `unit` names the axes' unit. A point with a non-finite coordinate breaks its line.
/// Errors (never panics) when there is no panel, a panel has no finite point, the picture's
/// size is out of range, or the file cannot be written (naming `path`).
pub fn plot_path_grid(
    path: &Path,
    title: &str,
    unit: &str,
    panels: &[PathPanel],
    columns: usize,
    panel_px: u32,
) -> Result<(), PlotError> {
    if panels.is_empty() {
        return Err(PlotError::NoPanels {
            path: path.to_owned(),
        });
    }
    let columns = columns.clamp(1, panels.len());
    let rows = panels.len().div_ceil(columns);
    let title_px = 40;
    let (width, height) = (
        (columns as u64 * panel_px as u64).min(u32::MAX as u64) as u32,
        (rows as u64 * panel_px as u64 + title_px).min(u32::MAX as u64) as u32,
    );
    if !(MIN_SIDE..=MAX_SIDE).contains(&width) || !(MIN_SIDE..=MAX_SIDE).contains(&height) {
        return Err(PlotError::Size {
            path: path.to_owned(),
            width,
            height,
        });
    }
    let ranges = panels
        .iter()
        .map(|p| {
            square_range(p).ok_or_else(|| PlotError::In {
                path: path.to_owned(),
                source: Box::new(PlotError::Plotters(format!(
                    "panel `{}` has no finite point",
                    p.title
                ))),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    register_font()?;
    let mut rgb = vec![0u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let body = root
            .titled(title, (FONT, 22).into_font().color(&BLACK))
            .map_err(plot_err)?;
        let areas = body.split_evenly((rows, columns));
        for ((area, panel), (xr, yr)) in areas.iter().zip(panels).zip(ranges) {
            draw_panel(area, panel, unit, xr, yr).map_err(|e| PlotError::Drawing {
                path: path.to_owned(),
                source: Box::new(e),
            })?;
        }
        root.present().map_err(plot_err)?;
    }
    write_png(path, width, height, &rgb)
}

/// Equal-span ranges around every finite point of `p` and its goal, padded by 8 %.
fn square_range(p: &PathPanel) -> Option<(std::ops::Range<f64>, std::ops::Range<f64>)> {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    let points = p.demos.iter().chain(&p.imitations).flatten();
    for q in points.chain(std::iter::once(&p.goal)) {
        if q.iter().all(|v| v.is_finite()) {
            for r in 0..2 {
                lo[r] = lo[r].min(q[r]);
                hi[r] = hi[r].max(q[r]);
            }
        }
    }
    if !lo[0].is_finite() {
        return None;
    }
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-9) * 1.16;
    let c = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    Some((
        c[0] - span / 2.0..c[0] + span / 2.0,
        c[1] - span / 2.0..c[1] + span / 2.0,
    ))
}

/// The runs of consecutive finite points of `path`.
fn segments(path: &[[f64; 2]]) -> Vec<Vec<(f64, f64)>> {
    let mut out = vec![Vec::new()];
    for q in path {
        if q.iter().all(|v| v.is_finite()) {
            out.last_mut().expect("one").push((q[0], q[1]));
        } else if !out.last().expect("one").is_empty() {
            out.push(Vec::new());
        }
    }
    out.retain(|s| !s.is_empty());
    out
}

fn draw_panel(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    panel: &PathPanel,
    unit: &str,
    xr: std::ops::Range<f64>,
    yr: std::ops::Range<f64>,
) -> Result<(), PlotError> {
    // A square plotting area: the labels' margins are the same on both axes.
    let (w, h) = area.dim_in_pixel();
    let side = w.min(h);
    let area = area.margin(
        (h - side) / 2,
        (h - side) / 2,
        (w - side) / 2,
        (w - side) / 2,
    );
    let mut chart = ChartBuilder::on(&area)
        .caption(&panel.title, (FONT, 15).into_font())
        .margin(6)
        .x_label_area_size(34)
        .y_label_area_size(34)
        .build_cartesian_2d(xr, yr)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_labels(4)
        .y_labels(4)
        .light_line_style(WHITE)
        .bold_line_style(RGBColor(235, 235, 235))
        .label_style((FONT, 11).into_font())
        .x_desc(unit)
        .axis_desc_style((FONT, 11).into_font())
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()
        .map_err(plot_err)?;
    for d in &panel.demos {
        for s in segments(d) {
            chart
                .draw_series(LineSeries::new(s, GREY.stroke_width(2)))
                .map_err(plot_err)?;
        }
    }
    for (i, im) in panel.imitations.iter().enumerate() {
        let colour = PALETTE[i % PALETTE.len()];
        for s in segments(im) {
            chart
                .draw_series(LineSeries::new(s, colour.stroke_width(2)))
                .map_err(plot_err)?;
        }
    }
    let g = (panel.goal[0], panel.goal[1]);
    chart
        .draw_series([
            Circle::new(g, 6, BLACK.stroke_width(1)),
            Circle::new(g, 3, BLACK.filled()),
        ])
        .map_err(plot_err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn panel(k: usize) -> PathPanel {
        let arc = |r: f64| -> Vec<[f64; 2]> {
            (0..=40)
                .map(|i| {
                    let a = std::f64::consts::PI * i as f64 / 40.0;
                    [r * a.cos() - r, r * a.sin()]
                })
                .collect()
        };
        PathPanel {
            title: format!("shape {k}"),
            demos: vec![arc(9.5), arc(10.5)],
            imitations: vec![arc(10.0)],
            goal: [-20.0, 0.0],
        }
    }

    fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
        let d = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
        let mut r = d.read_info().unwrap();
        let mut buf = vec![0; r.output_buffer_size().unwrap()];
        let info = r.next_frame(&mut buf).unwrap();
        buf.truncate(info.buffer_size());
        (info.width, info.height, buf)
    }

    /// The grid has the asked layout, and the demonstrations' grey, the imitation's colour and
    /// the goal's black are drawn.
    #[test]
    fn a_grid_of_panels_draws_demonstrations_imitations_and_goals() {
        let dir = std::env::temp_dir().join(format!("plot-paths-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("grid.png");
        let panels: Vec<PathPanel> = (0..5).map(panel).collect();
        plot_path_grid(&path, "paths", "cm", &panels, 3, 240).unwrap();
        let (w, h, rgb) = decode(&path);
        assert_eq!((w, h), (3 * 240, 2 * 240 + 40));
        let count = |c: RGBColor| {
            rgb.chunks(3)
                .filter(|p| p[0] == c.0 && p[1] == c.1 && p[2] == c.2)
                .count()
        };
        assert!(count(GREY) > 5 * 200, "grey {}", count(GREY));
        assert!(count(PALETTE[0]) > 5 * 100, "colour {}", count(PALETTE[0]));
        assert!(count(BLACK) > 5 * 20, "black {}", count(BLACK));
        // The sixth cell of the grid is empty: white in its middle.
        let at = |x: u32, y: u32| &rgb[((y * w + x) * 3) as usize..((y * w + x) * 3 + 3) as usize];
        assert_eq!(at(600, 40 + 360), [255, 255, 255]);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn what_cannot_be_drawn_is_refused_naming_the_file() {
        let path = Path::new("/nonexistent-dir/grid.png");
        let e = plot_path_grid(path, "t", "cm", &[], 3, 240).unwrap_err();
        assert!(e.to_string().contains("no panels"), "{e}");
        let mut p = panel(0);
        p.demos = vec![vec![[f64::NAN, 0.0]]];
        p.imitations.clear();
        p.goal = [f64::NAN; 2];
        let e = plot_path_grid(path, "t", "cm", &[p], 3, 240).unwrap_err();
        assert!(format!("{e:#?}").contains("no finite point"), "{e:?}");
        let e = plot_path_grid(path, "t", "cm", &[panel(0)], 1, 100).unwrap_err();
        assert!(e.to_string().contains("out of range"), "{e}");
        let e = plot_path_grid(path, "t", "cm", &[panel(0)], 1, 240).unwrap_err();
        assert!(e.to_string().contains("/nonexistent-dir/grid.png"), "{e}");
    }
}
