//! A north-up elevation raster in the source's horizontal units, and the crop window read from it.

use std::path::Path;

use crate::error::PlanError;
use crate::io::format_error;
use crate::map::Point;

/// Where a raster lies: cell counts, lower-left corner and cell sizes in the source's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RasterGeometry {
    /// Cells from west to east.
    pub columns: usize,
    /// Cells from north to south (file order) or south to north (memory order): the same count.
    pub rows: usize,
    /// x of the raster's west edge.
    pub west: f64,
    /// y of the raster's south edge.
    pub south: f64,
    /// Cell width along x.
    pub dx: f64,
    /// Cell height along y.
    pub dy: f64,
}

impl RasterGeometry {
    /// Width and height of the raster, source units.
    pub fn extent(&self) -> (f64, f64) {
        (self.columns as f64 * self.dx, self.rows as f64 * self.dy)
    }

    /// The geometry of `window` of this raster.
    pub fn of_window(&self, window: &CellWindow) -> RasterGeometry {
        let south_row = window.row0 + window.rows; // file rows count from the north
        RasterGeometry {
            columns: window.columns,
            rows: window.rows,
            west: self.west + window.column0 as f64 * self.dx,
            south: self.south + (self.rows - south_row) as f64 * self.dy,
            dx: self.dx,
            dy: self.dy,
        }
    }

    /// Checks what a header must give: cells, finite corner, positive finite cell sizes.
    pub fn validate(&self, path: &Path) -> Result<(), PlanError> {
        let bad = |reason: String| format_error(path, reason);
        if self.columns == 0 || self.rows == 0 {
            return Err(bad(format!(
                "raster of {} x {} cells is empty",
                self.columns, self.rows
            )));
        }
        for (name, value) in [("dx (cell width)", self.dx), ("dy (cell height)", self.dy)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(bad(format!(
                    "cell size {name} = {value}: must be finite and > 0"
                )));
            }
        }
        if !(self.west.is_finite() && self.south.is_finite()) {
            return Err(bad(format!(
                "lower-left corner ({}, {}) is not finite",
                self.west, self.south
            )));
        }
        let (w, h) = self.extent();
        if !(w.is_finite() && h.is_finite()) {
            return Err(bad("the raster's extent overflows".into()));
        }
        Ok(())
    }
}

/// A crop of the source raster.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Crop {
    /// Keep the cells whose centres lie in `[min.x, max.x] × [min.y, max.y]`, source coordinates.
    World { min: Point, max: Point },
    /// Keep columns `column0..column1` and rows `row0..row1` (ends exclusive) as stored in the
    /// file: column 0 is the westernmost, row 0 the northernmost (the file's first row).
    Cells {
        column0: usize,
        row0: usize,
        column1: usize,
        row1: usize,
    },
}

/// A rectangle of source cells in file order (row 0 = north).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellWindow {
    pub column0: usize,
    pub row0: usize,
    pub columns: usize,
    pub rows: usize,
}

impl CellWindow {
    /// The whole raster.
    pub fn full(geometry: &RasterGeometry) -> Self {
        Self {
            column0: 0,
            row0: 0,
            columns: geometry.columns,
            rows: geometry.rows,
        }
    }

    /// Cells in the window.
    pub fn cells(&self) -> usize {
        self.columns * self.rows
    }

    /// The window of `crop` (the whole raster without one), refused when empty, outside the
    /// raster or larger than `max_cells`: checked before any cell is stored.
    pub fn resolve(
        geometry: &RasterGeometry,
        crop: Option<&Crop>,
        max_cells: usize,
        path: &Path,
    ) -> Result<Self, PlanError> {
        let window = match crop {
            None => Self::full(geometry),
            Some(&Crop::Cells {
                column0,
                row0,
                column1,
                row1,
            }) => {
                if column0 >= column1
                    || row0 >= row1
                    || column1 > geometry.columns
                    || row1 > geometry.rows
                {
                    return Err(PlanError::InvalidOption {
                        name: "crop (cells)",
                        reason: format!(
                            "columns {column0}..{column1}, rows {row0}..{row1} is empty or leaves \
                             the raster of {} x {} cells in {}",
                            geometry.columns,
                            geometry.rows,
                            path.display()
                        ),
                    });
                }
                Self {
                    column0,
                    row0,
                    columns: column1 - column0,
                    rows: row1 - row0,
                }
            }
            Some(&Crop::World { min, max }) => world_window(geometry, min, max, path)?,
        };
        let too_large = window
            .columns
            .checked_mul(window.rows)
            .map_or(true, |n| n > max_cells);
        if too_large {
            return Err(format_error(
                path,
                format!(
                    "{} x {} cells to read exceed the limit of {max_cells} cells (crop the raster \
                     with --crop or raise --max-cells)",
                    window.columns, window.rows
                ),
            ));
        }
        Ok(window)
    }
}

