//! The pruned foothold search against the exhaustive one.
use super::*;
use crate::api::{HEIGHT_MAP_CELLS, HEIGHT_MAP_SIZE};
use crate::{Controller, ControllerConfig, RobotModel};

/// The pruned foothold search returns bit for bit what evaluating every candidate returns.
#[test]
fn pruned_foothold_search_equals_the_exhaustive_search() {
    let robot = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robot/quadruped.toml");
    let model = RobotModel::from_config_file(&robot).expect("URDF");
    let config = ControllerConfig::default();
    let radius = model.foot_radius();
    let controller = Controller::new(model, config.clone()).expect("controller");
    // The planner of the default controller: feet at the standing pose.
    let q = controller.stand_joint_positions();
    let nominal_feet = Leg::ALL.map(|leg| {
        let l = leg.index();
        Vector3::from(
            controller
                .model()
                .foot_position_body(leg, [q[3 * l], q[3 * l + 1], q[3 * l + 2]]),
        )
    });
    let mut planner = FootholdPlanner::new(&config, nominal_feet, radius);
    let reference = Reference::default();
    let mut seed = 0x2545_f491_4f6c_dd1d_u64;
    let mut uniform = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let exhaustive = |c: &FootholdPlanner, x: f64, y: f64| {
        let mut best: Option<(f64, f64, f64)> = None;
        for k in &c.foothold_candidates {
            let (cx, cy) = (x + k.dx, y + k.dy);
            if let Some(cost) = c.foothold_cost(k.ring, cx, cy, f64::INFINITY) {
                if best.map_or(true, |(b, _, _)| cost < b - 1e-9) {
                    best = Some((cost, cx, cy));
                }
            }
        }
        let (fx, fy) = best.map_or((x, y), |(_, bx, by)| (bx, by));
        [fx, fy]
    };
    for map_index in 0..40 {
        // Flat, stepped (walls and pits) and rough maps.
        let mut map = HeightMap {
            origin: [-0.5, -0.5],
            spacing: 0.1,
            heights: [0.0; HEIGHT_MAP_CELLS],
        };
        for iy in 0..HEIGHT_MAP_SIZE {
            for ix in 0..HEIGHT_MAP_SIZE {
                map.heights[iy * HEIGHT_MAP_SIZE + ix] = match map_index % 4 {
                    0 => 0.0,
                    1 => (if ix > 5 { 0.3 } else { 0.0 }) + 0.01 * uniform(),
                    2 => {
                        if (ix + iy) % 5 == 0 {
                            -0.2
                        } else {
                            0.0
                        }
                    }
                    _ => 0.15 * uniform(),
                };
            }
        }
        planner.set_height_map(&map);
        for _ in 0..50 {
            let x = -0.6 + 1.2 * uniform();
            let y = -0.6 + 1.2 * uniform();
            let pruned = planner.select_foothold(&reference, x, y);
            let full = exhaustive(&planner, x, y);
            assert_eq!(
                [pruned.x.to_bits(), pruned.y.to_bits()],
                [full[0].to_bits(), full[1].to_bits()],
                "map {map_index} at ({x}, {y})"
            );
        }
    }
}

/// While a push is taken out, the governed velocity starts at the body's and the Raibert
/// feedback would vanish; the footholds steer to `foothold_velocity` (the given reference's)
/// instead, and step out by the gain times the difference.
#[test]
fn footholds_steer_a_pushed_body_to_the_given_velocity() {
    let config = ControllerConfig::default();
    let nominal = [
        Vector3::new(0.18, -0.13, -0.28),
        Vector3::new(0.18, 0.13, -0.28),
        Vector3::new(-0.18, -0.13, -0.28),
        Vector3::new(-0.18, 0.13, -0.28),
    ];
    let planner = FootholdPlanner::new(&config, nominal, 0.02);
    let reference = Reference::default();
    let estimate = Estimate {
        rotation: nalgebra::Matrix3::identity(),
        rpy: Vector3::zeros(),
        position: Vector3::new(0.0, 0.0, 0.28),
        velocity: Vector3::new(0.0, 1.0, 0.0),
        angular_velocity: Vector3::zeros(),
        q: [[0.0; 3]; NUM_LEGS],
        dq: [[0.0; 3]; NUM_LEGS],
        feet_world: nominal,
        gravity_body: [0.0, 0.0, -1.0],
    };
    let pushed = MotionTarget {
        xy: [0.0; 2],
        roll: 0.0,
        yaw: 0.0,
        velocity: [0.0, 0.65],
        foothold_velocity: [0.0, 0.65],
        yaw_rate: 0.0,
    };
    let steered = MotionTarget {
        foothold_velocity: [0.0, 0.0],
        ..pushed
    };
    let (t_td, t_st) = (0.05, 0.15);
    let leg = Leg::FL;
    let along = planner.raibert_foothold(&estimate, &reference, &pushed, leg, t_td, t_st);
    let back = planner.raibert_foothold(&estimate, &reference, &steered, leg, t_td, t_st);
    let expected = config.raibert_gain * 0.65;
    assert!(
        (back.y - along.y - expected).abs() < 1e-12,
        "{along} {back}"
    );
    assert_eq!(back.x, along.x);
}
