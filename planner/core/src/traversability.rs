//! Traversability p(x) ∈ [p_floor, 1]: the cost density every planner integrates (∫ p ds).
//!
//! The paper's choice is p = h / h_max (low ground is cheap, mountains are expensive). Optional
//! slope and roughness terms are blended in with non-negative weights:
//!
//! ```text
//! p = clamp( (w_h · h/h_max + w_s · min(slope/slope_ref, 1) + w_r · min(rough/rough_ref, 1))
//!            / (w_h + w_s + w_r),  p_floor, 1 )
//! ```
//!
//! - `h` is the cell height (must be ≥ 0), `h_max` the map's highest cell unless overridden;
//! - `slope` is the terrain inclination from central differences of the heights, in degrees;
//! - `rough` is the RMS deviation of the 3×3 neighbourhood from its mean, metres;
//! - `p_floor > 0` keeps the density-space LP well posed (where p = 0 speed and density are
//!   undetermined) and keeps graph edge weights positive.
//!
//! Defaults (`w_h = 1`, `w_s = w_r = 0`) give exactly the paper's p = h/h_max (floored).
//!
//! **Robot footprint** (`footprint_radius_m`, default 0 = the paper's point robot): the planners
//! move a particle, but a legged robot stands on feet up to ~0.25 m from its centre. With a
//! radius r > 0 each cell's p becomes the largest p of the cells whose centres lie within r
//! (a disc max filter, the configuration-space cost): a path along the foot of a steep flank
//! then keeps about r away from it instead of putting the uphill feet on the flank. Hard
//! obstacle cells count as p = 1 within the footprint (a foot in a pit is the worst case), so
//! paths also keep r off pit rims where there is room; the obstacle constraint is unchanged.
//! Cells beyond the map edge count as p = 1 too: the ground (known or simulated) ends there.
//!
//! **Walkable slope** (`max_slope_deg`, default none = the paper's model): p is a cost, and a
//! cost alone never forbids anything — a ridge whose flanks no legged robot can climb is merely
//! expensive, and with part of the map unknown (priced at the prior p) crossing it can look
//! cheaper than going around. With a limit set, [`block_steep_cells`] turns every known cell
//! steeper than it into a hard obstacle before planning.
//!
//! **Uncertain heights** (`height_confidence_sigmas` κ > 0 and a map whose
//! [`MapKnowledge`] carries height variances): a mapped height is an estimate, so a known cell
//! is priced from its confidence bounds. The height term uses h + κσ (an uncertain cell costs
//! more); the slope term uses the upper bound of the slope, each central difference widened by
//! κ times its σ. The walkable-slope limit keeps the mapped slope: a lower bound would unblock
//! exactly the steep cells, whose returns spread and whose measurements disagree most (a sensed
//! C ridge lost the tip of its flank that way, and the robot was sent up it). Without variances,
//! or with κ = 0, every bound is the mapped value itself (the model above, bit for bit).
//!
//! **Fitted slope** (`slope_fit_radius_m` r ≥ one cell; default 0 = central differences): the
//! slope of a known cell is that of the plane fitted by least squares to the known heights within
//! r, each weighted by its inverse variance (floored at 1 mm²), and its σ comes from the fit's
//! covariance. A single wrong height that the map itself holds uncertain then tilts nothing,
//! where central differences made its four neighbours steep (and, with the walkable-slope limit,
//! obstacles a robot detoured around); a flank measured alike throughout keeps its slope. Cells
//! whose known neighbours are fewer than three or collinear fall back to central differences.

use std::borrow::Cow;

use serde::{Deserialize, Serialize};

use crate::error::{MapError, PlanError};
use crate::map::{GridMap, MapKnowledge, Point};

/// Weights and references of the traversability model (see the module docs for the formula).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TraversabilityParams {
    /// Weight of the paper's height term h/h_max.
    pub height_weight: f64,
    /// Weight of the slope term min(slope/slope_ref, 1).
    pub slope_weight: f64,
    /// Weight of the roughness term min(rough/rough_ref, 1).
    pub roughness_weight: f64,
    /// Slope (degrees) at which the slope term saturates at 1.
    pub slope_ref_deg: f64,
    /// Roughness (metres, RMS of the 3×3 neighbourhood) at which the roughness term saturates at 1.
    pub roughness_ref_m: f64,
    /// Lower bound of p; must lie in (0, 1].
    pub p_floor: f64,
    /// Height that maps to p = 1; `None` uses the highest cell of the map.
    pub h_max: Option<f64>,
    /// Radius of the robot's footprint, metres: p of a cell is the largest p within this radius
    /// (0 = the paper's point robot).
    pub footprint_radius_m: f64,
    /// Steepest walkable slope, degrees: known cells steeper than this are hard obstacles
    /// (`None`: no limit, the paper's model).
    pub max_slope_deg: Option<f64>,
    /// κ of the heights' confidence bounds (module docs); 0 prices the mapped heights themselves.
    /// Acts only on maps whose knowledge carries height variances.
    pub height_confidence_sigmas: f64,
    /// Radius, metres, of the plane fitted to the known heights around each cell for its slope
    /// (weighted by the heights' inverse variances; module docs). 0 (default) or a radius under
    /// one cell: central differences.
    pub slope_fit_radius_m: f64,
}

/// Largest footprint radius in cells; bounds the filter's cost (cells × (2R + 1)).
pub const MAX_FOOTPRINT_CELLS: usize = 64;
/// Largest slope-fit radius in cells; bounds the fit's cost (cells × (2R + 1)²).
pub const MAX_SLOPE_FIT_CELLS: usize = 8;
/// Variance floor of a height in the slope fit, m² (1 mm): exact heights weigh alike.
const MIN_FIT_VARIANCE: f64 = 1e-6;

impl Default for TraversabilityParams {
    fn default() -> Self {
        Self {
            height_weight: 1.0,
            slope_weight: 0.0,
            roughness_weight: 0.0,
            slope_ref_deg: 30.0,
            roughness_ref_m: 0.1,
            p_floor: 0.05,
            h_max: None,
            footprint_radius_m: 0.0,
            max_slope_deg: None,
            height_confidence_sigmas: 0.0,
            slope_fit_radius_m: 0.0,
        }
    }
}

