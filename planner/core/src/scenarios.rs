//! The paper's three test terrains and the `surprise` terrain, generated deterministically from a
//! seed.
//!
//! All are 16 m × 16 m at 0.125 m resolution (128 × 128 cells), heights in metres ≥ 0 so that
//! they can double as the physics terrain. The gentle background undulation is a sum of seeded
//! plane waves whose amplitudes are scaled so that its slope provably never exceeds a bound
//! (Σ 2π aᵢ/λᵢ = tan(bound)); the low-cost routes therefore stay walkable for a small quadruped
//! (≤ ~15°), while mountains, ridges and pit walls are deliberately steep (≥ 45°).
//!
//! - `mountain_pass`: a winding valley (a road over a gentle saddle) between 2.5–3.5 m mountains
//!   with 50° flanks; start and goal at the valley's two ends.
//! - `pits`: rough ground with a few steep hills and pits that are *low* (p alone would attract a
//!   path into them) and marked as hard obstacles.
//! - `c_shape`: a 2.2 m ridge shaped like a C whose opening faces the start; the goal lies behind
//!   the closed side, so a greedy (Euclidean-heuristic) search walks into the C and has to climb
//!   over the ridge, while the optimum walks around it.
//!
//! Not one of the paper's ([`SCENARIO_NAMES`]), but accepted by [`by_name`]
//! ([`EXTRA_SCENARIO_NAMES`]):
//!
//! - `surprise`: the only scenario with a *prior* map (what the robot is told before it moves).
//!   Gentle ground with a shallow valley from the start to the goal, so on the prior the direct
//!   route is the optimum; the true map has a trench of hard obstacles across that route, at least
//!   4 m from the start (a 3 m height sensor sees it only after walking), which the prior shows as
//!   flat ground. The way around one of its ends is walkable (slopes ≤ 10°, gaps of ≥ 3 m to
//!   the map's edge) and costs noticeably more than the prior's direct route.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::PlanError;
use crate::grid::GoalRegion;
use crate::io::MapScenario;
use crate::map::{GridMap, Point};
use crate::traversability::TraversabilityParams;

/// The paper's scenarios: what `pf-plan scenario list` and the demo use.
pub const SCENARIO_NAMES: [&str; 3] = ["mountain_pass", "pits", "c_shape"];
/// Further scenarios accepted by [`by_name`] (`pf-plan scenario list --all` adds them).
pub const EXTRA_SCENARIO_NAMES: [&str; 1] = ["surprise"];

/// Every name accepted by [`by_name`]: the paper's first.
pub fn all_names() -> impl Iterator<Item = &'static str> {
    SCENARIO_NAMES.into_iter().chain(EXTRA_SCENARIO_NAMES)
}

/// Side of every scenario map, metres.
pub const SIDE_M: f64 = 16.0;
/// Cells along each side.
pub const CELLS: usize = 128;
/// Slope bound of the background undulation, degrees.
const BACKGROUND_SLOPE_DEG: f64 = 6.0;
/// `surprise`: slope bound of its background undulation and slope of its valley's sides, degrees.
const SURPRISE_BACKGROUND_SLOPE_DEG: f64 = 4.0;
const SURPRISE_VALLEY_SLOPE_DEG: f64 = 6.0;

/// Default seed of each scenario (what `pf-plan` uses unless told otherwise).
pub fn default_seed(name: &str) -> Option<u64> {
    match name {
        "mountain_pass" => Some(1),
        "pits" => Some(2),
        "c_shape" => Some(3),
        "surprise" => Some(4),
        _ => None,
    }
}

/// The named scenario with its default seed.
pub fn by_name(name: &str) -> Result<MapScenario, PlanError> {
    let seed = default_seed(name).ok_or_else(|| unknown(name))?;
    with_seed(name, seed)
}

/// The named scenario generated from `seed`.
pub fn with_seed(name: &str, seed: u64) -> Result<MapScenario, PlanError> {
    let scenario = match name {
        "mountain_pass" => mountain_pass(seed),
        "pits" => pits(seed),
        "c_shape" => c_shape(seed),
        "surprise" => surprise(seed),
        _ => return Err(unknown(name)),
    };
    scenario.validate()?;
    Ok(scenario)
}

