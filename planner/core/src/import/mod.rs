//! Terrain import: real elevation models (ESRI ASCII grids, GeoTIFF) to the map format.
//!
//! Pipeline ([`import_map`], then [`scenario_from`]): read the crop window of the source
//! (rows turned from the file's north-first order to the map's south-first order) → resample
//! bilinearly to square cells (a cell touching nodata stays nodata) → nodata cells become hard
//! obstacles, their heights filled from the nearest valid cell → heights shifted so the lowest
//! valid cell is at 0 m (the planner's p = h/h_max needs h ≥ 0) → uniform scale of cell size and
//! heights together (slopes kept) → a [`GridMap`] with its origin at (0, 0), the south-west
//! corner of the crop. Start and goal are then given in those map coordinates. See
//! `docs/terrain-import.md` for the conventions and an example.

mod esri_ascii;
mod geotiff;
mod raster;
mod resample;

use std::fmt;
use std::path::Path;

pub use esri_ascii::read_esri_ascii;
pub use geotiff::read_geotiff;
pub use raster::{CellWindow, Crop, Raster, RasterGeometry, MAX_ABS_ELEVATION};
pub use resample::{fill_nodata, resample};

use crate::error::PlanError;
use crate::grid::GoalRegion;
use crate::io::MapScenario;
use crate::map::{GridMap, Point, MAX_MAP_CELLS};
use crate::traversability::{slope_deg, TraversabilityParams};

/// File formats [`import_map`] reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DemFormat {
    /// ESRI ASCII grid (`.asc`).
    EsriAscii,
    /// GeoTIFF (`.tif`, `.tiff`).
    GeoTiff,
}

impl DemFormat {
    /// The format a file name's extension names.
    pub fn from_path(path: &Path) -> Result<Self, PlanError> {
        let extension = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match extension.as_deref() {
            Some("asc") => Ok(DemFormat::EsriAscii),
            Some("tif" | "tiff") => Ok(DemFormat::GeoTiff),
            _ => Err(PlanError::InvalidOption {
                name: "format",
                reason: format!(
                    "cannot tell the format of {} from its extension (.asc, .tif, .tiff): give \
                     --format",
                    path.display()
                ),
            }),
        }
    }
}

impl fmt::Display for DemFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            DemFormat::EsriAscii => "ESRI ASCII grid",
            DemFormat::GeoTiff => "GeoTIFF",
        })
    }
}

/// The cell size of the written map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Resolution {
    /// The source's cells (which must be square).
    Source,
    /// Square cells of this edge, metres in the written map (after `scale`).
    CellSize(f64),
    /// The largest square cells with which the crop fits in `columns` × `rows` cells: one side
    /// gets exactly its count, the other at most its count.
    Size { columns: usize, rows: usize },
}

/// How [`import_map`] turns an elevation model into a map.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// `None`: from the file's extension.
    pub format: Option<DemFormat>,
    pub crop: Option<Crop>,
    pub resolution: Resolution,
    /// Factor applied to cell size and heights alike (e.g. 1/50: a 1 m DEM at robot scale).
    pub scale: f64,
    /// Keep absolute elevations instead of shifting the lowest valid cell to 0 m.
    pub keep_elevation: bool,
    /// Cell size of the source in its own units, for rasters without one (or in degrees).
    pub source_cell_size: Option<f64>,
    /// Largest number of cells read from the source and written to the map (at most
    /// [`MAX_MAP_CELLS`]), checked before either is allocated.
    pub max_cells: usize,
}

impl Default for ImportOptions {
    fn default() -> Self {
        Self {
            format: None,
            crop: None,
            resolution: Resolution::Source,
            scale: 1.0,
            keep_elevation: false,
            source_cell_size: None,
            max_cells: MAX_MAP_CELLS,
        }
    }
}

/// Slope statistics of a map's valid cells, degrees, as the traversability model measures slope
/// ([`slope_deg`]: central differences, one-sided at the edge).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlopeStats {
    pub p50: f64,
    pub p95: f64,
    pub max: f64,
}

