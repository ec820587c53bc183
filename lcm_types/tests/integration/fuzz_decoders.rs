//! Property-based fuzzing of every generated decoder (bounded: a fixed number of cases with a
//! fixed seed, so the run is reproducible and takes seconds).
//!
//! Properties, for the wire contract and the codegen test schemas:
//! - random bytes behind each type's fingerprint, and fully random bytes: decoding never
//!   panics, and whatever decodes re-encodes to a canonical encoding that is a fixed point;
//! - every strict prefix of a valid encoding is rejected;
//! - bit flips in a valid encoding never panic and keep the round-trip property.

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};

use lcm_types::pfnav::{
    FeedbackField, Header, LowCmd, LowState, NavCmd, PlanMetrics, PlanOptions, PlanReply,
    PlanRequest, RobotEstimate, RobotStatus, ServiceStatus, TerrainMap, TrajectorySample,
};
use lcm_types::{AnyMessage, Message};

use crate::test_types;

const CASES: u32 = 20_000;

fn runner(seed_byte: u8) -> TestRunner {
    let config = Config {
        cases: CASES,
        failure_persistence: None,
        ..Config::default()
    };
    TestRunner::new_with_rng(
        config,
        TestRng::from_seed(RngAlgorithm::ChaCha, &[seed_byte; 32]),
    )
}

fn header(seq: i64) -> Header {
    Header {
        utime: 1_700_000_000_123_456 + seq,
        seq,
        frame_id: "world".to_string(),
    }
}

fn sample_map() -> TerrainMap {
    TerrainMap {
        header: header(3),
        origin_x: -1.5,
        origin_y: 2.0,
        resolution: 0.25,
        width: 3,
        height: 2,
        num_cells: 6,
        heights: vec![0.0, 0.1, -0.2, 1.5, 2.25, -3.0],
        num_obstacle_cells: 6,
        obstacle_mask: vec![false, true, false, false, false, true],
        num_known_cells: 6,
        known_mask: vec![true, true, false, true, false, true],
        unknown_traversability: 0.7,
        num_variance_cells: 6,
        height_variances: vec![0.01, 0.0, 0.0, 2.5e-3, 0.0, 1.0],
    }
}

