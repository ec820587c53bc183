//! Path → time-parameterised reference (t, x, y, z, yaw, vx, vy, yaw_rate) at a nominal speed.
//!
//! The polyline is walked at constant speed and sampled every `dt`. The heading is the direction
//! of the chord between the points half a `heading_window` behind and ahead along the path, so
//! the corners of a grid path become smooth turns instead of yaw jumps; it is unwrapped
//! (continuous, not folded to (−π, π]) and `yaw_rate` is its central difference. When the
//! initial heading differs from the path's, the reference first turns in place at
//! `max_turn_rate`. The last sample is at rest at the path's end. `z` is the terrain height.

use serde::Serialize;

use crate::error::PlanError;
use crate::grid::segment_is_clear;
use crate::map::{GridMap, Point};

/// Upper bound on samples of one reference (keeps absurd speed/period combinations bounded).
pub const MAX_SAMPLES: usize = 1_000_000;
/// Fastest nominal speed accepted, m/s (a legged robot, not a car).
pub const MAX_SPEED: f64 = 10.0;

/// One reference sample, world frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TrajectorySample {
    /// Time since the start, seconds.
    pub t: f64,
    /// Position east, metres.
    pub x: f64,
    /// Position north, metres.
    pub y: f64,
    /// Terrain height at (x, y), metres.
    pub z: f64,
    /// Heading, radians, counter-clockwise from +x, unwrapped.
    pub yaw: f64,
    /// Velocity east, m/s.
    pub vx: f64,
    /// Velocity north, m/s.
    pub vy: f64,
    /// Heading rate, rad/s.
    pub yaw_rate: f64,
}

/// How a path is turned into a reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrajectoryOptions {
    /// Nominal walking speed, m/s, in (0, MAX_SPEED].
    pub speed: f64,
    /// Sample period, seconds.
    pub dt: f64,
    /// Arc length over which the heading is averaged, metres.
    pub heading_window: f64,
    /// Turn rate of the initial in-place turn, rad/s.
    pub max_turn_rate: f64,
}

impl Default for TrajectoryOptions {
    fn default() -> Self {
        Self {
            speed: 0.5,
            dt: 0.1,
            heading_window: 0.6,
            max_turn_rate: 1.0,
        }
    }
}

impl TrajectoryOptions {
    /// Rejects non-finite, zero, negative or absurd values.
    pub fn validate(&self) -> Result<(), PlanError> {
        let positive = |name: &'static str, v: f64, max: f64| {
            if v.is_finite() && v > 0.0 && v <= max {
                Ok(())
            } else {
                Err(PlanError::InvalidOption {
                    name,
                    reason: format!("{v} must be finite, > 0 and <= {max}"),
                })
            }
        };
        positive("speed", self.speed, MAX_SPEED)?;
        positive("dt", self.dt, 10.0)?;
        positive("heading_window", self.heading_window, 100.0)?;
        positive("max_turn_rate", self.max_turn_rate, 100.0)
    }
}