/// What an import read and wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportSummary {
    pub format: DemFormat,
    /// The whole source raster.
    pub source: RasterGeometry,
    /// The crop window read from it.
    pub window: RasterGeometry,
    /// Cells, cell size and heights of the written map.
    pub width: usize,
    pub height: usize,
    pub resolution: f64,
    pub height_min: f64,
    pub height_max: f64,
    /// Source elevation subtracted before scaling (0 with `keep_elevation`).
    pub elevation_offset: f64,
    pub scale: f64,
    /// Share of the map's cells that were nodata (now obstacles).
    pub nodata_fraction: f64,
    pub slope: SlopeStats,
    /// Things the user should know (ignored or replaced metadata, aliasing).
    pub warnings: Vec<String>,
}

impl fmt::Display for ImportSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (s, w) = (&self.source, &self.window);
        let n = short;
        writeln!(
            f,
            "source:  {} of {} x {} cells of {} x {}, lower-left corner ({}, {})",
            self.format,
            s.columns,
            s.rows,
            n(s.dx),
            n(s.dy),
            n(s.west),
            n(s.south)
        )?;
        writeln!(
            f,
            "crop:    {} x {} cells, lower-left corner ({}, {}) -> map origin (0, 0)",
            w.columns,
            w.rows,
            n(w.west),
            n(w.south)
        )?;
        writeln!(
            f,
            "map:     {} x {} cells of {} m ({} x {} m), scale {}",
            self.width,
            self.height,
            n(self.resolution),
            n(self.width as f64 * self.resolution),
            n(self.height as f64 * self.resolution),
            n(self.scale)
        )?;
        writeln!(
            f,
            "heights: {} .. {} m (source elevation {} subtracted before scaling)",
            n(self.height_min),
            n(self.height_max),
            n(self.elevation_offset)
        )?;
        writeln!(
            f,
            "slope:   p50 {:.1} deg, p95 {:.1} deg, max {:.1} deg",
            self.slope.p50, self.slope.p95, self.slope.max
        )?;
        write!(
            f,
            "nodata:  {:.2} % of the cells (hard obstacles)",
            100.0 * self.nodata_fraction
        )
    }
}

/// `v` with at most 6 decimals and no trailing zeros (summaries, not data).
fn short(v: f64) -> String {
    let text = format!("{v:.6}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    if text == "-0" {
        "0".into()
    } else {
        text.into()
    }
}

/// A map made from an elevation model.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportedMap {
    pub map: GridMap,
    pub summary: ImportSummary,
}