/// Valid, non-trivial messages of every wire-contract type.
fn pfnav_seeds() -> Vec<AnyMessage> {
    let request = PlanRequest {
        header: header(9),
        request_id: 77,
        num_inline_maps: 1,
        inline_map: vec![sample_map()],
        map_seq: -1,
        start_x: 0.1,
        start_y: 2.2,
        start_yaw: 0.5,
        goal_x: -0.9,
        goal_y: 2.4,
        goal_radius: 0.3,
        method: PlanRequest::METHOD_PF,
        options: PlanOptions {
            basis: PlanOptions::BASIS_RBF,
            grid_size: 24,
            directions: 8,
            speed: 0.5,
            start_density: PlanOptions::START_DENSITY_UNIFORM,
            sample_period: 0.1,
            max_solve_time: 5.0,
            solver: PlanOptions::SOLVER_CLARABEL,
            confidence_sigmas: 2.5,
            generators: PlanOptions::GENERATORS_ANSDMD,
        },
        start_sigma: 0.15,
    };
    let samples: Vec<TrajectorySample> = (0..4)
        .map(|i| {
            let t = f64::from(i) * 0.1;
            TrajectorySample {
                t,
                x: t,
                y: 2.0 * t,
                z: 0.01,
                yaw: 1.1,
                vx: 0.2,
                vy: 0.4,
                yaw_rate: 0.0,
            }
        })
        .collect();
    let reply = PlanReply {
        header: header(10),
        request_id: 77,
        status: PlanReply::STATUS_OK,
        error: String::new(),
        method: PlanRequest::METHOD_PF,
        map_seq: 3,
        num_samples: 4,
        samples,
        metrics: PlanMetrics {
            cost: 1.25,
            length: 0.9,
            duration: 0.3,
            solve_time: 0.02,
            objective: 3.75,
            lp_status: PlanMetrics::LP_SOLVED,
            lp_iterations: 17,
            expanded_nodes: 0,
            reached_goal: true,
            lp_solver: PlanMetrics::SOLVER_DIJKSTRA,
            primal_residual: 1e-15,
            dual_residual: 0.0,
            duality_gap: 2e-16,
            certified: true,
            certificate_tolerance: 1e-6,
            cache_hit: true,
            generator_time: 0.0,
            solve_phase_time: 0.004,
            path_time: 0.002,
        },
    };
    let failed = PlanReply {
        status: PlanReply::STATUS_START_INVALID,
        error: "start (9, 9) is outside the map → rejected".to_string(),
        ..PlanReply::default()
    };
    let status = ServiceStatus {
        header: header(11),
        uptime: 12.5,
        requests_received: 5,
        requests_served: 3,
        requests_failed: 2,
        requests_rejected_busy: 1,
        malformed_messages: 100_000,
        maps_received: 1,
        latest_map_seq: 3,
        last_solve_time: 0.4,
        queue_depth: 2,
        queue_capacity: 16,
        cached_generators: 1,
    };
    let field = FeedbackField {
        header: header(12),
        request_id: 77,
        map_seq: 3,
        origin_x: -1.5,
        origin_y: 2.0,
        resolution: 0.5,
        width: 2,
        height: 2,
        num_cells: 4,
        dir_x: vec![1.0, 0.0, 0.0, -0.6],
        dir_y: vec![0.0, 0.0, 1.0, 0.8],
        speed: vec![0.5, 0.0, 0.5, 0.5],
        cost_to_go: vec![0.25, 0.0, -1.0, 0.75],
        goal_x: -1.0,
        goal_y: 2.4,
        goal_radius: 0.3,
    };
    let mut seeds = vec![
        AnyMessage::LowState(low_state()),
        AnyMessage::LowCmd(low_cmd()),
        AnyMessage::NavCmd(nav_cmd()),
        AnyMessage::RobotStatus(robot_status()),
        AnyMessage::RobotEstimate(robot_estimate()),
        AnyMessage::TerrainMap(sample_map()),
        AnyMessage::FeedbackField(field),
        AnyMessage::PlanRequest(request),
        AnyMessage::PlanReply(reply),
        AnyMessage::PlanReply(failed),
        AnyMessage::ServiceStatus(status),
    ];
    for name in lcm_types::TYPE_NAMES {
        seeds.push(AnyMessage::default_for(name).expect("every listed type has a default"));
    }
    seeds
}

fn low_state() -> LowState {
    let joints: [f32; 12] = std::array::from_fn(|j| 0.1 * j as f32 - 0.55);
    LowState {
        header: header(13),
        tick: 123_456,
        imu_quaternion: [0.995, 0.0, 0.0998, 0.0],
        imu_gyroscope: [0.01, -0.02, 0.3],
        imu_accelerometer: [0.1, 0.0, 9.81],
        q: joints,
        dq: joints.map(|v| -2.0 * v),
        tau_est: joints.map(|v| 10.0 * v),
        foot_force: [40.0, 0.0, 38.5, 1.5],
        foot_contact: [1, 0, -1, 1],
    }
}

fn low_cmd() -> LowCmd {
    LowCmd {
        header: header(14),
        state_seq: 13,
        mode: [LowCmd::MODE_SERVO; 12],
        q: [0.0; 12],
        dq: [0.0; 12],
        tau: std::array::from_fn(|j| 2.0 - 0.5 * j as f32),
        kp: [0.0; 12],
        kd: [f32::MIN_POSITIVE; 12],
    }
}

fn nav_cmd() -> NavCmd {
    NavCmd {
        header: header(15),
        mode: NavCmd::MODE_LOCOMOTION,
        x: 1.5,
        y: -0.25,
        z: 0.02,
        yaw: 0.3,
        vx: 0.5,
        vy: 0.05,
        yaw_rate: -0.1,
        body_height: 0.0,
        terrain_dzdx: 0.1,
        terrain_dzdy: -0.05,
    }
}