fn unknown(name: &str) -> PlanError {
    PlanError::InvalidOption {
        name: "scenario",
        reason: format!(
            "unknown scenario {name:?}; known: {}",
            all_names().collect::<Vec<_>>().join(", ")
        ),
    }
}

/// A sum of plane waves with a guaranteed slope bound, evaluated anywhere.
struct Undulation {
    waves: Vec<([f64; 2], f64, f64)>, // (wave vector, amplitude, phase)
}

impl Undulation {
    /// `count` waves with wavelengths in `[min_wavelength, max_wavelength]`, scaled so the
    /// gradient magnitude never exceeds tan(`max_slope_deg`).
    fn new(
        rng: &mut ChaCha8Rng,
        count: usize,
        min_wavelength: f64,
        max_wavelength: f64,
        max_slope_deg: f64,
    ) -> Self {
        let mut waves = Vec::with_capacity(count);
        let mut gradient_bound = 0.0;
        for _ in 0..count {
            let wavelength = rng.random_range(min_wavelength..=max_wavelength);
            let angle = rng.random_range(0.0..std::f64::consts::TAU);
            let k = std::f64::consts::TAU / wavelength;
            let amplitude = rng.random_range(0.5..1.0);
            let phase = rng.random_range(0.0..std::f64::consts::TAU);
            gradient_bound += amplitude * k;
            waves.push(([k * angle.cos(), k * angle.sin()], amplitude, phase));
        }
        let scale = max_slope_deg.to_radians().tan() / gradient_bound;
        for w in &mut waves {
            w.1 *= scale;
        }
        Self { waves }
    }

    /// Largest possible |value|.
    fn amplitude(&self) -> f64 {
        self.waves.iter().map(|w| w.1).sum()
    }

    fn at(&self, p: Point) -> f64 {
        self.waves
            .iter()
            .map(|(k, a, phase)| a * (k[0] * p[0] + k[1] * p[1] + phase).sin())
            .sum()
    }
}

fn sample(mut height: impl FnMut(Point) -> f64) -> Vec<f64> {
    let res = SIDE_M / CELLS as f64;
    let mut heights = Vec::with_capacity(CELLS * CELLS);
    for iy in 0..CELLS {
        for ix in 0..CELLS {
            let p = [(ix as f64 + 0.5) * res, (iy as f64 + 0.5) * res];
            heights.push(height(p).max(0.0));
        }
    }
    heights
}

fn build(
    name: &str,
    seed: u64,
    heights: Vec<f64>,
    obstacles: Option<Vec<bool>>,
    start: Point,
    start_yaw: f64,
    goal: GoalRegion,
) -> MapScenario {
    // The generators produce CELLS² finite heights by construction; GridMap::new re-checks.
    let map = GridMap {
        origin: [0.0, 0.0],
        resolution: SIDE_M / CELLS as f64,
        width: CELLS,
        height: CELLS,
        heights,
        obstacles,
    };
    MapScenario {
        name: name.to_string(),
        seed: Some(seed),
        map,
        start,
        start_yaw,
        goal,
        traversability: TraversabilityParams::default(),
        prior: None,
    }
}

