//! PNG of a map with every method's path: terrain colour map (height), hard obstacles, start,
//! goal region, one coloured polyline per method, a legend and the metrics of each path; and a
//! PNG of a P-F feedback law (cost-to-go bands and direction arrows).

use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use pf_planner::error::PlanError;
use pf_planner::feedback_grid::FeedbackGrid;
use pf_planner::grid::GoalRegion;
use pf_planner::map::{GridMap, Point};
use pf_planner::metrics::PathMetrics;

/// One path to draw.
#[derive(Debug, Clone)]
pub struct PlotPath {
    /// Legend label (method name).
    pub label: String,
    /// The polyline.
    pub points: Vec<Point>,
    /// Metrics printed under the map.
    pub metrics: Option<PathMetrics>,
}

/// Path colours, one per method in order (colour-blind friendly).
const PATH_COLOURS: [RGBColor; 6] = [
    RGBColor(230, 25, 75),
    RGBColor(0, 130, 200),
    RGBColor(255, 225, 25),
    RGBColor(245, 130, 48),
    RGBColor(145, 30, 180),
    RGBColor(70, 240, 240),
];

/// Height colour map stops (fraction of the height range → colour): lowland green to rock to snow.
const TERRAIN_STOPS: [(f64, [f64; 3]); 5] = [
    (0.0, [38.0, 115.0, 77.0]),
    (0.2, [120.0, 170.0, 90.0]),
    (0.45, [215.0, 200.0, 120.0]),
    (0.75, [150.0, 110.0, 80.0]),
    (1.0, [245.0, 245.0, 245.0]),
];

fn terrain_colour(fraction: f64) -> RGBColor {
    let f = fraction.clamp(0.0, 1.0);
    let i = TERRAIN_STOPS
        .iter()
        .position(|s| s.0 >= f)
        .unwrap_or(TERRAIN_STOPS.len() - 1)
        .max(1);
    let (f0, c0) = TERRAIN_STOPS[i - 1];
    let (f1, c1) = TERRAIN_STOPS[i];
    let t = if f1 > f0 { (f - f0) / (f1 - f0) } else { 0.0 };
    let mix = |k: usize| (c0[k] + t * (c1[k] - c0[k])).round() as u8;
    RGBColor(mix(0), mix(1), mix(2))
}

/// A chart over map coordinates (metres).
type MapChart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A chart of the map rectangle `lo`–`hi` (metres) on `area`: caption, labelled axes, no grid.
fn map_chart<'a, 'b>(
    area: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    caption: String,
    font_size: u32,
    (lo, hi): (Point, Point),
    out: &Path,
) -> Result<MapChart<'a, 'b>, PlanError> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", font_size))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(45)
        .build_cartesian_2d(lo[0]..hi[0], lo[1]..hi[1])
        .map_err(|e| plot_error(out, e))?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x [m]")
        .y_desc("y [m]")
        .draw()
        .map_err(|e| plot_error(out, e))?;
    Ok(chart)
}

/// The goal disc's outline (at least half a cell wide, so a point goal stays visible).
fn draw_goal<'a, 'b: 'a>(
    chart: &mut MapChart<'a, 'b>,
    goal: &GoalRegion,
    res: f64,
    out: &Path,
) -> Result<(), PlanError> {
    let goal_outline: Vec<(f64, f64)> = (0..=64)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 64.0;
            let r = goal.radius.max(0.5 * res);
            (goal.center[0] + r * a.cos(), goal.center[1] + r * a.sin())
        })
        .collect();
    chart
        .draw_series(std::iter::once(PathElement::new(
            goal_outline,
            BLUE.stroke_width(3),
        )))
        .map_err(|e| plot_error(out, e))?
        .label("goal")
        .legend(|(x, y)| Circle::new((x + 10, y), 5, BLUE.stroke_width(2)));
    Ok(())
}

/// The start marker, then the legend of everything drawn so far.
fn draw_start_and_legend<'a, 'b: 'a>(
    chart: &mut MapChart<'a, 'b>,
    start: Point,
    out: &Path,
) -> Result<(), PlanError> {
    chart
        .draw_series(std::iter::once(Circle::new(
            (start[0], start[1]),
            7,
            GREEN.filled(),
        )))
        .map_err(|e| plot_error(out, e))?
        .label("start")
        .legend(|(x, y)| Circle::new((x + 10, y), 5, GREEN.filled()));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(|e| plot_error(out, e))?;
    Ok(())
}

fn plot_error(path: &Path, e: impl std::fmt::Display) -> PlanError {
    PlanError::Io {
        path: path.display().to_string(),
        reason: format!("plotting failed: {e}"),
    }
}