fn robot_status() -> RobotStatus {
    RobotStatus {
        header: header(16),
        uptime: 61.5,
        period: 1e-3,
        window_cycles: 500,
        total_cycles: 61_500,
        window_misses: 1,
        total_misses: 7,
        period_p50: 1.0e-3,
        period_p99: 1.1e-3,
        period_max: 1.4e-3,
        runtime_p50: 6.0e-5,
        runtime_p99: 4.0e-4,
        runtime_max: 6.0e-4,
        latency_p99: 9.5e-4,
        latency_max: 1.2e-3,
        safety: RobotStatus::SAFETY_DAMPING,
        safety_since: 60.25,
        reason: "no low_state_t for 20 ms".to_string(),
        damping_entries: 2,
        fsm_state: 2,
        states_received: 61_000,
        states_out_of_order: 3,
        states_non_finite: 1,
        nav_cmds_received: 3_000,
        malformed_messages: 12,
        realtime_priority: false,
        memory_locked: true,
        jitter_p99: 6.5e-5,
        jitter_max: 4.0e-4,
        latency_p50: 3.1e-4,
        window_overruns: 1,
        total_overruns: 5,
    }
}

/// Valid, non-trivial messages of every codegen test type.
fn test_schema_seeds() -> Vec<test_types::AnyMessage> {
    use test_types::codegen_test::deep::{Holder, Leaf};
    use test_types::codegen_test::{AllPrimitives, Arrays, Point};
    let point = |x: f64, label: &str| Point {
        x,
        y: -x,
        label: label.to_string(),
    };
    let arrays = Arrays {
        rows: 2,
        cols: 1,
        count: 1,
        fixed2d: [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]],
        var2d: vec![vec![7.0], vec![8.0]],
        fixed_then_var: [vec![1.5], vec![2.5]],
        var_then_fixed: vec![[1, 2], [3, 4]],
        var3d: vec![vec![[1, 2]], vec![[3, 4]]],
        points: vec![point(1.0, "p")],
        grid: vec![
            [point(2.0, "a"), point(3.0, "b")],
            [point(4.0, ""), point(5.0, "ü")],
        ],
        pair: [point(6.0, "x"), point(7.0, "y")],
        single: point(8.0, "single"),
        names: vec![vec!["r0".to_string()], vec!["r1".to_string()]],
    };
    let primitives = AllPrimitives {
        i8: -3,
        i16: 300,
        i32: -70_000,
        i64: i64::MIN,
        b: 250,
        f: 1.25,
        d: -1e300,
        s: "s".to_string(),
        flag: true,
        i8s: [1, -1, 0],
        i16s: [i16::MIN, i16::MAX],
        n: 2,
        i32s: vec![1, 2],
        i64s: vec![3, 4],
        bytes: vec![0, 255],
        fs: vec![0.5, -0.5],
        ds: [1.0, 2.0],
        strs: vec![String::new(), "two".to_string()],
        flags: vec![true, false],
    };
    let leaf = Leaf { value: 5 };
    let holder = Holder {
        first: leaf.clone(),
        second: Leaf { value: 6 },
        r#where: point(0.5, "w"),
        num_children: 1,
        children: vec![Holder {
            first: leaf,
            ..Holder::default()
        }],
    };
    let mut seeds = vec![
        test_types::AnyMessage::Arrays(arrays),
        test_types::AnyMessage::AllPrimitives(primitives),
        test_types::AnyMessage::Holder(holder),
    ];
    for name in test_types::TYPE_NAMES {
        seeds.push(test_types::AnyMessage::default_for(name).expect("default"));
    }
    seeds
}