impl TraversabilityParams {
    /// Rejects weights and references that would make p undefined or outside [p_floor, 1].
    pub fn validate(&self) -> Result<(), PlanError> {
        let bad =
            |name: &'static str, reason: String| Err(PlanError::InvalidOption { name, reason });
        for (name, w) in [
            ("traversability.height_weight", self.height_weight),
            ("traversability.slope_weight", self.slope_weight),
            ("traversability.roughness_weight", self.roughness_weight),
        ] {
            if !(w.is_finite() && w >= 0.0) {
                return bad(name, format!("must be finite and >= 0, got {w}"));
            }
        }
        if self.height_weight + self.slope_weight + self.roughness_weight <= 0.0 {
            return bad(
                "traversability weights",
                "at least one weight must be positive".into(),
            );
        }
        if !(self.slope_ref_deg.is_finite()
            && self.slope_ref_deg > 0.0
            && self.slope_ref_deg < 90.0)
        {
            return bad(
                "traversability.slope_ref_deg",
                format!("must lie in (0, 90), got {}", self.slope_ref_deg),
            );
        }
        if !(self.roughness_ref_m.is_finite() && self.roughness_ref_m > 0.0) {
            return bad(
                "traversability.roughness_ref_m",
                format!("must be finite and > 0, got {}", self.roughness_ref_m),
            );
        }
        if !(self.p_floor.is_finite() && self.p_floor > 0.0 && self.p_floor <= 1.0) {
            return bad(
                "traversability.p_floor",
                format!("must lie in (0, 1], got {}", self.p_floor),
            );
        }
        if !(self.footprint_radius_m.is_finite() && self.footprint_radius_m >= 0.0) {
            return bad(
                "traversability.footprint_radius_m",
                format!("must be finite and >= 0, got {}", self.footprint_radius_m),
            );
        }
        if !(self.height_confidence_sigmas.is_finite() && self.height_confidence_sigmas >= 0.0) {
            return bad(
                "traversability.height_confidence_sigmas",
                format!(
                    "must be finite and >= 0, got {}",
                    self.height_confidence_sigmas
                ),
            );
        }
        if !(self.slope_fit_radius_m.is_finite() && self.slope_fit_radius_m >= 0.0) {
            return bad(
                "traversability.slope_fit_radius_m",
                format!("must be finite and >= 0, got {}", self.slope_fit_radius_m),
            );
        }
        if let Some(limit) = self.max_slope_deg {
            if !(limit.is_finite() && limit > 0.0 && limit < 90.0) {
                return bad(
                    "traversability.max_slope_deg",
                    format!("must lie in (0, 90), got {limit}"),
                );
            }
        }
        if let Some(h) = self.h_max {
            if !(h.is_finite() && h > 0.0) {
                return bad(
                    "traversability.h_max",
                    format!("must be finite and > 0, got {h}"),
                );
            }
        }
        Ok(())
    }
}

/// p at every cell centre of a map, with bilinear interpolation in between: the continuous
/// field that [`crate::metrics`] integrates for every method alike.
#[derive(Debug, Clone, PartialEq)]
pub struct TraversabilityField {
    /// Lower-left corner of cell (0, 0), as in the map.
    pub origin: Point,
    /// Cell size of the map, metres.
    pub resolution: f64,
    /// Cells along x.
    pub width: usize,
    /// Cells along y.
    pub height: usize,
    /// p per map cell, row-major `iy · width + ix`, each in [p_floor, 1].
    pub values: Vec<f64>,
}

impl TraversabilityField {
    /// Evaluates the model on every cell of `map`.
    pub fn from_map(map: &GridMap, params: &TraversabilityParams) -> Result<Self, PlanError> {
        Self::from_partial_map(map, None, params)
    }

