//! Terrain awareness with a local height map: the failure mode of the scenario falls was a foot
//! placed on the height of a plane fitted around the base while it actually landed on a wall
//! beside the path (c_shape), a pit rim (pits) or a valley side (mountain_pass).
#![allow(clippy::needless_range_loop)] // common/ indexes joints and axes in parallel
use crate::common;

use quad_controller::{
    Controller, ControllerConfig, ControllerError, FsmState, HeightMap, Leg, ModeRequest,
    Reference, RobotState, HEIGHT_MAP_CELLS, HEIGHT_MAP_SIZE,
};

fn reference(mode: ModeRequest) -> Reference {
    Reference {
        mode,
        body_height: quad_controller::tuning::TUNED_STAND_HEIGHT,
        ..Reference::default()
    }
}

/// A map centred on the origin whose sample at (x, y) has height `f(x, y)`.
fn map_from(f: impl Fn(f64, f64) -> f64) -> HeightMap {
    let spacing = 0.1;
    let half = (HEIGHT_MAP_SIZE - 1) as f64 / 2.0 * spacing;
    let mut map = HeightMap {
        origin: [-half, -half],
        spacing,
        heights: [0.0; HEIGHT_MAP_CELLS],
    };
    for iy in 0..HEIGHT_MAP_SIZE {
        for ix in 0..HEIGHT_MAP_SIZE {
            let x = map.origin[0] + ix as f64 * spacing;
            let y = map.origin[1] + iy as f64 * spacing;
            map.heights[iy * HEIGHT_MAP_SIZE + ix] = f(x, y);
        }
    }
    map
}

#[test]
fn height_map_is_exact_on_planes_and_empty_outside() {
    let map = map_from(|x, y| 0.3 * x - 0.2 * y + 0.1);
    for (x, y) in [(0.0, 0.0), (0.123, -0.377), (-0.5, 0.5), (0.499, 0.05)] {
        let h = map.height(x, y).expect("inside the map");
        assert!(
            (h - (0.3 * x - 0.2 * y + 0.1)).abs() < 1e-12,
            "({x}, {y}): {h}"
        );
    }
    assert_eq!(map.height(0.51, 0.0), None);
    assert_eq!(map.height(0.0, f64::NAN), None);
    assert_eq!(HeightMap::default().height(0.0, 0.0), None);
    // Triangulation of the terrain mesh: each cell is split along its (0,0)–(1,1) diagonal.
    let mut bump = HeightMap {
        origin: [0.0, 0.0],
        spacing: 1.0,
        heights: [0.0; HEIGHT_MAP_CELLS],
    };
    bump.heights[1] = 1.0; // sample (ix = 1, iy = 0)
    assert!((bump.height(0.75, 0.25).unwrap() - 0.5).abs() < 1e-12); // lower triangle
    assert!(bump.height(0.25, 0.75).unwrap().abs() < 1e-12); // upper triangle: not touched
}

#[test]
fn invalid_height_map_is_rejected_and_the_old_one_kept() {
    let mut ctrl =
        Controller::new(common::model(), ControllerConfig::default()).expect("valid config");
    let good = map_from(|_, _| 0.0);
    ctrl.set_height_map(&good).expect("valid map");
    let mut bad = good;
    bad.heights[7] = f64::NAN;
    assert!(matches!(
        ctrl.set_height_map(&bad),
        Err(ControllerError::InvalidReference(_))
    ));
    assert_eq!(ctrl.height_map(), &good);
}

/// Desired position of the rear-right foot at the end of its first swing, on flat ground at
/// z = 0 with the given map (or none): a steep wall rises on the right of the path.
fn rear_right_touchdown(map: Option<&HeightMap>) -> [f64; 3] {
    let mut ctrl =
        Controller::new(common::model(), ControllerConfig::default()).expect("valid config");
    if let Some(map) = map {
        ctrl.set_height_map(map).expect("valid map");
    }
    let state = RobotState {
        base_position: [0.0, 0.0, quad_controller::tuning::TUNED_STAND_HEIGHT],
        joint_positions: ctrl.stand_joint_positions(),
        ..RobotState::default()
    };
    for _ in 0..1002 {
        ctrl.step(&state, &reference(ModeRequest::Stand), 0.001)
            .expect("valid input");
    }
    let mut last = [0.0; 3];
    // Trot: FL and RR swing during the first half period (0.15 s).
    for tick in 0..148 {
        let cmd = ctrl
            .step(&state, &reference(ModeRequest::Locomotion), 0.001)
            .expect("valid input");
        assert_eq!(cmd.fsm_state, FsmState::Locomotion);
        assert!(
            !cmd.contacts[Leg::RR.index()],
            "tick {tick}: RR should swing"
        );
        last = cmd.desired_foot_positions[Leg::RR.index()];
    }
    last
}

#[test]
fn footholds_move_off_a_steep_wall_onto_flat_ground_at_the_map_height() {
    // Flat for y ≥ 0, a 72° wall (rise 3 per metre) for y < 0: the nominal right footholds
    // (y ≈ −0.127) are on the wall, where a foot slides down.
    let wall = map_from(|_, y| if y < 0.0 { -3.0 * y } else { 0.0 });
    let radius = common::model().foot_radius();
    let without = rear_right_touchdown(None);
    assert!(
        without[1] < -0.1,
        "plane only: nominal foothold {without:?}"
    );
    let with = rear_right_touchdown(Some(&wall));
    assert!(
        with[1] >= 0.0,
        "the foothold must leave the wall, got {with:?}"
    );
    assert!(
        (with[2] - radius).abs() < 0.01,
        "the foot must land on the flat ground's height, got {with:?}"
    );
}