/// Winding valley between mountains; start and goal at its ends.
pub fn mountain_pass(seed: u64) -> MapScenario {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let background = Undulation::new(&mut rng, 10, 3.0, 8.0, BACKGROUND_SLOPE_DEG);
    let peaks = Undulation::new(&mut rng, 8, 3.0, 6.0, 30.0);
    let bend = rng.random_range(1.8..2.4);
    let phase = rng.random_range(-0.3..0.3);
    let centre =
        move |x: f64| 0.5 * SIDE_M + bend * (std::f64::consts::TAU * x / SIDE_M + phase).sin();
    let centre_slope = move |x: f64| {
        bend * std::f64::consts::TAU / SIDE_M * (std::f64::consts::TAU * x / SIDE_M + phase).cos()
    };
    let half_width = 1.1;
    let flank = 50f64.to_radians().tan();
    let peak_amplitude = peaks.amplitude();
    let heights = sample(|p| {
        // A gentle saddle along the road: 0.15 m at the ends, 0.5 m at the pass.
        let floor = 0.15 + 0.35 * (std::f64::consts::PI * p[0] / SIDE_M).sin().powi(2);
        let undulation = 0.5 * background.amplitude() + background.at(p);
        let distance = (p[1] - centre(p[0])).abs() / centre_slope(p[0]).hypot(1.0);
        let summit = 3.0 + 0.5 * peaks.at(p) / peak_amplitude;
        let mountain = (flank * (distance - half_width)).clamp(0.0, summit);
        floor + undulation + mountain
    });
    let (x0, x1) = (0.8, SIDE_M - 0.8);
    build(
        "mountain_pass",
        seed,
        heights,
        None,
        [x0, centre(x0)],
        centre_slope(x0).atan(),
        GoalRegion {
            center: [x1, centre(x1)],
            radius: 0.5,
        },
    )
}

/// Rough ground with steep hills and low pits that are hard obstacles.
pub fn pits(seed: u64) -> MapScenario {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let background = Undulation::new(&mut rng, 14, 2.0, 6.0, 10.0);
    let start = [1.5, 1.5];
    let goal = GoalRegion {
        center: [SIDE_M - 1.5, SIDE_M - 1.5],
        radius: 0.5,
    };
    // Pits: three near the straight line start → goal (so that they matter), the rest anywhere.
    let mut pits: Vec<(Point, f64)> = Vec::new();
    let mut attempts = 0;
    while pits.len() < 9 && attempts < 10_000 {
        attempts += 1;
        let radius = rng.random_range(0.7..1.2);
        let centre = if pits.len() < 3 {
            let t = [0.3, 0.5, 0.7][pits.len()];
            let along = start[0] + t * (goal.center[0] - start[0]);
            [
                along + rng.random_range(-0.6..0.6),
                along + rng.random_range(-0.6..0.6),
            ]
        } else {
            [
                rng.random_range(3.0..SIDE_M - 3.0),
                rng.random_range(3.0..SIDE_M - 3.0),
            ]
        };
        let far_from =
            |q: Point, gap: f64| (centre[0] - q[0]).hypot(centre[1] - q[1]) > radius + gap;
        if far_from(start, 2.0)
            && far_from(goal.center, 2.0)
            && pits.iter().all(|&(c, r)| far_from(c, r + 1.2))
        {
            pits.push((centre, radius));
        }
    }
    // Hills between the pits: steep (≈ 30°) and expensive.
    let mut hills: Vec<(Point, f64, f64)> = Vec::new();
    while hills.len() < 4 && attempts < 20_000 {
        attempts += 1;
        let centre = [
            rng.random_range(2.0..SIDE_M - 2.0),
            rng.random_range(2.0..SIDE_M - 2.0),
        ];
        let sigma = rng.random_range(1.0..1.6);
        let height = rng.random_range(1.2..1.8);
        let clear_of = |q: Point, gap: f64| (centre[0] - q[0]).hypot(centre[1] - q[1]) > gap;
        if clear_of(start, 3.0 * sigma)
            && clear_of(goal.center, 3.0 * sigma)
            && pits.iter().all(|&(c, r)| clear_of(c, r + 1.5 * sigma))
        {
            hills.push((centre, sigma, height));
        }
    }
    let wall = 0.3;
    let bottom = 0.02;
    let pit_depth_at = |p: Point| -> Option<f64> {
        pits.iter().find_map(|&(c, r)| {
            let d = (p[0] - c[0]).hypot(p[1] - c[1]);
            (d < r).then(|| ((r - d) / wall).min(1.0))
        })
    };
    let heights = sample(|p| {
        let ground = 0.45
            + background.amplitude()
            + background.at(p)
            + hills
                .iter()
                .map(|&(c, s, h)| {
                    h * (-((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2)) / (2.0 * s * s)).exp()
                })
                .sum::<f64>();
        match pit_depth_at(p) {
            Some(fraction) => ground + (bottom - ground) * fraction,
            None => ground,
        }
    });
    let res = SIDE_M / CELLS as f64;
    let obstacles = (0..CELLS * CELLS)
        .map(|i| {
            let p = [
                ((i % CELLS) as f64 + 0.5) * res,
                ((i / CELLS) as f64 + 0.5) * res,
            ];
            pit_depth_at(p).is_some()
        })
        .collect();
    build(
        "pits",
        seed,
        heights,
        Some(obstacles),
        start,
        std::f64::consts::FRAC_PI_4,
        goal,
    )
}