/// Runs the three properties over one schema.
macro_rules! fuzz_schema {
    ($any:ty, $seeds:expr, $fingerprints:expr, $seed_byte:expr) => {{
        let seeds: Vec<$any> = $seeds;
        let encoded: Vec<Vec<u8>> = seeds
            .iter()
            .map(|m| m.encode().expect("seed messages are consistent"))
            .collect();
        for (m, bytes) in seeds.iter().zip(&encoded) {
            assert_eq!(&<$any>::decode(bytes).expect("seed decodes"), m);
        }
        let fingerprints: Vec<u64> = $fingerprints.iter().map(|(_, f)| *f).collect();

        let roundtrips = |bytes: &[u8]| -> Result<(), TestCaseError> {
            if let Ok(message) = <$any>::decode(bytes) {
                // Compare bytes, not values: flipped bits make NaNs, and NaN != NaN. Booleans
                // other than 0/1 decode as true and re-encode as 1, so the first re-encoding
                // is canonical and must then be a fixed point.
                let again = message
                    .encode()
                    .map_err(|e| TestCaseError::fail(e.to_string()))?;
                let decoded =
                    <$any>::decode(&again).map_err(|e| TestCaseError::fail(e.to_string()))?;
                let third = decoded
                    .encode()
                    .map_err(|e| TestCaseError::fail(e.to_string()))?;
                prop_assert_eq!(third, again);
            }
            Ok(())
        };

        // Random bodies behind every fingerprint, and fully random payloads.
        runner($seed_byte)
            .run(
                &(
                    0..fingerprints.len(),
                    proptest::collection::vec(any::<u8>(), 0..600),
                    any::<bool>(),
                ),
                |(which, body, keep_fingerprint)| {
                    let mut payload = Vec::with_capacity(8 + body.len());
                    if keep_fingerprint {
                        payload.extend_from_slice(&fingerprints[which].to_be_bytes());
                    }
                    payload.extend_from_slice(&body);
                    roundtrips(&payload)
                },
            )
            .expect("random payloads");

        // Every strict prefix of a valid encoding fails, and so does trailing garbage.
        for bytes in &encoded {
            for cut in 0..bytes.len() {
                assert!(
                    <$any>::decode(&bytes[..cut]).is_err(),
                    "prefix of {cut} bytes accepted"
                );
            }
            let mut longer = bytes.clone();
            longer.push(0);
            assert!(<$any>::decode(&longer).is_err(), "trailing byte accepted");
        }

        // Bit flips.
        runner($seed_byte.wrapping_add(1))
            .run(
                &(
                    0..encoded.len(),
                    proptest::collection::vec(any::<prop::sample::Index>(), 1..6),
                    any::<u8>(),
                ),
                |(which, flips, bit)| {
                    let mut bytes = encoded[which].clone();
                    for index in &flips {
                        let i = index.index(bytes.len());
                        bytes[i] ^= 1 << (bit % 8);
                    }
                    roundtrips(&bytes)
                },
            )
            .expect("bit flips");
    }};
}

#[test]
fn wire_contract_decoders_survive_fuzzing() {
    fuzz_schema!(AnyMessage, pfnav_seeds(), lcm_types::FINGERPRINTS, 1u8);
}

#[test]
fn codegen_test_schema_decoders_survive_fuzzing() {
    fuzz_schema!(
        test_types::AnyMessage,
        test_schema_seeds(),
        test_types::FINGERPRINTS,
        7u8
    );
}

#[test]
fn typed_decoders_reject_other_types() {
    let map = sample_map().encode().expect("consistent");
    let err = PlanRequest::decode(&map).expect_err("wrong type");
    assert!(
        matches!(err, lcm_types::DecodeError::FingerprintMismatch { expected, found, .. }
            if expected == PlanRequest::FINGERPRINT && found == TerrainMap::FINGERPRINT),
        "{err}"
    );
}

fn robot_estimate() -> RobotEstimate {
    RobotEstimate {
        header: header(17),
        state_seq: 13,
        position: [1.25, -0.5, 0.31],
        velocity: [0.4, 0.01, -0.02],
        rpy: [0.01, -0.03, 0.8],
        position_variance: [1e-4, 1e-4, 4e-6],
        estimator_status: 8,
        fsm_state: 3,
        safety: RobotStatus::SAFETY_OK,
    }
}