/// Reads `path` and turns it into a map (see the module docs for the steps).
pub fn import_map(path: &Path, options: &ImportOptions) -> Result<ImportedMap, PlanError> {
    let scale = options.scale;
    if !(scale.is_finite() && scale > 0.0) {
        return Err(PlanError::InvalidOption {
            name: "scale",
            reason: format!("must be finite and > 0, got {scale}"),
        });
    }
    if let Some(size) = options.source_cell_size {
        if !(size.is_finite() && size > 0.0) {
            return Err(PlanError::InvalidOption {
                name: "source cell size",
                reason: format!("must be finite and > 0, got {size}"),
            });
        }
    }
    let max_cells = options.max_cells.min(MAX_MAP_CELLS);
    let format = match options.format {
        Some(format) => format,
        None => DemFormat::from_path(path)?,
    };
    let mut warnings = Vec::new();
    let crop = options.crop.as_ref();
    let (source, mut window) = match format {
        DemFormat::EsriAscii => {
            if options.source_cell_size.is_some() {
                warnings.push(
                    "--source-cell-size is ignored: an ESRI ASCII grid states its cell size".into(),
                );
            }
            read_esri_ascii(path, crop, max_cells)?
        }
        DemFormat::GeoTiff => read_geotiff(
            path,
            crop,
            max_cells,
            options.source_cell_size,
            &mut warnings,
        )?,
    };
    let window_geometry = window.geometry;
    let g = &window.geometry;
    let target = match options.resolution {
        Resolution::Source if square(g) => None,
        Resolution::Source => {
            return Err(PlanError::InvalidOption {
                name: "cell size",
                reason: format!(
                    "{} has cells of {} x {}, the map needs square cells: give --cell-size or \
                     --size to resample",
                    path.display(),
                    g.dx,
                    g.dy
                ),
            })
        }
        Resolution::CellSize(size) => {
            if !(size.is_finite() && size > 0.0) {
                return Err(PlanError::InvalidOption {
                    name: "cell size",
                    reason: format!("must be finite and > 0, got {size}"),
                });
            }
            Some(size / scale)
        }
        Resolution::Size { columns, rows } => {
            if columns == 0 || rows == 0 {
                return Err(PlanError::InvalidOption {
                    name: "size",
                    reason: format!("{columns} x {rows} cells: both must be > 0"),
                });
            }
            let (w, h) = g.extent();
            Some((w / columns as f64).max(h / rows as f64))
        }
    };
    if let Some(cell) = target {
        let coarsening = cell / g.dx.min(g.dy);
        if coarsening > 2.0 {
            warnings.push(format!(
                "cells {coarsening:.1} x the source's: bilinear resampling samples the surface at \
                 the new centres without averaging, so features smaller than a cell can be missed"
            ));
        }
        window = resample(&window, cell, max_cells)?;
    }
    let columns = window.geometry.columns;
    let cells = window.values.len();
    let nodata = fill_nodata(&mut window.values, columns).ok_or_else(|| PlanError::Format {
        path: path.display().to_string(),
        reason: "every cell of the crop is nodata".into(),
    })?;
    let nodata_cells = nodata.iter().filter(|&&n| n).count();
    let lowest = window
        .values
        .iter()
        .zip(&nodata)
        .filter(|(_, &n)| !n)
        .map(|(&h, _)| h)
        .fold(f64::INFINITY, f64::min);
    // The planner's height term p = h/h_max needs h >= 0: refuse here rather than at plan time.
    if options.keep_elevation && lowest < 0.0 {
        return Err(PlanError::InvalidOption {
            name: "--keep-elevation",
            reason: format!(
                "the crop goes down to {lowest} m, below 0 m (the planner needs heights >= 0); \
                 leave out --keep-elevation to shift the lowest cell to 0 m"
            ),
        });
    }
    let offset = if options.keep_elevation { 0.0 } else { lowest };
    let heights: Vec<f64> = window.values.iter().map(|h| (h - offset) * scale).collect();
    let obstacles = (nodata_cells > 0).then_some(nodata);
    let map = GridMap::new(
        [0.0, 0.0],
        window.geometry.dx * scale,
        columns,
        window.geometry.rows,
        heights,
        obstacles,
    )?;
    let (height_min, height_max) = map
        .heights
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &h| {
            (lo.min(h), hi.max(h))
        });
    let summary = ImportSummary {
        format,
        source,
        window: window_geometry,
        width: map.width,
        height: map.height,
        resolution: map.resolution,
        height_min,
        height_max,
        elevation_offset: offset,
        scale,
        nodata_fraction: nodata_cells as f64 / cells as f64,
        slope: slope_stats(&map),
        warnings,
    };
    Ok(ImportedMap { map, summary })
}

fn square(g: &RasterGeometry) -> bool {
    (g.dx - g.dy).abs() <= 1e-9 * g.dx.max(g.dy)
}

/// Slope percentiles over the cells that are not obstacles (nearest rank).
pub fn slope_stats(map: &GridMap) -> SlopeStats {
    let mut slopes: Vec<f64> = (0..map.height)
        .flat_map(|iy| (0..map.width).map(move |ix| (ix, iy)))
        .filter(|&(ix, iy)| !map.is_obstacle(ix, iy))
        .map(|(ix, iy)| slope_deg(map, ix, iy))
        .collect();
    if slopes.is_empty() {
        return SlopeStats {
            p50: 0.0,
            p95: 0.0,
            max: 0.0,
        };
    }
    slopes.sort_by(f64::total_cmp);
    let rank =
        |q: f64| slopes[((q * slopes.len() as f64).ceil() as usize).clamp(1, slopes.len()) - 1];
    SlopeStats {
        p50: rank(0.5),
        p95: rank(0.95),
        max: rank(1.0),
    }
}