/// Builds the reference for `path` starting with heading `start_yaw`.
pub fn build_trajectory(
    map: &GridMap,
    path: &[Point],
    start_yaw: f64,
    opts: &TrajectoryOptions,
) -> Result<Vec<TrajectorySample>, PlanError> {
    opts.validate()?;
    if !start_yaw.is_finite() {
        return Err(PlanError::InvalidOption {
            name: "start_yaw",
            reason: "must be finite".into(),
        });
    }
    let mut points: Vec<Point> = Vec::with_capacity(path.len());
    for &p in path {
        if !(p[0].is_finite() && p[1].is_finite()) {
            return Err(PlanError::InvalidOption {
                name: "path",
                reason: "contains a non-finite point".into(),
            });
        }
        let is_new = points
            .last()
            .map_or(true, |q: &Point| (p[0] - q[0]).hypot(p[1] - q[1]) > 1e-9);
        if is_new {
            points.push(p);
        }
    }
    let Some(&first) = points.first() else {
        return Err(PlanError::InvalidOption {
            name: "path",
            reason: "is empty".into(),
        });
    };
    // Cumulative arc length at each vertex.
    let mut arc = vec![0.0];
    for w in points.windows(2) {
        let last = arc[arc.len() - 1];
        arc.push(last + (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]));
    }
    let total = arc[arc.len() - 1];
    let step = opts.speed * opts.dt;
    // Compared in floating point first: a tiny speed must not overflow the sample count.
    let walking_estimate = (total / step).ceil();
    if walking_estimate.is_nan() || walking_estimate >= MAX_SAMPLES as f64 {
        return Err(PlanError::InvalidOption {
            name: "speed/dt",
            reason: format!(
                "{total:.1} m at {} m/s sampled every {} s needs about {walking_estimate:.3e} samples, more than the limit of {MAX_SAMPLES}",
                opts.speed, opts.dt
            ),
        });
    }
    let walking_samples = walking_estimate as usize;
    let heading_at = |s: f64| {
        let half = 0.5 * opts.heading_window;
        let (a, b) = (
            point_at(&points, &arc, s - half),
            point_at(&points, &arc, s + half),
        );
        (b[1] - a[1]).atan2(b[0] - a[0])
    };
    let mut samples = Vec::new();
    let mut t = 0.0;
    let mut yaw = start_yaw;
    if total > 0.0 {
        // Turn in place towards the path's initial heading, by the shorter way round.
        let target = yaw + wrap_angle(heading_at(0.0) - yaw);
        let turn_steps = ((target - yaw).abs() / (opts.max_turn_rate * opts.dt)).ceil() as usize;
        if walking_samples + turn_steps + 1 > MAX_SAMPLES {
            return Err(PlanError::InvalidOption {
                name: "speed/dt",
                reason: format!(
                    "{:.0} m at {} m/s sampled every {} s needs more than {MAX_SAMPLES} samples",
                    total, opts.speed, opts.dt
                ),
            });
        }
        let rate = if turn_steps > 0 {
            (target - yaw) / (turn_steps as f64 * opts.dt)
        } else {
            0.0
        };
        for _ in 0..turn_steps {
            samples.push(sample(map, t, first, yaw, [0.0, 0.0], rate));
            t += opts.dt;
            yaw += rate * opts.dt;
        }
        yaw = target;
    }
    let walk_start = samples.len();
    let mut walk: Vec<(f64, f64)> = Vec::with_capacity(walking_samples + 1);
    for k in 0..=walking_samples {
        walk.push(((k as f64 * step).min(total), t));
        t += opts.dt;
    }
    if map.obstacles.is_some() {
        walk = keep_chords_clear(map, &points, &arc, &walk, opts.speed);
    }
    for (k, &(s, t)) in walk.iter().enumerate() {
        let p = point_at(&points, &arc, s);
        if k > 0 {
            yaw += wrap_angle(heading_at(s) - yaw);
        }
        samples.push(sample(map, t, p, yaw, [0.0, 0.0], 0.0));
    }
    // Velocities and yaw rates from central differences of the sampled walk (one-sided at the ends),
    // so that they are consistent with the positions a tracker sees; the last sample is at rest.
    let n = samples.len();
    for i in walk_start..n {
        if i + 1 == n {
            samples[i].vx = 0.0;
            samples[i].vy = 0.0;
            samples[i].yaw_rate = 0.0;
            continue;
        }
        let (lo, hi) = (if i > walk_start { i - 1 } else { i }, i + 1);
        let span = samples[hi].t - samples[lo].t;
        samples[i].vx = (samples[hi].x - samples[lo].x) / span;
        samples[i].vy = (samples[hi].y - samples[lo].y) / span;
        samples[i].yaw_rate = (samples[hi].yaw - samples[lo].yaw) / span;
    }
    Ok(samples)
}

/// The walk's (arc length, time) samples with the path's own vertices added wherever the straight
/// chord between two consecutive samples would cross an obstacle cell of the map. A tracker
/// interpolates linearly between samples, so the samples' polyline, not only the path, must stay
/// out of obstacles; the path's segments are obstacle-free (the integrator checks them), and so
/// is a polyline through its vertices. Inserted samples are timed at the nominal speed.
fn keep_chords_clear(
    map: &GridMap,
    points: &[Point],
    arc: &[f64],
    walk: &[(f64, f64)],
    speed: f64,
) -> Vec<(f64, f64)> {
    let clear = |a: Point, b: Point| {
        segment_is_clear(
            map.origin,
            map.resolution,
            (map.width, map.height),
            a,
            b,
            |ix, iy| map.is_obstacle(ix, iy),
        )
    };
    let mut out = Vec::with_capacity(walk.len());
    for (k, &(s, t)) in walk.iter().enumerate() {
        if let Some(&(s_prev, t_prev)) = k.checked_sub(1).and_then(|j| walk.get(j)) {
            let (a, b) = (point_at(points, arc, s_prev), point_at(points, arc, s));
            if !clear(a, b) {
                let first = arc.partition_point(|&v| v <= s_prev);
                let last = arc.partition_point(|&v| v < s);
                for &v in &arc[first..last] {
                    out.push((v, t_prev + (v - s_prev) / speed));
                }
            }
        }
        out.push((s, t));
    }
    out
}