    /// Evaluates the model on a map of which only some cells were observed (`knowledge`; `None`:
    /// every cell). An unknown cell gets the prior p (`unknown_traversability`, raised to
    /// `p_floor` if below); its height and obstacle flag are ignored. h_max (unless given),
    /// slopes and roughness are taken over known cells only, so the unseen part of the map
    /// neither rescales nor roughens the seen part. The footprint filter is unchanged: it
    /// spreads the largest p within its radius, unknown cells included.
    pub fn from_partial_map(
        map: &GridMap,
        knowledge: Option<&MapKnowledge>,
        params: &TraversabilityParams,
    ) -> Result<Self, PlanError> {
        map.validate()?;
        params.validate()?;
        let known = knowledge.map(MapKnowledge::known);
        if let Some(mask) = known {
            if mask.len() != map.len() {
                return Err(MapError::LengthMismatch {
                    what: "known_mask",
                    expected: map.len(),
                    actual: mask.len(),
                }
                .into());
            }
        }
        let is_known = |i: usize| known.map_or(true, |m| m[i]);
        if let Some(i) = (0..map.len()).find(|&i| is_known(i) && map.heights[i] < 0.0) {
            return Err(MapError::NegativeHeight {
                ix: i % map.width,
                iy: i / map.width,
                value: map.heights[i],
            }
            .into());
        }
        let observed_max = (0..map.len())
            .filter(|&i| is_known(i))
            .map(|i| map.heights[i])
            .fold(0.0_f64, f64::max);
        let h_max = params.h_max.unwrap_or(observed_max);
        let weight_sum = params.height_weight + params.slope_weight + params.roughness_weight;
        let fit = PlaneFitWindow::new(params.slope_fit_radius_m, map.resolution)?;
        let mut values = Vec::with_capacity(map.len());
        for iy in 0..map.height {
            for ix in 0..map.width {
                let index = map.index(ix, iy);
                if let Some(knowledge) = knowledge.filter(|k| !k.is_known(index)) {
                    values.push(
                        knowledge
                            .unknown_traversability()
                            .clamp(params.p_floor, 1.0),
                    );
                    continue;
                }
                let kappa_sigma = params.height_confidence_sigmas
                    * knowledge.map_or(0.0, |k| k.height_sigma(index));
                let h = map.heights[index] + kappa_sigma;
                let height_term = if h_max > 0.0 {
                    (h / h_max).min(1.0)
                } else {
                    0.0
                };
                let slope_term = if params.slope_weight > 0.0 {
                    (gradient_at(map, knowledge, fit.as_ref(), ix, iy)
                        .slope_deg(params.height_confidence_sigmas)
                        / params.slope_ref_deg)
                        .min(1.0)
                } else {
                    0.0
                };
                let rough_term = if params.roughness_weight > 0.0 {
                    (roughness_over(map, known, ix, iy) / params.roughness_ref_m).min(1.0)
                } else {
                    0.0
                };
                let p = (params.height_weight * height_term
                    + params.slope_weight * slope_term
                    + params.roughness_weight * rough_term)
                    / weight_sum;
                values.push(p.clamp(params.p_floor, 1.0));
            }
        }
        // Obstacle flags of unknown cells mean nothing (nothing was seen there).
        let obstacles: Option<Vec<bool>> = map.obstacles.as_ref().map(|mask| {
            mask.iter()
                .enumerate()
                .map(|(i, &blocked)| blocked && is_known(i))
                .collect()
        });
        let values = if params.footprint_radius_m > 0.0 {
            let radius_cells = params.footprint_radius_m / map.resolution;
            if radius_cells > MAX_FOOTPRINT_CELLS as f64 {
                return Err(PlanError::InvalidOption {
                    name: "traversability.footprint_radius_m",
                    reason: format!(
                        "{} m is {radius_cells:.0} cells of {} m; at most {MAX_FOOTPRINT_CELLS} \
                         cells are supported",
                        params.footprint_radius_m, map.resolution
                    ),
                });
            }
            // A foot in a hard obstacle (a pit) is as bad as it gets: obstacle cells count as
            // p = 1 within the footprint, so paths keep r off pit rims where there is room
            // (the obstacle constraint itself is unchanged).
            let mut worst = values.clone();
            if let Some(mask) = &obstacles {
                for (p, &blocked) in worst.iter_mut().zip(mask) {
                    if blocked {
                        *p = 1.0;
                    }
                }
            }
            let dilated = footprint_max(&worst, map.width, map.height, radius_cells);
            // Obstacle cells keep their own p (they are never entered anyway).
            match &obstacles {
                Some(mask) => dilated
                    .iter()
                    .zip(mask)
                    .zip(&values)
                    .map(|((&d, &blocked), &own)| if blocked { own } else { d })
                    .collect(),
                None => dilated,
            }
        } else {
            values
        };
        Ok(Self {
            origin: map.origin,
            resolution: map.resolution,
            width: map.width,
            height: map.height,
            values,
        })
    }

    /// p of the cell containing `p`, clamped to the nearest edge cell outside the map.
    pub fn cell_value_at(&self, p: Point) -> f64 {
        let ix = (((p[0] - self.origin[0]) / self.resolution).floor().max(0.0) as usize)
            .min(self.width - 1);
        let iy = (((p[1] - self.origin[1]) / self.resolution).floor().max(0.0) as usize)
            .min(self.height - 1);
        self.values[iy * self.width + ix]
    }

    /// p at `p` by bilinear interpolation between cell centres, clamped at the map edge.
    pub fn at(&self, p: Point) -> f64 {
        let fx =
            ((p[0] - self.origin[0]) / self.resolution - 0.5).clamp(0.0, (self.width - 1) as f64);
        let fy =
            ((p[1] - self.origin[1]) / self.resolution - 0.5).clamp(0.0, (self.height - 1) as f64);
        // NaN coordinates clamp to NaN; fall back to the lower-left cell rather than index garbage.
        let (fx, fy) = (
            if fx.is_nan() { 0.0 } else { fx },
            if fy.is_nan() { 0.0 } else { fy },
        );
        let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
        let v = |ix: usize, iy: usize| self.values[iy * self.width + ix];
        let bottom = v(x0, y0) * (1.0 - tx) + v(x1, y0) * tx;
        let top = v(x0, y1) * (1.0 - tx) + v(x1, y1) * tx;
        bottom * (1.0 - ty) + top * ty
    }
}

/// Largest value within `radius_cells` of each cell centre, where cells beyond the map edge
/// count as p = 1: nothing is known there, and on a real terrain tile or a simulated world the
/// ground ends at the edge, so a foot there is the worst case and paths keep the footprint on
/// the map where there is room.
fn footprint_max(values: &[f64], width: usize, height: usize, radius_cells: f64) -> Vec<f64> {
    let pad = (radius_cells + 1e-9).floor() as usize;
    if pad == 0 {
        return disc_max_filter(values, width, height, radius_cells);
    }
    let (padded_width, padded_height) = (width + 2 * pad, height + 2 * pad);
    let mut padded = vec![1.0; padded_width * padded_height];
    for (row, source) in values.chunks_exact(width).enumerate() {
        let start = (row + pad) * padded_width + pad;
        padded[start..start + width].copy_from_slice(source);
    }
    let dilated = disc_max_filter(&padded, padded_width, padded_height, radius_cells);
    (0..height)
        .flat_map(|row| {
            let start = (row + pad) * padded_width + pad;
            dilated[start..start + width].iter().copied()
        })
        .collect()
}