/// Where the robot starts and what it must reach, in the imported map's coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    pub name: String,
    pub start: Option<Point>,
    pub start_yaw: f64,
    pub goal: Option<Point>,
    pub goal_radius: f64,
}

/// The scenario of an imported map: start and goal are required, inside the map and off its
/// obstacles; the traversability model is the default one.
pub fn scenario_from(map: GridMap, placement: &Placement) -> Result<MapScenario, PlanError> {
    let (lo, hi) = map.bounds();
    let extent = format!(
        "the map spans x {}..{}, y {}..{} m",
        lo[0], hi[0], lo[1], hi[1]
    );
    let (Some(start), Some(goal)) = (placement.start, placement.goal) else {
        return Err(PlanError::InvalidOption {
            name: "start/goal",
            reason: format!(
                "an imported map needs a start and a goal: give --start X,Y --goal X,Y in map \
                 coordinates ({extent})"
            ),
        });
    };
    for (name, point) in [("start", start), ("goal", goal)] {
        if !map.contains(point) {
            return Err(PlanError::InvalidOption {
                name,
                reason: format!("({}, {}) is off the map: {extent}", point[0], point[1]),
            });
        }
        if map.is_obstacle_at(point) {
            return Err(PlanError::InvalidOption {
                name,
                reason: format!(
                    "({}, {}) lies on an obstacle (a nodata cell of the source)",
                    point[0], point[1]
                ),
            });
        }
    }
    if !(placement.goal_radius.is_finite() && placement.goal_radius >= 0.0) {
        return Err(PlanError::InvalidOption {
            name: "goal radius",
            reason: format!("must be finite and >= 0, got {}", placement.goal_radius),
        });
    }
    if !placement.start_yaw.is_finite() {
        return Err(PlanError::InvalidOption {
            name: "start yaw",
            reason: format!("must be finite, got {}", placement.start_yaw),
        });
    }
    Ok(MapScenario {
        name: placement.name.clone(),
        seed: None,
        map,
        start,
        start_yaw: placement.start_yaw,
        goal: GoalRegion {
            center: goal,
            radius: placement.goal_radius,
        },
        traversability: TraversabilityParams::default(),
        prior: None,
    })
}

/// `N` comma-separated finite numbers ("1.5,-2"), as command-line flags give points and windows.
pub fn numbers<const N: usize>(text: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!(
            "{text:?}: expected {N} comma-separated numbers, got {}",
            parts.len()
        ));
    }
    let mut out = [0.0; N];
    for (slot, part) in out.iter_mut().zip(parts) {
        *slot = part
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("{text:?}: {part:?} is not a finite number"))?;
    }
    Ok(out)
}

/// `N` comma-separated whole numbers ("0,10,64,80"), as flags give cell windows and sizes.
pub fn counts<const N: usize>(text: &str) -> Result<[usize; N], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let values: Vec<usize> = parts
        .iter()
        .map(|part| {
            part.parse::<usize>()
                .map_err(|_| format!("{text:?}: {part:?} is not a whole number >= 0"))
        })
        .collect::<Result<_, _>>()?;
    values.try_into().map_err(|v: Vec<usize>| {
        format!(
            "{text:?}: expected {N} comma-separated whole numbers, got {}",
            v.len()
        )
    })
}

/// A positive factor written as a number ("0.02") or a fraction ("1/50").
pub fn factor(text: &str) -> Result<f64, String> {
    let value = match text.split_once('/') {
        Some((a, b)) => {
            let [a, b] = [a, b].map(|t| t.trim().parse::<f64>().ok());
            a.zip(b).map(|(a, b)| a / b)
        }
        None => text.trim().parse::<f64>().ok(),
    };
    value
        .filter(|v| v.is_finite() && *v > 0.0)
        .ok_or_else(|| format!("{text:?} is not a finite factor > 0 (e.g. 0.02 or 1/50)"))
}

/// A scenario name from a file's stem: characters other than letters, digits, '_' and '-'
/// become '_' (the names `save_scenario` accepts).
pub fn stem_name(path: &Path) -> String {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if name.is_empty() {
        "terrain".into()
    } else {
        name
    }
}

#[cfg(test)]
mod tests;