/// A high C-shaped ridge whose opening faces the start; the goal is behind it.
pub fn c_shape(seed: u64) -> MapScenario {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let background = Undulation::new(&mut rng, 10, 3.0, 8.0, BACKGROUND_SLOPE_DEG);
    let centre = [
        8.5 + rng.random_range(-0.2..0.2),
        0.5 * SIDE_M + rng.random_range(-0.2..0.2),
    ];
    let radius = 3.3;
    // The ridge covers bearings |θ| ≤ 125° from +x: the opening (110°) faces −x, the start.
    let half_arc = 125f64.to_radians();
    let crest_half_width = 0.25;
    let ridge_height = 2.2;
    let flank = 60f64.to_radians().tan();
    let ridge_distance = |p: Point| {
        let (dx, dy) = (p[0] - centre[0], p[1] - centre[1]);
        let bearing = dy.atan2(dx);
        if bearing.abs() <= half_arc {
            (dx.hypot(dy) - radius).abs()
        } else {
            // Beyond the tips: distance to the nearer tip point.
            let tip_y = radius * half_arc.sin() * dy.signum();
            let tip = [centre[0] + radius * half_arc.cos(), centre[1] + tip_y];
            (p[0] - tip[0]).hypot(p[1] - tip[1])
        }
    };
    let heights = sample(|p| {
        let ground = 0.1 + background.amplitude() + background.at(p);
        let ridge =
            (ridge_height - flank * (ridge_distance(p) - crest_half_width).max(0.0)).max(0.0);
        ground + ridge
    });
    let start = [1.5, centre[1]];
    build(
        "c_shape",
        seed,
        heights,
        None,
        start,
        0.0,
        GoalRegion {
            center: [SIDE_M - 1.7, centre[1]],
            radius: 0.5,
        },
    )
}