/// Largest value among the cells whose centres lie within `radius_cells` (cell units) of each
/// cell centre, inside the grid. Row by row: every row offset dy of the disc contributes a window
/// of half-width ⌊√(r² − dy²)⌋ on row iy + dy, whose maximum a monotone deque gives in one pass.
fn disc_max_filter(values: &[f64], width: usize, height: usize, radius_cells: f64) -> Vec<f64> {
    // A centre exactly on the circle counts as inside despite rounding of radius / resolution.
    let r2 = radius_cells * radius_cells + 1e-9;
    let reach = r2.sqrt().floor() as usize;
    let mut out = values.to_vec();
    let mut window: std::collections::VecDeque<usize> = std::collections::VecDeque::new();
    for dy in 0..=reach {
        let half = (r2 - (dy * dy) as f64).sqrt().floor() as usize;
        for iy in 0..height {
            let rows = if dy == 0 {
                [Some(iy), None]
            } else {
                [iy.checked_sub(dy), Some(iy + dy).filter(|&r| r < height)]
            };
            for source_row in rows.into_iter().flatten() {
                let row = &values[source_row * width..(source_row + 1) * width];
                window.clear();
                let mut next = 0;
                for ix in 0..width {
                    // Admit cells up to ix + half, drop those left of ix − half.
                    while next < width && next <= ix + half {
                        while window.back().is_some_and(|&j| row[j] <= row[next]) {
                            window.pop_back();
                        }
                        window.push_back(next);
                        next += 1;
                    }
                    while window.front().is_some_and(|&j| j + half < ix) {
                        window.pop_front();
                    }
                    if let Some(&j) = window.front() {
                        let cell = &mut out[iy * width + ix];
                        *cell = cell.max(row[j]);
                    }
                }
            }
        }
    }
    out
}

/// The map the planners plan on: with `params.max_slope_deg`, every known cell steeper than the
/// limit is added to the hard obstacles (unknown cells are never blocked: nothing was seen there).
/// Without a limit, or when no cell is too steep, the map itself.
pub fn block_steep_cells<'a>(
    map: &'a GridMap,
    knowledge: Option<&MapKnowledge>,
    params: &TraversabilityParams,
) -> Cow<'a, GridMap> {
    let Some(limit) = params.max_slope_deg else {
        return Cow::Borrowed(map);
    };
    let is_known = |i: usize| knowledge.map_or(true, |k| k.is_known(i));
    // An invalid radius is reported by the traversability field built from the same params.
    let fit = PlaneFitWindow::new(params.slope_fit_radius_m, map.resolution)
        .ok()
        .flatten();
    let steep: Vec<usize> = (0..map.len())
        .filter(|&i| {
            is_known(i)
                && !map.obstacles.as_ref().is_some_and(|mask| mask[i])
                && gradient_at(map, knowledge, fit.as_ref(), i % map.width, i / map.width)
                    .slope_deg(0.0)
                    > limit
        })
        .collect();
    if steep.is_empty() {
        return Cow::Borrowed(map);
    }
    let mut blocked = map.clone();
    let mask = blocked
        .obstacles
        .get_or_insert_with(|| vec![false; map.len()]);
    for i in steep {
        mask[i] = true;
    }
    Cow::Owned(blocked)
}

/// Terrain inclination at a cell centre in degrees (central differences, one-sided at the edge).
pub fn slope_deg(map: &GridMap, ix: usize, iy: usize) -> f64 {
    gradient_over(map, None, ix, iy).slope_deg(0.0)
}

/// The height gradient at a cell centre from central differences, and the standard deviation
/// of each component from the heights' σ (0 without variances).
#[derive(Debug, Clone, Copy)]
struct Gradient {
    dx: f64,
    dy: f64,
    sigma_dx: f64,
    sigma_dy: f64,
}

impl Gradient {
    /// Slope in degrees with each component's magnitude widened by κσ (its upper bound).
    fn slope_deg(&self, kappa: f64) -> f64 {
        let widened = |d: f64, sigma: f64| d.abs() + kappa * sigma;
        widened(self.dx, self.sigma_dx)
            .hypot(widened(self.dy, self.sigma_dy))
            .atan()
            .to_degrees()
    }
}

/// The cell offsets within a slope-fit radius.
struct PlaneFitWindow {
    offsets: Vec<(isize, isize)>,
    resolution: f64,
}

impl PlaneFitWindow {
    /// `None` for a radius under one cell (central differences); an error beyond
    /// [`MAX_SLOPE_FIT_CELLS`].
    fn new(radius_m: f64, resolution: f64) -> Result<Option<Self>, PlanError> {
        let radius_cells = radius_m / resolution;
        if radius_cells > MAX_SLOPE_FIT_CELLS as f64 {
            return Err(PlanError::InvalidOption {
                name: "traversability.slope_fit_radius_m",
                reason: format!(
                    "{radius_m} m is {radius_cells:.0} cells of {resolution} m; at most \
                     {MAX_SLOPE_FIT_CELLS} cells are supported"
                ),
            });
        }
        if radius_cells < 1.0 {
            return Ok(None);
        }
        let reach = radius_cells.floor() as isize;
        let offsets = (-reach..=reach)
            .flat_map(|dy| (-reach..=reach).map(move |dx| (dx, dy)))
            .filter(|&(dx, dy)| ((dx * dx + dy * dy) as f64) <= radius_cells * radius_cells + 1e-9)
            .collect();
        Ok(Some(Self {
            offsets,
            resolution,
        }))
    }
}

/// [`Gradient`] of the plane fitted over `fit`'s window when given and determined, else from
/// central differences.
fn gradient_at(
    map: &GridMap,
    knowledge: Option<&MapKnowledge>,
    fit: Option<&PlaneFitWindow>,
    ix: usize,
    iy: usize,
) -> Gradient {
    fit.and_then(|window| fitted_gradient(map, knowledge, window, ix, iy))
        .unwrap_or_else(|| gradient_over(map, knowledge, ix, iy))
}