/// Draws with `draw` on an RGB canvas of `size` pixels, then writes it to `out` as a PNG.
/// (plotters' own file output would compile the whole `image` crate for this one format.)
fn render_png(
    out: &Path,
    (width, height): (u32, u32),
    draw: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> Result<(), PlanError>,
) -> Result<(), PlanError> {
    let mut rgb = vec![0u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        draw(&root)?;
        root.present().map_err(|e| plot_error(out, e))?;
    }
    let file = std::fs::File::create(out).map_err(|e| plot_error(out, e))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(|e| plot_error(out, e))?;
    writer
        .write_image_data(&rgb)
        .map_err(|e| plot_error(out, e))?;
    writer.finish().map_err(|e| plot_error(out, e))
}

/// Draws `map`, `start`, `goal`, `paths` and free-text `notes` (e.g. failed methods) to a PNG at `out`.
pub fn plot_plans(
    out: &Path,
    title: &str,
    map: &GridMap,
    start: Point,
    goal: &GoalRegion,
    paths: &[PlotPath],
    notes: &[String],
) -> Result<(), PlanError> {
    map.validate()?;
    let text_lines = paths.len() + notes.len() + 1;
    let (width, map_px) = (900u32, 820u32);
    let height = map_px + 30 + 22 * text_lines as u32;
    render_png(out, (width, height), |root| {
        root.fill(&WHITE).map_err(|e| plot_error(out, e))?;
        let (upper, lower) = root.split_vertically(map_px);
        let (lo, hi) = map.bounds();
        let (h_min, h_max) = map
            .heights
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
                (a.min(h), b.max(h))
            });
        let caption =
            format!("{title}   (colour: height {h_min:.2}–{h_max:.2} m; black: obstacles)");
        let mut chart = map_chart(&upper, caption, 18, (lo, hi), out)?;
        let span = (h_max - h_min).max(1e-9);
        let res = map.resolution;
        chart
            .draw_series((0..map.len()).map(|i| {
                let (ix, iy) = (i % map.width, i / map.width);
                let x0 = map.origin[0] + ix as f64 * res;
                let y0 = map.origin[1] + iy as f64 * res;
                let colour = if map.is_obstacle(ix, iy) {
                    RGBColor(20, 20, 20)
                } else {
                    terrain_colour((map.heights[i] - h_min) / span)
                };
                Rectangle::new([(x0, y0), (x0 + res, y0 + res)], colour.filled())
            }))
            .map_err(|e| plot_error(out, e))?;
        draw_goal(&mut chart, goal, res, out)?;
        for (k, p) in paths.iter().enumerate() {
            let colour = PATH_COLOURS[k % PATH_COLOURS.len()];
            chart
                .draw_series(std::iter::once(PathElement::new(
                    p.points.iter().map(|q| (q[0], q[1])).collect::<Vec<_>>(),
                    colour.stroke_width(3),
                )))
                .map_err(|e| plot_error(out, e))?
                .label(p.label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(3))
                });
        }
        draw_start_and_legend(&mut chart, start, out)?;
        let style = ("monospace", 15).into_font().color(&BLACK);
        let mut y = 8;
        lower
            .draw_text(
                &format!(
                    "{:<22}{:>10}{:>11}{:>14}{:>14}{:>11}",
                    "method", "∫p ds", "length m", "in obst. m", "clearance m", "max slope"
                ),
                &style,
                (20, y),
            )
            .map_err(|e| plot_error(out, e))?;
        for p in paths {
            y += 22;
            let line = match &p.metrics {
                Some(m) => format!(
                    "{:<22}{:>10.4}{:>11.2}{:>14.3}{:>14}{:>10.1}°",
                    p.label,
                    m.cost_integral,
                    m.length,
                    m.length_in_obstacles,
                    if m.min_clearance.is_finite() {
                        format!("{:.3}", m.min_clearance)
                    } else {
                        "–".into()
                    },
                    m.max_slope_deg
                ),
                None => p.label.clone(),
            };
            lower
                .draw_text(&line, &style, (20, y))
                .map_err(|e| plot_error(out, e))?;
        }
        for note in notes {
            y += 22;
            lower
                .draw_text(note, &style, (20, y))
                .map_err(|e| plot_error(out, e))?;
        }
        Ok(())
    })
}

/// Filled bands of the cost-to-go plot (contour levels between 0 and the largest finite value).
const COST_BANDS: usize = 12;