fn sample(
    map: &GridMap,
    t: f64,
    p: Point,
    yaw: f64,
    v: [f64; 2],
    yaw_rate: f64,
) -> TrajectorySample {
    TrajectorySample {
        t,
        x: p[0],
        y: p[1],
        z: map.height_at(p),
        yaw,
        vx: v[0],
        vy: v[1],
        yaw_rate,
    }
}

/// The point at arc length `s` (clamped to the path) on the polyline with cumulative lengths `arc`.
fn point_at(points: &[Point], arc: &[f64], s: f64) -> Point {
    let total = arc[arc.len() - 1];
    let s = s.clamp(0.0, total);
    let i = arc
        .partition_point(|&a| a <= s)
        .clamp(1, points.len().max(2) - 1);
    if points.len() == 1 {
        return points[0];
    }
    let (a, b) = (points[i - 1], points[i]);
    let length = arc[i] - arc[i - 1];
    let f = if length > 0.0 {
        (s - arc[i - 1]) / length
    } else {
        0.0
    };
    [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])]
}

/// `a` folded into (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    let w = a.rem_euclid(tau);
    if w > std::f64::consts::PI {
        w - tau
    } else {
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat() -> GridMap {
        GridMap::new([0.0, 0.0], 1.0, 10, 10, vec![0.25; 100], None).expect("map")
    }

    #[test]
    fn straight_path_is_walked_at_nominal_speed() {
        let opts = TrajectoryOptions {
            speed: 0.5,
            dt: 0.1,
            ..Default::default()
        };
        let traj =
            build_trajectory(&flat(), &[[1.0, 1.0], [4.0, 1.0]], 0.0, &opts).expect("trajectory");
        assert_eq!(traj.len(), 61); // 3 m at 0.05 m per sample
        for s in &traj[..60] {
            assert!((s.vx - 0.5).abs() < 1e-9 && s.vy.abs() < 1e-12 && s.yaw.abs() < 1e-12);
            assert!((s.z - 0.25).abs() < 1e-12);
        }
        let last = traj[60];
        assert!((last.x - 4.0).abs() < 1e-12 && last.vx == 0.0);
        assert!((last.t - 6.0).abs() < 1e-9);
    }

    #[test]
    fn corner_becomes_a_smooth_turn_and_initial_heading_is_turned_in_place() {
        let opts = TrajectoryOptions {
            speed: 0.5,
            dt: 0.1,
            heading_window: 0.6,
            max_turn_rate: 1.0,
        };
        let traj = build_trajectory(
            &flat(),
            &[[1.0, 1.0], [3.0, 1.0], [3.0, 3.0]],
            -std::f64::consts::FRAC_PI_2,
            &opts,
        )
        .expect("trajectory");
        // In-place turn of π/2 at 1 rad/s: 16 samples of 0.1 s, at rest.
        let turning: Vec<_> = traj
            .iter()
            .take_while(|s| s.vx == 0.0 && s.vy == 0.0)
            .collect();
        assert_eq!(turning.len(), 16);
        assert!(turning
            .iter()
            .all(|s| s.yaw_rate > 0.0 && s.yaw_rate <= 1.0 + 1e-12));
        // Per-sample yaw change bounded: the corner is spread over the heading window.
        let max_step = traj
            .windows(2)
            .map(|w| (w[1].yaw - w[0].yaw).abs())
            .fold(0.0, f64::max);
        assert!(max_step < 0.2, "yaw jumps by {max_step}");
        let end = traj[traj.len() - 1];
        assert!((end.yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
    }

    #[test]
    fn bad_options_are_errors() {
        let map = flat();
        for speed in [0.0, -1.0, f64::NAN, 1e9] {
            let opts = TrajectoryOptions {
                speed,
                ..Default::default()
            };
            assert!(matches!(
                build_trajectory(&map, &[[1.0, 1.0], [2.0, 1.0]], 0.0, &opts),
                Err(PlanError::InvalidOption { name: "speed", .. })
            ));
        }
        assert!(build_trajectory(&map, &[], 0.0, &TrajectoryOptions::default()).is_err());
        let tiny = TrajectoryOptions {
            speed: 1e-6,
            dt: 1e-3,
            ..Default::default()
        };
        assert!(build_trajectory(&map, &[[0.0, 0.0], [9.0, 9.0]], 0.0, &tiny).is_err());
    }
}