/// The plane z = c + gx·x + gy·y fitted by weighted least squares to the known heights within
/// the window around a cell, each weighted by its inverse variance (floored at
/// [`MIN_FIT_VARIANCE`]); the gradient's σ from the fit's covariance. A lone wrong height among
/// well-measured neighbours carries its own large variance and tilts the plane little; a
/// flank seen at a grazing angle, uncertain throughout, keeps its slope. `None` when fewer than
/// three known cells or only collinear ones are in the window.
fn fitted_gradient(
    map: &GridMap,
    knowledge: Option<&MapKnowledge>,
    window: &PlaneFitWindow,
    ix: usize,
    iy: usize,
) -> Option<Gradient> {
    let mut normal = nalgebra::Matrix3::<f64>::zeros();
    let mut rhs = nalgebra::Vector3::<f64>::zeros();
    let mut count = 0;
    for &(dx, dy) in &window.offsets {
        let (Some(x), Some(y)) = (ix.checked_add_signed(dx), iy.checked_add_signed(dy)) else {
            continue;
        };
        if x >= map.width || y >= map.height {
            continue;
        }
        let index = map.index(x, y);
        if !knowledge.map_or(true, |k| k.is_known(index)) {
            continue;
        }
        let variance = knowledge
            .map_or(0.0, |k| k.height_sigma(index).powi(2))
            .max(MIN_FIT_VARIANCE);
        let row = nalgebra::Vector3::new(
            1.0,
            dx as f64 * window.resolution,
            dy as f64 * window.resolution,
        );
        normal += row * row.transpose() / variance;
        rhs += row * (map.heights[index] / variance);
        count += 1;
    }
    // The cells' spread in x and y about their weighted mean (the Schur complement of the
    // normal matrix): collinear cells determine no plane.
    let spread =
        |r: usize, c: usize| normal[(r, c)] - normal[(r, 0)] * normal[(0, c)] / normal[(0, 0)];
    let (sxx, syy, sxy) = (spread(1, 1), spread(2, 2), spread(1, 2));
    if count < 3 || sxx * syy - sxy * sxy <= 1e-9 * (sxx + syy).powi(2) {
        return None;
    }
    let factor = normal.cholesky()?;
    let plane = factor.solve(&rhs);
    let covariance = factor.inverse();
    let gradient = Gradient {
        dx: plane[1],
        dy: plane[2],
        sigma_dx: covariance[(1, 1)].max(0.0).sqrt(),
        sigma_dy: covariance[(2, 2)].max(0.0).sqrt(),
    };
    [
        gradient.dx,
        gradient.dy,
        gradient.sigma_dx,
        gradient.sigma_dy,
    ]
    .iter()
    .all(|v| v.is_finite())
    .then_some(gradient)
}

/// [`Gradient`] from known cells only (`knowledge`: `None` = all known, no variances): an
/// unknown neighbour is replaced by the cell itself, so the difference turns one-sided.
fn gradient_over(
    map: &GridMap,
    knowledge: Option<&MapKnowledge>,
    ix: usize,
    iy: usize,
) -> Gradient {
    let usable = |x: usize, y: usize| knowledge.map_or(true, |k| k.is_known(map.index(x, y)));
    let h = |x: usize, y: usize| map.heights[map.index(x, y)];
    let sigma = |x: usize, y: usize| knowledge.map_or(0.0, |k| k.height_sigma(map.index(x, y)));
    // (derivative, its σ) of the difference from cell `lo` to cell `hi` along one axis.
    let derivative = |lo: usize, hi: usize, (hl, sl): (f64, f64), (hh, sh): (f64, f64)| {
        if hi > lo {
            let run = (hi - lo) as f64 * map.resolution;
            ((hh - hl) / run, sl.hypot(sh) / run)
        } else {
            (0.0, 0.0)
        }
    };
    let pick = |candidate: usize, own: usize, is_x: bool| {
        let ok = if is_x {
            usable(candidate, iy)
        } else {
            usable(ix, candidate)
        };
        if ok {
            candidate
        } else {
            own
        }
    };
    let xl = pick(ix.saturating_sub(1), ix, true);
    let xh = pick((ix + 1).min(map.width - 1), ix, true);
    let yl = pick(iy.saturating_sub(1), iy, false);
    let yh = pick((iy + 1).min(map.height - 1), iy, false);
    let at = |x: usize, y: usize| (h(x, y), sigma(x, y));
    let (dx, sigma_dx) = derivative(xl, xh, at(xl, iy), at(xh, iy));
    let (dy, sigma_dy) = derivative(yl, yh, at(ix, yl), at(ix, yh));
    Gradient {
        dx,
        dy,
        sigma_dx,
        sigma_dy,
    }
}

/// RMS deviation of the heights of the 3×3 neighbourhood (clipped at the edge) from their mean, metres.
pub fn roughness(map: &GridMap, ix: usize, iy: usize) -> f64 {
    roughness_over(map, None, ix, iy)
}

