//! One yardstick for every method: ∫ p ds along the continuous polyline, its length, the length
//! inside obstacles, the minimum clearance to obstacles and the steepest terrain crossed.
//!
//! Every segment of a path is cut into sub-steps of at most `resolution / 8` and integrated with
//! the composite trapezoid rule on the bilinear traversability field of the *map* (not the
//! planning grid), so P-F, A* and Dijkstra paths are measured identically whatever their
//! planning resolution.

use serde::Serialize;

use crate::map::{GridMap, Point};
use crate::traversability::TraversabilityField;

/// Sub-steps per map cell along a path.
const SAMPLES_PER_CELL: f64 = 8.0;

/// Measurements of one path.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PathMetrics {
    /// ∫ p ds along the path (composite trapezoid, bilinear p).
    pub cost_integral: f64,
    /// Euclidean length, metres.
    pub length: f64,
    /// Length of the sub-steps whose midpoint lies in an obstacle cell of the map, metres.
    pub length_in_obstacles: f64,
    /// Smallest distance from a path sample to an obstacle cell, metres (`f64::INFINITY` without
    /// obstacles; 0 when the path enters one).
    pub min_clearance: f64,
    /// Steepest terrain inclination at the path samples (bilinear heights, central differences
    /// over one map cell), degrees.
    pub max_slope_deg: f64,
}

/// Measures `path` on `map` with traversability `field` (which must have been evaluated on `map`).
pub fn evaluate_path(map: &GridMap, field: &TraversabilityField, path: &[Point]) -> PathMetrics {
    let mut metrics = PathMetrics {
        cost_integral: 0.0,
        length: 0.0,
        length_in_obstacles: 0.0,
        min_clearance: f64::INFINITY,
        max_slope_deg: 0.0,
    };
    let step_max = map.resolution / SAMPLES_PER_CELL;
    let visit = |p: Point, m: &mut PathMetrics| {
        m.min_clearance = m.min_clearance.min(clearance(map, p));
        m.max_slope_deg = m.max_slope_deg.max(inclination_deg(map, p));
    };
    if let Some(&first) = path.first() {
        visit(first, &mut metrics);
    }
    for pair in path.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let length = (b[0] - a[0]).hypot(b[1] - a[1]);
        if !length.is_finite() || length == 0.0 {
            continue;
        }
        let steps = (length / step_max).ceil().max(1.0) as usize;
        let h = length / steps as f64;
        let at = |s: f64| [a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s];
        let mut previous = field.at(a);
        for s in 1..=steps {
            let p = at(s as f64 / steps as f64);
            let value = field.at(p);
            metrics.cost_integral += 0.5 * (previous + value) * h;
            previous = value;
            if map.is_obstacle_at(at((s as f64 - 0.5) / steps as f64)) {
                metrics.length_in_obstacles += h;
            }
            visit(p, &mut metrics);
        }
        metrics.length += length;
    }
    metrics
}

/// Distance from `p` to the nearest obstacle cell (0 inside one, `INFINITY` without obstacles).
///
/// Searches square rings of cells around `p`'s cell outward and stops once a ring cannot hold
/// anything closer than the best distance found.
pub fn clearance(map: &GridMap, p: Point) -> f64 {
    let Some(mask) = &map.obstacles else {
        return f64::INFINITY;
    };
    if !mask.iter().any(|&o| o) {
        return f64::INFINITY;
    }
    let res = map.resolution;
    let cx = ((p[0] - map.origin[0]) / res).floor();
    let cy = ((p[1] - map.origin[1]) / res).floor();
    if !(cx.is_finite() && cy.is_finite()) {
        return f64::INFINITY;
    }
    let (w, h) = (map.width as i64, map.height as i64);
    let (cx, cy) = (
        cx.clamp(-1.0, w as f64) as i64,
        cy.clamp(-1.0, h as f64) as i64,
    );
    let mut best = f64::INFINITY;
    let max_ring = w.max(h) + 2;
    for ring in 0..=max_ring {
        // Every cell of this ring is at least (ring - 1) cells away from p.
        if (ring - 1) as f64 * res > best {
            break;
        }
        let mut check = |ix: i64, iy: i64| {
            if ix < 0 || iy < 0 || ix >= w || iy >= h || !mask[map.index(ix as usize, iy as usize)]
            {
                return;
            }
            let x0 = map.origin[0] + ix as f64 * res;
            let y0 = map.origin[1] + iy as f64 * res;
            let dx = (x0 - p[0]).max(0.0).max(p[0] - (x0 + res));
            let dy = (y0 - p[1]).max(0.0).max(p[1] - (y0 + res));
            best = best.min(dx.hypot(dy));
        };
        if ring == 0 {
            check(cx, cy);
            continue;
        }
        for d in -ring..=ring {
            check(cx + d, cy - ring);
            check(cx + d, cy + ring);
        }
        for d in (-ring + 1)..ring {
            check(cx - ring, cy + d);
            check(cx + ring, cy + d);
        }
    }
    best
}