/// Gentle valley from start to goal; on the true map a trench of hard obstacles crosses it, on
/// the prior (what the robot is told) the ground there is flat.
pub fn surprise(seed: u64) -> MapScenario {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let background = Undulation::new(&mut rng, 10, 3.0, 8.0, SURPRISE_BACKGROUND_SLOPE_DEG);
    let valley_y = 0.5 * SIDE_M + rng.random_range(-0.5..0.5);
    // The trench: a capsule (a segment of half-width `half_width`) crossing the valley at
    // x = `trench_x`, tilted by up to 15° from the valley's normal, reaching 3–4 m to each side.
    let trench_x = rng.random_range(7.5..9.0);
    let tilt = rng.random_range(-15f64..15.0).to_radians();
    let (below, above) = (rng.random_range(3.0..4.0), rng.random_range(3.0..4.0));
    let along = [tilt.sin(), tilt.cos()];
    let ends = [
        [trench_x - below * along[0], valley_y - below * along[1]],
        [trench_x + above * along[0], valley_y + above * along[1]],
    ];
    let half_width = 0.5;
    let trench_distance = move |p: Point| {
        let (a, b) = (ends[0], ends[1]);
        let ab = [b[0] - a[0], b[1] - a[1]];
        let t = (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / (ab[0] * ab[0] + ab[1] * ab[1]))
            .clamp(0.0, 1.0);
        (p[0] - a[0] - t * ab[0]).hypot(p[1] - a[1] - t * ab[1])
    };
    // The valley: a rounded V rising at `SURPRISE_VALLEY_SLOPE_DEG` away from y = valley_y.
    let valley_slope = SURPRISE_VALLEY_SLOPE_DEG.to_radians().tan();
    let valley_round = 0.5;
    let ground = |p: Point| {
        let d = p[1] - valley_y;
        0.1 + background.amplitude()
            + background.at(p)
            + valley_slope * (d.hypot(valley_round) - valley_round)
    };
    let (wall, bottom) = (0.3, 0.02);
    let prior_heights = sample(ground);
    let heights = sample(|p| {
        let g = ground(p);
        let d = trench_distance(p);
        if d < half_width {
            g + (bottom - g) * ((half_width - d) / wall).min(1.0)
        } else {
            g
        }
    });
    let res = SIDE_M / CELLS as f64;
    let obstacles = (0..CELLS * CELLS)
        .map(|i| {
            let p = [
                ((i % CELLS) as f64 + 0.5) * res,
                ((i / CELLS) as f64 + 0.5) * res,
            ];
            trench_distance(p) < half_width
        })
        .collect();
    // p = h / h_max with h_max fixed to the prior's highest cell (the trench only lowers the
    // ground, so that is the true map's too): a cell costs the same on both maps wherever they
    // agree, and what a robot learns while walking never rescales the rest of the map.
    let h_max = prior_heights.iter().copied().fold(0.0, f64::max);
    let start = [1.5, valley_y];
    let mut scenario = build(
        "surprise",
        seed,
        heights,
        Some(obstacles),
        start,
        0.0,
        GoalRegion {
            center: [SIDE_M - 1.5, valley_y],
            radius: 0.5,
        },
    );
    scenario.traversability.h_max = Some(h_max);
    let map = &scenario.map;
    scenario.prior = Some(GridMap {
        origin: map.origin,
        resolution: map.resolution,
        width: map.width,
        height: map.height,
        heights: prior_heights,
        obstacles: None,
    });
    scenario
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::graph::{dijkstra_path, Connectivity, GraphPath};
    use crate::grid::PlanningGrid;
    use crate::metrics::{clearance, evaluate_path, PathMetrics};
    use crate::traversability::TraversabilityField;

    #[test]
    fn same_seed_same_map_other_seed_other_map() {
        for name in all_names() {
            let a = by_name(name).expect("scenario");
            let b = by_name(name).expect("scenario");
            assert_eq!(a, b, "{name} is not deterministic");
            let c = with_seed(name, 1234).expect("scenario");
            assert_ne!(a.map.heights, c.map.heights, "{name} ignores its seed");
            assert!(a.map.heights.iter().all(|&h| h >= 0.0));
            // Only `surprise` carries a prior; it differs with the seed like the true map.
            assert_eq!(a.prior.is_some(), name == "surprise", "{name}");
            if let (Some(pa), Some(pc)) = (&a.prior, &c.prior) {
                assert_ne!(pa.heights, pc.heights, "{name}'s prior ignores its seed");
            }
        }
        assert_eq!(default_seed("surprise"), Some(4));
        assert!(!SCENARIO_NAMES.contains(&"surprise"));
        let err = by_name("volcano").unwrap_err().to_string();
        assert!(err.contains("surprise"), "{err}");
    }

    /// Dijkstra at the map's own resolution (8 directions) on `map` with the scenario's model.
    fn optimum(s: &MapScenario, map: &GridMap) -> GraphPath {
        let grid = PlanningGrid::from_map(map, &s.traversability, CELLS).expect("grid");
        dijkstra_path(&grid, s.start, &s.goal, Connectivity::Eight).expect("path")
    }

    fn measure(s: &MapScenario, map: &GridMap, path: &[Point]) -> PathMetrics {
        let field = TraversabilityField::from_map(map, &s.traversability).expect("field");
        evaluate_path(map, &field, path)
    }

    /// The surprise's defining property, for its default seed and a few others: on the prior the
    /// optimum is the direct route along the valley; on the true map that route crosses the trench
    /// and the true optimum (a walkable detour) costs noticeably more.
    #[test]
    fn surprise_prior_optimum_is_the_direct_route_which_the_true_map_blocks() {
        for seed in [4, 5, 6, 7, 8] {
            let s = with_seed("surprise", seed).expect("scenario");
            let prior = s.prior.as_ref().expect("surprise has a prior");
            let on_prior = optimum(&s, prior);
            let off_line = on_prior
                .points
                .iter()
                .map(|p| (p[1] - s.start[1]).abs())
                .fold(0.0, f64::max);
            assert!(
                off_line <= 0.5,
                "seed {seed}: the prior's optimum strays {off_line:.2} m from the direct line"
            );
            let crossing = measure(&s, &s.map, &on_prior.points);
            assert!(
                crossing.length_in_obstacles >= 0.5,
                "seed {seed}: the prior's route crosses only {:.2} m of the trench",
                crossing.length_in_obstacles
            );
            let on_true = optimum(&s, &s.map);
            assert!(
                on_true.cost > 1.5 * on_prior.cost,
                "seed {seed}: true optimum {:.4} vs the prior's route {:.4}",
                on_true.cost,
                on_prior.cost
            );
            assert_eq!(
                measure(&s, &s.map, &on_true.points).length_in_obstacles,
                0.0
            );
            // Walkable with the co-simulation's footprint (0.25 m): gentle all the way round.
            let mut robot = s.clone();
            robot.traversability.footprint_radius_m = 0.25;
            let walked = measure(&robot, &s.map, &optimum(&robot, &s.map).points);
            assert_eq!(walked.length_in_obstacles, 0.0, "seed {seed}");
            assert!(
                walked.max_slope_deg <= 12.0,
                "seed {seed}: the detour climbs {:.1}°",
                walked.max_slope_deg
            );
        }
    }

    #[test]
    fn surprise_trench_is_out_of_sensor_range_at_the_start_and_can_be_walked_around() {
        for seed in [4, 5, 6, 7, 8, 1234] {
            let s = with_seed("surprise", seed).expect("scenario");
            let prior = s.prior.as_ref().expect("prior");
            let to_trench = clearance(&s.map, s.start);
            assert!(
                to_trench >= 4.0,
                "seed {seed}: the trench is {to_trench:.2} m from the start"
            );
            assert!(clearance(&s.map, s.goal.center) >= 2.0, "seed {seed}");
            // The prior shows no trench: no obstacles, and the true map differs only inside it
            // (where it is lower).
            let mask = s.map.obstacles.as_ref().expect("the trench is an obstacle");
            assert!(prior.obstacles.is_none());
            let mut rows_blocked = Vec::new();
            for (i, (&h, &hp)) in s.map.heights.iter().zip(&prior.heights).enumerate() {
                if mask[i] {
                    assert!(h < hp, "seed {seed}: the trench lowers the ground");
                    rows_blocked.push(i / s.map.width);
                } else {
                    assert_eq!(h, hp, "seed {seed}: cell {i} differs outside the trench");
                }
            }
            // Gaps of at least 1.5 m between the trench's ends and the map's edges.
            let res = s.map.resolution;
            let low = *rows_blocked.iter().min().expect("trench") as f64 * res;
            let high = (*rows_blocked.iter().max().expect("trench") + 1) as f64 * res;
            assert!(
                low >= 1.5 && SIDE_M - high >= 1.5,
                "seed {seed}: trench spans y {low:.2}..{high:.2}"
            );
        }
    }

    #[test]
    fn undulation_respects_its_slope_bound() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let u = Undulation::new(&mut rng, 12, 2.0, 6.0, 10.0);
        let d = 1e-4;
        let bound = 10f64.to_radians().tan();
        for i in 0..400 {
            let p = [0.037 * i as f64, 0.091 * i as f64];
            let g = ((u.at([p[0] + d, p[1]]) - u.at([p[0] - d, p[1]])) / (2.0 * d))
                .hypot((u.at([p[0], p[1] + d]) - u.at([p[0], p[1] - d])) / (2.0 * d));
            assert!(g <= bound * (1.0 + 1e-6), "slope {g} above {bound}");
        }
    }
}
