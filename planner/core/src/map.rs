//! The terrain grid in metres: the one data structure every planner stage and the physics world share.
//!
//! Conventions (also the on-disk and on-wire conventions):
//! - cell `(ix, iy)` covers `[origin.x + ix·res, origin.x + (ix+1)·res) × [origin.y + iy·res, …)`;
//! - its centre is `origin + (ix + ½, iy + ½)·res`; a cell's height is the terrain height at its centre;
//! - storage is row-major with `y` as the slow index: `index = iy · width + ix`
//!   (numpy: `heights[iy, ix]`, array shape `(height, width)`).

use crate::error::MapError;

/// Upper bound on the cells of one map, so that a request cannot make the planner allocate without limit.
pub const MAX_MAP_CELLS: usize = 4096 * 4096;

/// A point in the map's world frame, metres.
pub type Point = [f64; 2];

/// A regular height grid with an optional hard-obstacle mask.
#[derive(Debug, Clone, PartialEq)]
pub struct GridMap {
    /// World coordinates of the lower-left corner of cell (0, 0), metres.
    pub origin: Point,
    /// Edge length of one square cell, metres.
    pub resolution: f64,
    /// Cells along x.
    pub width: usize,
    /// Cells along y.
    pub height: usize,
    /// Terrain height at each cell centre, metres, row-major (`iy · width + ix`).
    pub heights: Vec<f64>,
    /// `true` where the cell is a hard obstacle (never to be entered); `None` means no obstacles.
    pub obstacles: Option<Vec<bool>>,
}

impl GridMap {
    /// Builds a map and checks every invariant; the only way external data should become a `GridMap`.
    pub fn new(
        origin: Point,
        resolution: f64,
        width: usize,
        height: usize,
        heights: Vec<f64>,
        obstacles: Option<Vec<bool>>,
    ) -> Result<Self, MapError> {
        let map = Self {
            origin,
            resolution,
            width,
            height,
            heights,
            obstacles,
        };
        map.validate()?;
        Ok(map)
    }

    /// Checks the invariants a planner relies on; called again after deserialisation.
    pub fn validate(&self) -> Result<(), MapError> {
        if !(self.origin[0].is_finite() && self.origin[1].is_finite()) {
            return Err(MapError::NonFiniteOrigin);
        }
        if !(self.resolution.is_finite() && self.resolution > 0.0) {
            return Err(MapError::BadResolution(self.resolution));
        }
        if self.width == 0 || self.height == 0 {
            return Err(MapError::Empty {
                width: self.width,
                height: self.height,
            });
        }
        let cells = self
            .width
            .checked_mul(self.height)
            .filter(|&n| n <= MAX_MAP_CELLS)
            .ok_or(MapError::TooLarge {
                width: self.width,
                height: self.height,
                max_cells: MAX_MAP_CELLS,
            })?;
        if self.heights.len() != cells {
            return Err(MapError::LengthMismatch {
                what: "heights",
                expected: cells,
                actual: self.heights.len(),
            });
        }
        if let Some(i) = self.heights.iter().position(|h| !h.is_finite()) {
            return Err(MapError::NonFiniteHeight {
                ix: i % self.width,
                iy: i / self.width,
            });
        }
        if let Some(mask) = &self.obstacles {
            if mask.len() != cells {
                return Err(MapError::LengthMismatch {
                    what: "obstacles",
                    expected: cells,
                    actual: mask.len(),
                });
            }
        }
        Ok(())
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.width * self.height
    }

    /// A valid map is never empty; provided for API completeness.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Row-major index of cell `(ix, iy)`.
    #[inline]
    pub fn index(&self, ix: usize, iy: usize) -> usize {
        iy * self.width + ix
    }

    /// Centre of cell `(ix, iy)` in world coordinates.
    #[inline]
    pub fn cell_center(&self, ix: usize, iy: usize) -> Point {
        [
            self.origin[0] + (ix as f64 + 0.5) * self.resolution,
            self.origin[1] + (iy as f64 + 0.5) * self.resolution,
        ]
    }

    /// The cell containing `p`, or `None` outside the map.
    pub fn cell_of(&self, p: Point) -> Option<(usize, usize)> {
        let fx = (p[0] - self.origin[0]) / self.resolution;
        let fy = (p[1] - self.origin[1]) / self.resolution;
        if !(fx.is_finite() && fy.is_finite()) || fx < 0.0 || fy < 0.0 {
            return None;
        }
        let (ix, iy) = (fx.floor() as usize, fy.floor() as usize);
        (ix < self.width && iy < self.height).then_some((ix, iy))
    }

    /// Whether `p` lies inside the map's rectangle.
    pub fn contains(&self, p: Point) -> bool {
        self.cell_of(p).is_some()
    }

