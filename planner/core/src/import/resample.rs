//! Bilinear resampling of elevations between cell centres, and filling nodata cells.

use std::collections::VecDeque;

use super::raster::{Raster, RasterGeometry};
use crate::error::PlanError;

/// The raster on square cells of `cell` (source units) covering its extent from the south-west
/// corner; a strip narrower than one cell at the east and north edges is dropped. Each new cell
/// is the bilinear interpolation of the four source cell centres around its centre (clamped at
/// the edges, as [`crate::map::GridMap::height_at`]); a cell whose interpolation touches a
/// nodata cell with non-zero weight is nodata. Refuses more than `max_cells` cells before
/// allocating them.
pub fn resample(raster: &Raster, cell: f64, max_cells: usize) -> Result<Raster, PlanError> {
    let g = &raster.geometry;
    if !(cell.is_finite() && cell > 0.0) {
        return Err(PlanError::InvalidOption {
            name: "target cell size",
            reason: format!("{cell} (source units) must be finite and > 0"),
        });
    }
    let (width, height) = g.extent();
    // The tolerance keeps an exact multiple (e.g. 10 m / 0.1 m) from losing a cell to rounding.
    let count = |extent: f64| (extent / cell * (1.0 + 1e-9)).floor();
    let (nx, ny) = (count(width), count(height));
    if nx < 1.0 || ny < 1.0 {
        return Err(PlanError::InvalidOption {
            name: "target cell size",
            reason: format!(
                "cells of {cell} (source units) do not fit the {width} x {height} window"
            ),
        });
    }
    if nx * ny > max_cells as f64 {
        return Err(PlanError::InvalidOption {
            name: "target cell size",
            reason: format!(
                "{nx} x {ny} cells of {cell} exceed the limit of {max_cells} cells (raise \
                 --max-cells or choose larger cells)"
            ),
        });
    }
    let (nx, ny) = (nx as usize, ny as usize);
    let source = |ix: usize, iy: usize| raster.values[iy * g.columns + ix];
    // Fractional source index of a new cell's centre, and the two source cells either side.
    let axis = |i: usize, step: f64, count: usize| {
        let f = (((i as f64 + 0.5) * cell) / step - 0.5).clamp(0.0, (count - 1) as f64);
        let lo = f.floor() as usize;
        // Rounding must not give a nodata neighbour a weight of 1e-16 at a coinciding centre.
        let t = match f - lo as f64 {
            t if t < 1e-9 => 0.0,
            t if t > 1.0 - 1e-9 => 1.0,
            t => t,
        };
        (lo, (lo + 1).min(count - 1), t)
    };
    let xs: Vec<_> = (0..nx).map(|i| axis(i, g.dx, g.columns)).collect();
    let mut values = Vec::with_capacity(nx * ny);
    for iy in 0..ny {
        let (y0, y1, ty) = axis(iy, g.dy, g.rows);
        for &(x0, x1, tx) in &xs {
            let corners = [
                (x0, y0, (1.0 - tx) * (1.0 - ty)),
                (x1, y0, tx * (1.0 - ty)),
                (x0, y1, (1.0 - tx) * ty),
                (x1, y1, tx * ty),
            ];
            let mut sum = 0.0;
            for (x, y, weight) in corners {
                if weight > 0.0 {
                    sum += weight * source(x, y);
                }
            }
            values.push(sum); // NaN (nodata) propagates through the sum
        }
    }
    Ok(Raster {
        geometry: RasterGeometry {
            columns: nx,
            rows: ny,
            west: g.west,
            south: g.south,
            dx: cell,
            dy: cell,
        },
        values,
    })
}

/// Replaces every NaN (nodata) by the height of the nearest valid cell in 4-neighbour steps
/// (breadth-first from all valid cells at once; ties go to the first cell reached) and returns
/// the nodata mask. `None` when no cell is valid.
pub fn fill_nodata(values: &mut [f64], columns: usize) -> Option<Vec<bool>> {
    let rows = values.len() / columns.max(1);
    let nodata: Vec<bool> = values.iter().map(|v| v.is_nan()).collect();
    let mut queue: VecDeque<usize> = (0..values.len()).filter(|&i| !nodata[i]).collect();
    if queue.is_empty() {
        return None;
    }
    let mut filled: Vec<bool> = nodata.iter().map(|&n| !n).collect();
    while let Some(i) = queue.pop_front() {
        let (x, y) = (i % columns, i / columns);
        let neighbours = [
            (x > 0).then(|| i - 1),
            (x + 1 < columns).then(|| i + 1),
            (y > 0).then(|| i - columns),
            (y + 1 < rows).then(|| i + columns),
        ];
        for j in neighbours.into_iter().flatten() {
            if !filled[j] {
                filled[j] = true;
                values[j] = values[i];
                queue.push_back(j);
            }
        }
    }
    Some(nodata)
}