/// The cells whose centres lie in the closed rectangle `[min, max]`.
fn world_window(
    geometry: &RasterGeometry,
    min: Point,
    max: Point,
    path: &Path,
) -> Result<CellWindow, PlanError> {
    let finite = min.iter().chain(&max).all(|v| v.is_finite());
    if !finite || min[0] >= max[0] || min[1] >= max[1] {
        return Err(PlanError::InvalidOption {
            name: "crop",
            reason: format!(
                "({}, {})..({}, {}) must be finite with X0 < X1 and Y0 < Y1",
                min[0], min[1], max[0], max[1]
            ),
        });
    }
    // Centre of column c: west + (c + ½)·dx; the first and last columns whose centre is inside.
    let first = |lo: f64, origin: f64, step: f64| ((lo - origin) / step - 0.5).ceil().max(0.0);
    let last = |hi: f64, origin: f64, step: f64, count: usize| {
        ((hi - origin) / step - 0.5).floor().min(count as f64 - 1.0)
    };
    let (c0, c1) = (
        first(min[0], geometry.west, geometry.dx),
        last(max[0], geometry.west, geometry.dx, geometry.columns),
    );
    let (s0, s1) = (
        first(min[1], geometry.south, geometry.dy),
        last(max[1], geometry.south, geometry.dy, geometry.rows),
    );
    if c0 > c1 || s0 > s1 {
        let (w, h) = geometry.extent();
        return Err(PlanError::InvalidOption {
            name: "crop",
            reason: format!(
                "({}, {})..({}, {}) holds no cell centre of {}, which spans x {}..{}, y {}..{}",
                min[0],
                min[1],
                max[0],
                max[1],
                path.display(),
                geometry.west,
                geometry.west + w,
                geometry.south,
                geometry.south + h
            ),
        });
    }
    // Rows counted from the south (s0..=s1) become file rows counted from the north.
    let (c0, c1, s0, s1) = (c0 as usize, c1 as usize, s0 as usize, s1 as usize);
    Ok(CellWindow {
        column0: c0,
        row0: geometry.rows - 1 - s1,
        columns: c1 - c0 + 1,
        rows: s1 - s0 + 1,
    })
}

/// Elevations of a window, in memory in the map's order: row-major, row 0 = south.
#[derive(Debug, Clone, PartialEq)]
pub struct Raster {
    pub geometry: RasterGeometry,
    /// `values[iy · columns + ix]`, iy = 0 the southernmost row; NaN marks nodata.
    pub values: Vec<f64>,
}

/// Collects a window's values while the reader walks the file in its order (north row first).
pub(crate) struct WindowSink {
    window: CellWindow,
    values: Vec<f64>,
}

impl WindowSink {
    /// Allocates the window (its size was checked by [`CellWindow::resolve`]).
    pub(crate) fn new(window: CellWindow) -> Self {
        Self {
            window,
            values: vec![f64::NAN; window.cells()],
        }
    }

    /// Stores the value of file cell (`column`, `row`) if it lies in the window.
    #[inline]
    pub(crate) fn put(&mut self, column: usize, row: usize, value: f64) {
        let w = &self.window;
        let inside = column >= w.column0
            && column < w.column0 + w.columns
            && row >= w.row0
            && row < w.row0 + w.rows;
        if inside {
            let iy = w.row0 + w.rows - 1 - row;
            self.values[iy * w.columns + (column - w.column0)] = value;
        }
    }

    /// File rows `row0..row0 + rows` the window needs.
    pub(crate) fn rows(&self) -> std::ops::Range<usize> {
        self.window.row0..self.window.row0 + self.window.rows
    }

    /// File columns the window needs.
    pub(crate) fn columns(&self) -> std::ops::Range<usize> {
        self.window.column0..self.window.column0 + self.window.columns
    }

    pub(crate) fn finish(self, source: &RasterGeometry) -> Raster {
        Raster {
            geometry: source.of_window(&self.window),
            values: self.values,
        }
    }
}

/// Largest magnitude accepted as an elevation: beyond it the value is an undeclared nodata
/// marker (e.g. -3.4e38, the float minimum GDAL uses) rather than terrain.
pub const MAX_ABS_ELEVATION: f64 = 1e7;

/// The elevation of a cell's raw value: NaN for nodata, an error for non-finite or implausible
/// values. `item` names the cell in the error ("row 3, column 7").
pub(crate) fn elevation(
    value: f64,
    nodata: Option<f64>,
    path: &Path,
    item: impl FnOnce() -> String,
) -> Result<f64, PlanError> {
    let is_nodata = nodata.is_some_and(|nd| nd == value || (nd.is_nan() && value.is_nan()));
    if is_nodata {
        return Ok(f64::NAN);
    }
    if !value.is_finite() {
        return Err(format_error(
            path,
            format!(
                "{}: value {value} is not finite and is not the nodata value {}",
                item(),
                describe_nodata(nodata)
            ),
        ));
    }
    if value.abs() > MAX_ABS_ELEVATION {
        return Err(format_error(
            path,
            format!(
                "{}: value {value} is no elevation (|h| > {MAX_ABS_ELEVATION:e}); the nodata value \
                 is {} — is this an undeclared nodata marker?",
                item(),
                describe_nodata(nodata)
            ),
        ));
    }
    Ok(value)
}

fn describe_nodata(nodata: Option<f64>) -> String {
    nodata.map_or_else(|| "not declared".into(), |v| v.to_string())
}