    /// Extent of the map: `(min corner, max corner)` in world coordinates.
    pub fn bounds(&self) -> (Point, Point) {
        (
            self.origin,
            [
                self.origin[0] + self.width as f64 * self.resolution,
                self.origin[1] + self.height as f64 * self.resolution,
            ],
        )
    }

    /// Whether cell `(ix, iy)` is a hard obstacle.
    #[inline]
    pub fn is_obstacle(&self, ix: usize, iy: usize) -> bool {
        self.obstacles
            .as_ref()
            .is_some_and(|m| m[self.index(ix, iy)])
    }

    /// Whether `p` is inside an obstacle cell (points off the map are not obstacles; check `contains`).
    pub fn is_obstacle_at(&self, p: Point) -> bool {
        self.cell_of(p)
            .is_some_and(|(ix, iy)| self.is_obstacle(ix, iy))
    }

    /// Terrain height at `p` by bilinear interpolation between cell centres, clamped at the map edge.
    pub fn height_at(&self, p: Point) -> f64 {
        let fx =
            ((p[0] - self.origin[0]) / self.resolution - 0.5).clamp(0.0, (self.width - 1) as f64);
        let fy =
            ((p[1] - self.origin[1]) / self.resolution - 0.5).clamp(0.0, (self.height - 1) as f64);
        let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
        let h = |ix, iy| self.heights[self.index(ix, iy)];
        let bottom = h(x0, y0) * (1.0 - tx) + h(x1, y0) * tx;
        let top = h(x0, y1) * (1.0 - tx) + h(x1, y1) * tx;
        bottom * (1.0 - ty) + top * ty
    }
}

/// Which cells of a map were observed, and the traversability assumed for the others: a map
/// that a sensor reveals while the robot walks.
///
/// Kept beside [`GridMap`] rather than inside it so that every fully known map (files,
/// scenarios) stays exactly what it was. The planners read it through
/// [`crate::traversability::TraversabilityField::from_partial_map`]: an unknown cell costs
/// `unknown_traversability`, its height and obstacle flag are ignored, and the map statistics
/// (h_max, slope, roughness) use known cells only. An obstacle flag on an unknown cell must
/// also not block planning cells: [`MapKnowledge::clear_unknown_obstacles`] removes it from
/// the map the planning grid is built from.
///
/// A mapped height is an estimate: [`MapKnowledge::with_height_variances`] adds each cell's
/// variance, and the traversability model then prices a known cell from its confidence bounds
/// (`TraversabilityParams::height_confidence_sigmas`).
#[derive(Debug, Clone, PartialEq)]
pub struct MapKnowledge {
    /// `true` where the cell's height was observed, row-major like the heights.
    known: Vec<bool>,
    /// p of every unknown cell, in (0, 1].
    unknown_traversability: f64,
    /// Variance of each cell's height, m², row-major (`None`: heights exact).
    height_variances: Option<Vec<f64>>,
}

/// Largest accepted height variance, m² (σ = 10 m: beyond any terrain this planner maps).
pub const MAX_HEIGHT_VARIANCE: f64 = 100.0;

impl MapKnowledge {
    /// Checks the mask length against `map` and the prior p against (0, 1].
    pub fn new(
        map: &GridMap,
        known: Vec<bool>,
        unknown_traversability: f64,
    ) -> Result<Self, MapError> {
        if known.len() != map.len() {
            return Err(MapError::LengthMismatch {
                what: "known_mask",
                expected: map.len(),
                actual: known.len(),
            });
        }
        if !(unknown_traversability.is_finite()
            && unknown_traversability > 0.0
            && unknown_traversability <= 1.0)
        {
            return Err(MapError::BadUnknownTraversability(unknown_traversability));
        }
        Ok(Self {
            known,
            unknown_traversability,
            height_variances: None,
        })
    }

    /// Adds the variance of every cell of `map` (m², row-major like its heights). Each must be
    /// finite in 0 ..= [`MAX_HEIGHT_VARIANCE`]; unknown cells' values are checked, then ignored.
    pub fn with_height_variances(
        mut self,
        map: &GridMap,
        variances: &[f64],
    ) -> Result<Self, MapError> {
        if variances.len() != map.len() || self.known.len() != map.len() {
            return Err(MapError::LengthMismatch {
                what: "height_variances",
                expected: map.len(),
                actual: variances.len(),
            });
        }
        if let Some(i) = variances
            .iter()
            .position(|v| !(v.is_finite() && (0.0..=MAX_HEIGHT_VARIANCE).contains(v)))
        {
            return Err(MapError::BadHeightVariance {
                ix: i % map.width,
                iy: i / map.width,
                value: variances[i],
                max: MAX_HEIGHT_VARIANCE,
            });
        }
        self.height_variances = Some(variances.to_vec());
        Ok(self)
    }

    /// σ of the height of the cell with row-major index `index`, metres (0 without variances
    /// or for an unknown cell).
    #[inline]
    pub fn height_sigma(&self, index: usize) -> f64 {
        match &self.height_variances {
            Some(variances) if self.known[index] => variances[index].sqrt(),
            _ => 0.0,
        }
    }