/// [`roughness`] over the known cells of the neighbourhood only (the cell itself is known).
fn roughness_over(map: &GridMap, known: Option<&[bool]>, ix: usize, iy: usize) -> f64 {
    let mut samples = Vec::with_capacity(9);
    for y in iy.saturating_sub(1)..=(iy + 1).min(map.height - 1) {
        for x in ix.saturating_sub(1)..=(ix + 1).min(map.width - 1) {
            let index = map.index(x, y);
            if known.map_or(true, |m| m[index]) {
                samples.push(map.heights[index]);
            }
        }
    }
    let n = samples.len().max(1) as f64;
    let mean = samples.iter().sum::<f64>() / n;
    (samples.iter().map(|h| (h - mean).powi(2)).sum::<f64>() / n).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(slope: f64) -> GridMap {
        let (w, h) = (5, 4);
        let heights = (0..w * h).map(|i| 1.0 + slope * (i % w) as f64).collect();
        GridMap::new([0.0, 0.0], 1.0, w, h, heights, None).expect("valid map")
    }

    #[test]
    fn default_is_height_over_max_height_with_floor() {
        let map = ramp(1.0);
        let f =
            TraversabilityField::from_map(&map, &TraversabilityParams::default()).expect("field");
        for ix in 0..5 {
            let expected = (1.0 + ix as f64) / 5.0;
            assert!((f.values[ix] - expected).abs() < 1e-12, "ix {ix}");
        }
        let flat_zero = GridMap::new([0.0, 0.0], 1.0, 2, 2, vec![0.0; 4], None).expect("map");
        let f = TraversabilityField::from_map(&flat_zero, &TraversabilityParams::default())
            .expect("field");
        assert!(f.values.iter().all(|&p| p == 0.05));
    }

    #[test]
    fn slope_term_measures_inclination() {
        // A 1:1 ramp is 45 degrees; with slope_ref 90-epsilon... use 60 degrees: term = 45/60.
        let map = ramp(1.0);
        assert!((slope_deg(&map, 2, 1) - 45.0).abs() < 1e-9);
        let params = TraversabilityParams {
            height_weight: 0.0,
            slope_weight: 1.0,
            slope_ref_deg: 60.0,
            ..Default::default()
        };
        let f = TraversabilityField::from_map(&map, &params).expect("field");
        assert!((f.values[2] - 0.75).abs() < 1e-9);
    }

    #[test]
    fn negative_heights_and_bad_weights_are_rejected() {
        let map = GridMap::new([0.0, 0.0], 1.0, 2, 1, vec![0.0, -0.5], None).expect("map");
        assert!(matches!(
            TraversabilityField::from_map(&map, &TraversabilityParams::default()),
            Err(PlanError::InvalidMap(MapError::NegativeHeight {
                ix: 1,
                iy: 0,
                ..
            }))
        ));
        let params = TraversabilityParams {
            p_floor: 0.0,
            ..Default::default()
        };
        assert!(matches!(
            TraversabilityField::from_map(&ramp(1.0), &params),
            Err(PlanError::InvalidOption { .. })
        ));
    }

    #[test]
    fn footprint_takes_the_largest_p_within_the_radius() {
        let (w, h) = (9, 7);
        let mut heights = vec![0.0; w * h];
        heights[3 * w + 4] = 1.0; // one high cell at (4, 3)
        heights[6 * w + 8] = 0.5; // and a lower one in the corner
        let map = GridMap::new([0.0, 0.0], 0.5, w, h, heights, None).expect("map");
        let point =
            TraversabilityField::from_map(&map, &TraversabilityParams::default()).expect("field");
        for radius in [0.0, 0.4, 0.5, 0.75, 1.0, 1.2, 2.0] {
            let params = TraversabilityParams {
                footprint_radius_m: radius,
                ..Default::default()
            };
            let f = TraversabilityField::from_map(&map, &params).expect("field");
            // Brute force: the max over all cells within the radius (centre distances), cells
            // beyond the edge at p = 1.
            let (wi, hi) = (w as i64, h as i64);
            for iy in 0..h {
                for ix in 0..w {
                    let mut expected: f64 = 0.0;
                    for sy in -hi..2 * hi {
                        for sx in -wi..2 * wi {
                            let d = (ix as f64 - sx as f64).hypot(iy as f64 - sy as f64) * 0.5;
                            if d > radius + 1e-12 {
                                continue;
                            }
                            let inside = (0..wi).contains(&sx) && (0..hi).contains(&sy);
                            let p = if inside {
                                point.values[(sy * wi + sx) as usize]
                            } else {
                                1.0
                            };
                            expected = expected.max(p);
                        }
                    }
                    assert_eq!(
                        f.values[iy * w + ix],
                        expected,
                        "r {radius} cell ({ix}, {iy})"
                    );
                }
            }
        }
    }

    #[test]
    fn footprint_counts_obstacle_cells_as_untraversable() {
        let (w, h) = (7, 5);
        let mut obstacles = vec![false; w * h];
        obstacles[2 * w + 3] = true; // a pit cell at (3, 2), as low as the rest
        let map =
            GridMap::new([0.0, 0.0], 1.0, w, h, vec![0.5; w * h], Some(obstacles)).expect("map");
        let params = TraversabilityParams {
            footprint_radius_m: 1.0,
            h_max: Some(1.0),
            ..Default::default()
        };
        let f = TraversabilityField::from_map(&map, &params).expect("field");
        for iy in 0..h {
            for ix in 0..w {
                let near = (ix as f64 - 3.0).hypot(iy as f64 - 2.0) <= 1.0 && (ix, iy) != (3, 2);
                let on_edge = ix == 0 || iy == 0 || ix == w - 1 || iy == h - 1;
                let expected = if near || on_edge { 1.0 } else { 0.5 };
                assert_eq!(f.values[iy * w + ix], expected, "cell ({ix}, {iy})");
            }
        }
    }

    #[test]
    fn footprint_radius_is_validated() {
        for radius in [-0.1, f64::NAN, f64::INFINITY, 100.0] {
            let params = TraversabilityParams {
                footprint_radius_m: radius,
                ..Default::default()
            };
            assert!(
                matches!(
                    TraversabilityField::from_map(&ramp(1.0), &params),
                    Err(PlanError::InvalidOption { .. })
                ),
                "radius {radius}"
            );
        }
    }

    #[test]
    fn bilinear_value_matches_cell_values_at_centres() {
        let map = ramp(0.5);
        let f =
            TraversabilityField::from_map(&map, &TraversabilityParams::default()).expect("field");
        for iy in 0..map.height {
            for ix in 0..map.width {
                let c = map.cell_center(ix, iy);
                assert!((f.at(c) - f.values[map.index(ix, iy)]).abs() < 1e-12);
                assert_eq!(f.cell_value_at(c), f.values[map.index(ix, iy)]);
            }
        }
    }

    #[test]
    fn unknown_cells_get_the_prior_and_do_not_shape_the_known_ones() {
        // 4 x 1: heights 1, 2, 100 (unknown, a wrong guess), 0.5 (unknown, flagged obstacle).
        let map = GridMap::new(
            [0.0, 0.0],
            1.0,
            4,
            1,
            vec![1.0, 2.0, 100.0, 0.5],
            Some(vec![false, false, false, true]),
        )
        .expect("map");
        let knowledge =
            MapKnowledge::new(&map, vec![true, true, false, false], 0.3).expect("knowledge");
        let params = TraversabilityParams {
            height_weight: 1.0,
            slope_weight: 1.0,
            slope_ref_deg: 45.0,
            ..Default::default()
        };
        let f =
            TraversabilityField::from_partial_map(&map, Some(&knowledge), &params).expect("field");
        // h_max = 2 (known cells only); the slope of cell 1 is one-sided towards cell 0
        // (45°, term 1), not towards the unknown 100 m.
        assert!(
            (f.values[0] - (0.5 + 1.0) / 2.0).abs() < 1e-12,
            "{:?}",
            f.values
        );
        assert!(
            (f.values[1] - (1.0 + 1.0) / 2.0).abs() < 1e-12,
            "{:?}",
            f.values
        );
        assert_eq!(&f.values[2..], &[0.3, 0.3]);
        // A negative height in an unknown cell is no error (it is not a measurement).
        let mut negative = map.clone();
        negative.heights[2] = -3.0;
        assert!(
            TraversabilityField::from_partial_map(&negative, Some(&knowledge), &params).is_ok()
        );
        // The footprint ignores an unknown cell's obstacle flag (no p = 1 spread from it): a
        // flagged unknown cell amid known flat ground, on a map wide enough that the cells
        // next to it are more than the footprint away from the map edge.
        let (w, h) = (7, 7);
        let centre = 3 * w + 3;
        let mut flags = vec![false; w * h];
        flags[centre] = true;
        let flat = GridMap::new([0.0, 0.0], 1.0, w, h, vec![1.0; w * h], Some(flags)).expect("map");
        let mut seen = vec![true; w * h];
        seen[centre] = false;
        let knowledge = MapKnowledge::new(&flat, seen, 0.3).expect("knowledge");
        let footprint = TraversabilityParams {
            footprint_radius_m: 1.0,
            h_max: Some(10.0),
            ..Default::default()
        };
        let f = TraversabilityField::from_partial_map(&flat, Some(&knowledge), &footprint)
            .expect("field");
        for neighbour in [centre - 1, centre + 1, centre - w, centre + w] {
            assert!(f.values[neighbour] < 1.0, "{:?}", f.values);
        }
        // Without knowledge the same call is from_map.
        assert_eq!(
            TraversabilityField::from_partial_map(&map, None, &params).expect("field"),
            TraversabilityField::from_map(&map, &params).expect("field")
        );
    }

    #[test]
    fn cells_steeper_than_the_walkable_limit_become_obstacles() {
        // Flat on the left (ix 0..2), a 45° wall from ix 2 to 4 (heights 0, 0, 0, 1, 2).
        let heights = (0..20).map(|i| [0.0, 0.0, 0.0, 1.0, 2.0][i % 5]).collect();
        let map = GridMap::new([0.0, 0.0], 1.0, 5, 4, heights, None).expect("map");
        let unlimited = TraversabilityParams::default();
        assert!(matches!(
            block_steep_cells(&map, None, &unlimited),
            Cow::Borrowed(_)
        ));
        let limited = TraversabilityParams {
            max_slope_deg: Some(30.0),
            ..Default::default()
        };
        let blocked = block_steep_cells(&map, None, &limited);
        let mask = blocked.obstacles.as_ref().expect("steep cells blocked");
        for iy in 0..4 {
            // ix 0, 1: flat (0°); ix 2: one-sided 26.6°, walkable; ix 3, 4: 45°.
            let row: Vec<bool> = (0..5).map(|ix| mask[iy * 5 + ix]).collect();
            assert_eq!(row, [false, false, false, true, true], "row {iy}");
        }
        // A limit above the steepest slope changes nothing.
        let loose = TraversabilityParams {
            max_slope_deg: Some(60.0),
            ..Default::default()
        };
        assert!(matches!(
            block_steep_cells(&map, None, &loose),
            Cow::Borrowed(_)
        ));
        // Unknown cells are never blocked; their heights do not make known neighbours steep.
        let known: Vec<bool> = (0..20).map(|i| i % 5 < 3).collect();
        let knowledge = MapKnowledge::new(&map, known, 0.5).expect("knowledge");
        assert!(matches!(
            block_steep_cells(&map, Some(&knowledge), &limited),
            Cow::Borrowed(_)
        ));
    }

    #[test]
    fn walkable_slope_limit_must_be_an_angle_between_0_and_90() {
        for bad in [0.0, 90.0, -5.0, f64::NAN, f64::INFINITY] {
            let params = TraversabilityParams {
                max_slope_deg: Some(bad),
                ..Default::default()
            };
            let err = params.validate().expect_err("refused");
            assert!(err.to_string().contains("max_slope_deg"), "{err}");
        }
    }

    /// A map of `width` × 3 cells of 0.125 m with heights `row` on every row, all known, each
    /// height with variance `variance`.
    fn measured(row: &[f64], variance: f64) -> (GridMap, MapKnowledge) {
        let width = row.len();
        let heights = (0..3 * width).map(|i| row[i % width]).collect();
        let map = GridMap::new([0.0, 0.0], 0.125, width, 3, heights, None).expect("map");
        let knowledge = MapKnowledge::new(&map, vec![true; 3 * width], 0.5)
            .and_then(|k| k.with_height_variances(&map, &vec![variance; 3 * width]))
            .expect("knowledge");
        (map, knowledge)
    }

    /// The cells the 30° walkable-slope limit blocks with confidence κ and slope-fit radius.
    fn blocked(map: &GridMap, knowledge: &MapKnowledge, kappa: f64, fit_radius: f64) -> Vec<bool> {
        let params = TraversabilityParams {
            max_slope_deg: Some(30.0),
            height_confidence_sigmas: kappa,
            slope_fit_radius_m: fit_radius,
            ..Default::default()
        };
        block_steep_cells(map, Some(knowledge), &params)
            .obstacles
            .clone()
            .unwrap_or_else(|| vec![false; map.len()])
    }

    fn blocked_count(map: &GridMap, knowledge: &MapKnowledge, kappa: f64) -> usize {
        blocked(map, knowledge, kappa, 0.0)
            .iter()
            .filter(|&&b| b)
            .count()
    }

    /// A row of 12 cells: flat at 1 m, then a 60° flank (rise 0.2165 m per 0.125 m cell) from
    /// cell 6 on.
    fn flank_row() -> Vec<f64> {
        let rise = 0.125 * 60f64.to_radians().tan();
        (0..12)
            .map(|i| 1.0 + rise * (i as f64 - 6.0).max(0.0))
            .collect()
    }

    #[test]
    fn an_uncertain_flank_stays_blocked() {
        // A 60° flank whose cells are uncertain to σ = 15 cm, as a flank seen at a grazing
        // angle is: its slope's lower bound is flat, its mapped slope steep. The limit keeps the
        // mapped slope.
        let (map, knowledge) = measured(&flank_row(), 0.15 * 0.15);
        let exact = blocked_count(&map, &knowledge, 0.0);
        assert!(
            exact >= 3 * 5,
            "{exact} cells blocked on the mapped heights"
        );
        assert_eq!(blocked_count(&map, &knowledge, 2.0), exact);
    }

    #[test]
    fn the_fitted_plane_of_a_ramp_has_the_ramp_slope() {
        let map = ramp(0.5);
        let knowledge = MapKnowledge::new(&map, vec![true; map.len()], 0.5).expect("knowledge");
        let window = PlaneFitWindow::new(2.0 * map.resolution, map.resolution)
            .expect("radius")
            .expect("two cells");
        let want = 0.5 / map.resolution;
        for iy in 0..map.height {
            for ix in 0..map.width {
                let g = fitted_gradient(&map, Some(&knowledge), &window, ix, iy).expect("plane");
                assert!(
                    (g.dx - want).abs() < 1e-9 && g.dy.abs() < 1e-9,
                    "{g:?} at {ix},{iy}"
                );
            }
        }
        // Known cells in one row only: no plane, central differences instead.
        let mut row_only = vec![false; map.len()];
        row_only[..map.width].fill(true);
        let knowledge = MapKnowledge::new(&map, row_only, 0.5).expect("knowledge");
        assert!(fitted_gradient(&map, Some(&knowledge), &window, 2, 0).is_none());
        assert!(PlaneFitWindow::new(0.1, map.resolution)
            .expect("small")
            .is_none());
        assert!(PlaneFitWindow::new(100.0, map.resolution).is_err());
    }

    #[test]
    fn a_lone_uncertain_outlier_blocks_nothing_with_the_fitted_slope() {
        // Flat ground measured to 1 cm, one cell 0.3 m too high with the variance the map gave
        // it (σ 0.4 m): central differences block its four neighbours, the weighted plane fit
        // nothing. A 60° flank measured to 15 cm everywhere stays blocked either way.
        let (w, h) = (9, 9);
        let mut heights = vec![0.2; w * h];
        let mut variances = vec![0.01 * 0.01; w * h];
        heights[4 * w + 4] = 0.5;
        variances[4 * w + 4] = 0.4 * 0.4;
        let map = GridMap::new([0.0, 0.0], 0.125, w, h, heights, None).expect("map");
        let knowledge = MapKnowledge::new(&map, vec![true; w * h], 0.5)
            .and_then(|k| k.with_height_variances(&map, &variances))
            .expect("knowledge");
        let count = |mask: Vec<bool>| mask.iter().filter(|&&b| b).count();
        assert_eq!(count(blocked(&map, &knowledge, 0.0, 0.0)), 4);
        assert_eq!(count(blocked(&map, &knowledge, 0.0, 0.25)), 0);

        let (flank, uncertain) = measured(&flank_row(), 0.15 * 0.15);
        let fitted = blocked(&flank, &uncertain, 0.0, 0.25);
        // Every row: the flank cells beyond the foot (x ≥ 7) are blocked.
        for iy in 0..flank.height {
            for ix in 7..flank.width {
                assert!(fitted[flank.index(ix, iy)], "({ix}, {iy}) open");
            }
        }
    }

    #[test]
    fn an_uncertain_cell_costs_its_upper_confidence_bound() {
        let row = [1.0, 2.0, 3.0, 4.0];
        let (map, knowledge) = measured(&row, 0.0);
        let mut variances = vec![0.0; 12];
        variances[5] = 0.25 * 0.25; // σ = 0.25 m at (1, 1), mapped at 2 m
        let uncertain = MapKnowledge::new(&map, vec![true; 12], 0.5)
            .and_then(|k| k.with_height_variances(&map, &variances))
            .expect("knowledge");
        let params = |kappa: f64| TraversabilityParams {
            height_confidence_sigmas: kappa,
            ..Default::default()
        };
        let field = |k: &MapKnowledge, kappa: f64| {
            TraversabilityField::from_partial_map(&map, Some(k), &params(kappa))
                .expect("field")
                .values
        };
        let certain = field(&knowledge, 2.0);
        let priced = field(&uncertain, 2.0);
        // h_max is the highest mapped height (4 m): p = (2 + 2 · 0.25) / 4.
        assert_eq!(priced[5], 0.625);
        assert_eq!(certain[5], 0.5);
        for i in (0..12).filter(|&i| i != 5) {
            assert_eq!(priced[i], certain[i], "cell {i}");
        }
        // κ = 0 prices the mapped height, bit for bit the map without variances.
        let plain = TraversabilityField::from_map(&map, &params(0.0)).expect("field");
        assert_eq!(field(&uncertain, 0.0), plain.values);
    }

    #[test]
    fn height_variances_are_checked() {
        let (map, _) = measured(&[0.0, 1.0], 0.0);
        let knowledge = || MapKnowledge::new(&map, vec![true; 6], 0.5).expect("knowledge");
        for bad in [f64::NAN, -1e-6, f64::INFINITY, 100.5] {
            let err = knowledge()
                .with_height_variances(&map, &[0.0, 0.0, 0.0, bad, 0.0, 0.0])
                .expect_err("refused");
            assert!(err.to_string().contains("cell (1, 1)"), "{err}");
        }
        let err = knowledge()
            .with_height_variances(&map, &[0.0; 5])
            .expect_err("refused");
        assert!(err.to_string().contains("height_variances"), "{err}");
        let params = TraversabilityParams {
            height_confidence_sigmas: -1.0,
            ..Default::default()
        };
        assert!(params
            .validate()
            .expect_err("refused")
            .to_string()
            .contains("height_confidence_sigmas"));
    }
}