/// Terrain inclination at `p` in degrees from the bilinear height field (central differences over one cell).
pub fn inclination_deg(map: &GridMap, p: Point) -> f64 {
    let d = 0.5 * map.resolution;
    let gx = (map.height_at([p[0] + d, p[1]]) - map.height_at([p[0] - d, p[1]])) / (2.0 * d);
    let gy = (map.height_at([p[0], p[1] + d]) - map.height_at([p[0], p[1] - d])) / (2.0 * d);
    gx.hypot(gy).atan().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::traversability::TraversabilityParams;

    #[test]
    fn integral_of_a_linear_field_matches_the_closed_form() {
        // Heights h = 1 + x on a 0.5 m grid, h_max = 10 (override) => p = (1 + x)/10 in the interior.
        let (w, h) = (20, 4);
        let map = GridMap::new(
            [0.0, 0.0],
            0.5,
            w,
            h,
            (0..w * h)
                .map(|i| 1.0 + 0.5 * ((i % w) as f64 + 0.5))
                .collect(),
            None,
        )
        .expect("map");
        let params = TraversabilityParams {
            h_max: Some(10.0),
            ..Default::default()
        };
        let field = TraversabilityField::from_map(&map, &params).expect("field");
        let m = evaluate_path(&map, &field, &[[1.0, 1.0], [4.0, 1.0], [4.0, 1.5]]);
        // ∫_1^4 (1+x)/10 dx = (3 + (16-1)/2)/10 = 1.05; then 0.5 m at x = 4: 0.25.
        assert!((m.cost_integral - 1.3).abs() < 1e-9, "{}", m.cost_integral);
        assert!((m.length - 3.5).abs() < 1e-12);
        assert_eq!(m.length_in_obstacles, 0.0);
        assert!(m.min_clearance.is_infinite());
        assert!((m.max_slope_deg - 45.0).abs() < 1e-9);
    }

    #[test]
    fn obstacle_length_and_clearance() {
        let (w, h) = (10, 10);
        let mut mask = vec![false; w * h];
        mask[5 * w + 5] = true; // cell [5,6) x [5,6)
        let map = GridMap::new([0.0, 0.0], 1.0, w, h, vec![1.0; w * h], Some(mask)).expect("map");
        let field =
            TraversabilityField::from_map(&map, &TraversabilityParams::default()).expect("field");
        let through = evaluate_path(&map, &field, &[[0.5, 5.5], [9.5, 5.5]]);
        assert!((through.length_in_obstacles - 1.0).abs() < 1e-9);
        assert_eq!(through.min_clearance, 0.0);
        let beside = evaluate_path(&map, &field, &[[0.5, 3.0], [9.5, 3.0]]);
        assert_eq!(beside.length_in_obstacles, 0.0);
        assert!((beside.min_clearance - 2.0).abs() < 1e-12);
        assert!((clearance(&map, [8.0, 9.0]) - 13f64.sqrt()).abs() < 1e-12);
    }
}