    /// The heights' variances, m², row-major (`None`: heights exact).
    pub fn height_variances(&self) -> Option<&[f64]> {
        self.height_variances.as_deref()
    }

    /// Whether the cell with row-major index `index` was observed.
    #[inline]
    pub fn is_known(&self, index: usize) -> bool {
        self.known[index]
    }

    /// The mask, row-major.
    pub fn known(&self) -> &[bool] {
        &self.known
    }

    /// p assumed for unknown cells.
    pub fn unknown_traversability(&self) -> f64 {
        self.unknown_traversability
    }

    /// Number of observed cells.
    pub fn known_count(&self) -> usize {
        self.known.iter().filter(|&&k| k).count()
    }

    /// Drops the obstacle flags of unknown cells from `map` (an unobserved cell is never an
    /// obstacle: nothing has been seen there), and the mask itself when nothing is left.
    pub fn clear_unknown_obstacles(&self, map: &mut GridMap) {
        if let Some(mask) = map.obstacles.as_mut() {
            for (blocked, &known) in mask.iter_mut().zip(&self.known) {
                *blocked &= known;
            }
            if !mask.iter().any(|&b| b) {
                map.obstacles = None;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp() -> GridMap {
        let (w, h) = (4, 3);
        let heights = (0..w * h).map(|i| (i % w) as f64).collect();
        GridMap::new([-1.0, 2.0], 0.5, w, h, heights, None).expect("valid map")
    }

    #[test]
    fn cell_lookup_round_trips_through_centres() {
        let m = ramp();
        for iy in 0..m.height {
            for ix in 0..m.width {
                assert_eq!(m.cell_of(m.cell_center(ix, iy)), Some((ix, iy)));
            }
        }
        assert_eq!(m.cell_of([-1.01, 2.1]), None);
        assert_eq!(m.cell_of([1.0, 2.1]), None, "right edge is exclusive");
    }

    #[test]
    fn height_interpolates_between_centres_and_clamps_outside() {
        let m = ramp();
        let mid = [
            (m.cell_center(1, 1)[0] + m.cell_center(2, 1)[0]) / 2.0,
            m.cell_center(1, 1)[1],
        ];
        assert!((m.height_at(mid) - 1.5).abs() < 1e-12);
        assert!((m.height_at([-100.0, 0.0]) - 0.0).abs() < 1e-12);
        assert!((m.height_at([100.0, 100.0]) - 3.0).abs() < 1e-12);
    }

    #[test]
    fn invalid_maps_are_rejected_with_a_reason() {
        assert!(matches!(
            GridMap::new([0.0, 0.0], 1.0, 0, 3, vec![], None),
            Err(MapError::Empty { .. })
        ));
        assert!(matches!(
            GridMap::new([0.0, 0.0], 0.0, 1, 1, vec![0.0], None),
            Err(MapError::BadResolution(_))
        ));
        assert!(matches!(
            GridMap::new([0.0, 0.0], 1.0, 2, 1, vec![0.0, f64::NAN], None),
            Err(MapError::NonFiniteHeight { ix: 1, iy: 0 })
        ));
        assert!(matches!(
            GridMap::new([0.0, 0.0], 1.0, 2, 1, vec![0.0], None),
            Err(MapError::LengthMismatch { .. })
        ));
        assert!(matches!(
            GridMap::new([0.0, 0.0], 1.0, 1 << 20, 1 << 20, vec![], None),
            Err(MapError::TooLarge { .. })
        ));
    }

    #[test]
    fn knowledge_checks_its_mask_and_prior_and_clears_unknown_obstacles() {
        let mut map = GridMap::new(
            [0.0, 0.0],
            1.0,
            3,
            1,
            vec![0.0; 3],
            Some(vec![true, true, false]),
        )
        .expect("map");
        assert!(matches!(
            MapKnowledge::new(&map, vec![true; 2], 0.5),
            Err(MapError::LengthMismatch {
                what: "known_mask",
                expected: 3,
                actual: 2
            })
        ));
        for prior in [0.0, -0.1, 1.5, f64::NAN] {
            let err = MapKnowledge::new(&map, vec![true; 3], prior).expect_err("bad prior");
            assert!(err.to_string().contains("unknown_traversability"), "{err}");
        }
        let knowledge = MapKnowledge::new(&map, vec![true, false, false], 0.5).expect("valid");
        assert_eq!(knowledge.known_count(), 1);
        knowledge.clear_unknown_obstacles(&mut map);
        assert_eq!(map.obstacles, Some(vec![true, false, false]));
        let unseen = MapKnowledge::new(&map, vec![false; 3], 1.0).expect("valid");
        unseen.clear_unknown_obstacles(&mut map);
        assert_eq!(map.obstacles, None);
    }
}