/// Arrows along the longer side of the feedback-field plot: enough to see the law's shape,
/// few enough that each arrow is readable.
const ARROWS_ALONG_LONGER_SIDE: usize = 32;

/// Colour of band `k` of [`COST_BANDS`]: dark blue at the goal to pale yellow far away.
fn band_colour(k: usize) -> RGBColor {
    let t = k as f64 / (COST_BANDS - 1) as f64;
    let mix = |a: f64, b: f64| (a + t * (b - a)).round() as u8;
    RGBColor(mix(40.0, 250.0), mix(60.0, 235.0), mix(150.0, 160.0))
}

/// PNG of a feedback law: filled contour bands of the cost-to-go (∫p ds to the goal), cells that
/// cannot reach the goal (obstacles) dark, the direction field as arrows on a subsampled lattice,
/// the goal disc, the start and (optionally) the planned path.
pub fn plot_feedback_field(
    out: &Path,
    title: &str,
    field: &FeedbackGrid,
    start: Point,
    path: Option<&[Point]>,
) -> Result<(), PlanError> {
    let (width, height) = (900u32, 860u32);
    render_png(out, (width, height), |root| {
        root.fill(&WHITE).map_err(|e| plot_error(out, e))?;
        let res = field.resolution;
        let lo = field.origin;
        let hi = [
            lo[0] + field.width as f64 * res,
            lo[1] + field.height as f64 * res,
        ];
        let max_cost = field
            .cost_to_go
            .iter()
            .copied()
            .filter(|c| c.is_finite() && *c >= 0.0)
            .fold(0.0f64, f64::max)
            .max(1e-12);
        let caption = format!(
            "{title}: feedback law (colour: ∫p ds to the goal, 0–{max_cost:.3} in {COST_BANDS} bands; dark: unreachable)"
        );
        let mut chart = map_chart(root, caption, 16, (lo, hi), out)?;
        chart
            .draw_series((0..field.len()).map(|i| {
                let (ix, iy) = (i % field.width, i / field.width);
                let x0 = lo[0] + ix as f64 * res;
                let y0 = lo[1] + iy as f64 * res;
                let cost = field.cost_to_go[i];
                let colour = if cost < 0.0 || !cost.is_finite() {
                    RGBColor(25, 25, 25)
                } else {
                    let band = ((cost / max_cost) * COST_BANDS as f64).floor() as usize;
                    band_colour(band.min(COST_BANDS - 1))
                };
                Rectangle::new([(x0, y0), (x0 + res, y0 + res)], colour.filled())
            }))
            .map_err(|e| plot_error(out, e))?;
        let stride = field
            .width
            .max(field.height)
            .div_ceil(ARROWS_ALONG_LONGER_SIDE)
            .max(1);
        let arrow = 0.8 * stride as f64 * res;
        let mut arrows = Vec::new();
        for iy in (stride / 2..field.height).step_by(stride) {
            for ix in (stride / 2..field.width).step_by(stride) {
                let i = field.index(ix, iy);
                let d = [field.dir_x[i], field.dir_y[i]];
                if d == [0.0, 0.0] {
                    continue;
                }
                let c = field.cell_center(ix, iy);
                let tail = (c[0] - 0.5 * arrow * d[0], c[1] - 0.5 * arrow * d[1]);
                let head = (c[0] + 0.5 * arrow * d[0], c[1] + 0.5 * arrow * d[1]);
                // Two barbs at ±150° from the direction, a third of the shaft long.
                let barb = |angle: f64| {
                    let (s, co) = angle.sin_cos();
                    let b = [d[0] * co - d[1] * s, d[0] * s + d[1] * co];
                    (head.0 + arrow / 3.0 * b[0], head.1 + arrow / 3.0 * b[1])
                };
                let turn = 150f64.to_radians();
                arrows.push(vec![tail, head, barb(turn)]);
                arrows.push(vec![head, barb(-turn)]);
            }
        }
        chart
            .draw_series(
                arrows
                    .into_iter()
                    .map(|points| PathElement::new(points, BLACK.stroke_width(1))),
            )
            .map_err(|e| plot_error(out, e))?;
        draw_goal(&mut chart, &field.goal, res, out)?;
        if let Some(points) = path {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    points.iter().map(|q| (q[0], q[1])).collect::<Vec<_>>(),
                    PATH_COLOURS[0].stroke_width(3),
                )))
                .map_err(|e| plot_error(out, e))?
                .label("P-F path")
                .legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], PATH_COLOURS[0].stroke_width(3))
                });
        }
        draw_start_and_legend(&mut chart, start, out)?;
        Ok(())
    })
}
