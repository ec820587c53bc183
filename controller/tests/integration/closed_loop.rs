//! Closed loop on the single-rigid-body simulation driven by the controller's joint torques:
//! each stance foot pushes with the force its leg's torques produce (through the leg Jacobian and
//! the leg's own dynamics), so the stance torque law is in the loop. Trotting at 0.5 m/s along a
//! straight line and along a curve must track the reference position within 5 cm.
#![allow(clippy::needless_range_loop)] // parallel indexing of joints, axes and legs
use crate::common;

use quad_controller::{ControllerConfig, FsmState, ModeRequest, Reference, TerrainPlane};

struct Track {
    max_error: f64,
    final_pitch: f64,
    final_height_above_terrain: f64,
    rms_error: f64,
    final_fsm: FsmState,
    mpc_failures: usize,
}

/// Stand for 1.5 s, then follow `path(t)` = (x, y, yaw, vx, vy, yaw_rate) for `duration` s on the
/// terrain z = slope_x · x.
fn run(path: impl Fn(f64) -> [f64; 6], duration: f64, slope_x: f64) -> Track {
    let model = common::model();
    let config = ControllerConfig::default();
    let dt = config.control_dt;
    let (mut controller, mut sim) = common::controller_and_standing_sim(model, &config);
    sim.set_slope(slope_x, dt);
    let stand_ticks = (1.5 / dt) as usize;
    let walk_ticks = (duration / dt) as usize;
    let (mut max_error, mut sum_sq, mut samples, mut mpc_failures) = (0.0f64, 0.0, 0usize, 0usize);
    for tick in 0..stand_ticks + walk_ticks {
        let walking = tick >= stand_ticks;
        let t = (tick as f64 - stand_ticks as f64) * dt;
        let [x, y, yaw, vx, vy, yaw_rate] = if walking { path(t) } else { path(0.0) };
        let (vx, vy, yaw_rate) = if walking {
            (vx, vy, yaw_rate)
        } else {
            (0.0, 0.0, 0.0)
        };
        let reference = Reference {
            x,
            y,
            yaw,
            vx,
            vy,
            yaw_rate,
            body_height: config.body_height,
            terrain: TerrainPlane {
                height: slope_x * x,
                slope_x,
                slope_y: 0.0,
            },
            mode: if walking {
                ModeRequest::Locomotion
            } else {
                ModeRequest::Stand
            },
        };
        let command = controller
            .step(&sim.state(), &reference, dt)
            .expect("valid input");
        let balancing = matches!(command.fsm_state, FsmState::Stand | FsmState::Locomotion);
        if balancing && !command.mpc_solved {
            mpc_failures += 1;
        }
        sim.apply_torques(&command, dt, balancing);
        // Errors are measured after the first half second of walking (start-up transient).
        if walking && t >= 0.5 {
            let base = sim.base_position();
            let error = ((base.x - x).powi(2) + (base.y - y).powi(2)).sqrt();
            max_error = max_error.max(error);
            sum_sq += error * error;
            samples += 1;
        }
    }
    let base = sim.base_position();
    let rotation = sim.orientation.to_rotation_matrix();
    Track {
        max_error,
        final_pitch: (-rotation[(2, 0)]).asin(),
        final_height_above_terrain: base.z - slope_x * base.x,
        rms_error: (sum_sq / samples.max(1) as f64).sqrt(),
        final_fsm: controller.fsm_state(),
        mpc_failures,
    }
}

#[test]
fn trot_straight_at_half_a_metre_per_second() {
    let speed = 0.5;
    let track = run(|t| [speed * t, 0.0, 0.0, speed, 0.0, 0.0], 4.0, 0.0);
    println!(
        "straight: max error {:.4} m, rms {:.4} m, MPC failures {}",
        track.max_error, track.rms_error, track.mpc_failures
    );
    assert_eq!(track.final_fsm, FsmState::Locomotion);
    assert_eq!(track.mpc_failures, 0);
    assert!(track.max_error < 0.05, "max error {:.4} m", track.max_error);
}

#[test]
fn trot_along_a_curve() {
    let (speed, radius) = (0.5, 1.5);
    let yaw_rate = speed / radius;
    let track = run(
        |t| {
            let psi = yaw_rate * t;
            [
                radius * psi.sin(),
                radius * (1.0 - psi.cos()),
                psi,
                speed * psi.cos(),
                speed * psi.sin(),
                yaw_rate,
            ]
        },
        4.0,
        0.0,
    );
    println!(
        "curve: max error {:.4} m, rms {:.4} m, MPC failures {}",
        track.max_error, track.rms_error, track.mpc_failures
    );
    assert_eq!(track.final_fsm, FsmState::Locomotion);
    assert_eq!(track.mpc_failures, 0);
    assert!(track.max_error < 0.05, "max error {:.4} m", track.max_error);
}

#[test]
fn trot_uphill_follows_the_terrain_plane() {
    // 10° ramp: body pitch and height follow the terrain, footholds land on it.
    let slope = 10f64.to_radians().tan();
    let speed = 0.4;
    let track = run(|t| [speed * t, 0.0, 0.0, speed, 0.0, 0.0], 3.0, slope);
    println!(
        "uphill: max error {:.4} m, rms {:.4} m, pitch {:.4} rad, height {:.4} m",
        track.max_error, track.rms_error, track.final_pitch, track.final_height_above_terrain
    );
    assert_eq!(track.final_fsm, FsmState::Locomotion);
    assert!(
        (track.final_pitch + slope.atan()).abs() < 0.05,
        "pitch {}",
        track.final_pitch
    );
    assert!(
        (track.final_height_above_terrain - quad_controller::tuning::TUNED_STAND_HEIGHT).abs()
            < 0.03
    );
    assert!(track.max_error < 0.05, "max error {:.4} m", track.max_error);
}
