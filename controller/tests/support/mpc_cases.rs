//! MPC problem instances shared by the MPC tests and the MPC benchmark: trot and stand problems
//! for the repository robot at horizon 10 (perturbed state, yaw, yaw rate, slope, gait phase),
//! built from a seeded specification; the exact optimum of a problem's condensed QP (Clarabel at
//! 1e-11, optimality conditions checked) and the step-0 force error of a solve against it.
#![allow(dead_code)] // each includer uses a different part

use super::mpc_oracle::QpData;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use quad_controller::gait::Gait;
use quad_controller::mpc::{ConvexMpc, MpcInput, MpcParams, MpcSolution};
use quad_controller::{Controller, ControllerConfig, GaitKind, Leg, RobotModel, GRAVITY};

pub const HORIZON: usize = 10;

/// One MPC problem.
pub struct Case {
    pub name: String,
    pub x0: [f64; 13],
    pub reference: Vec<[f64; 13]>,
    pub contacts: Vec<[bool; 4]>,
    pub offsets: Vec<[[f64; 3]; 4]>,
    pub normal: [f64; 3],
}

impl Case {
    pub fn input(&self) -> MpcInput<'_> {
        MpcInput {
            x0: self.x0,
            reference: &self.reference,
            contacts: &self.contacts,
            foot_offsets: &self.offsets,
            terrain_normal: self.normal,
        }
    }
}

/// What a problem looks like: gait, commanded motion, terrain, and how far the start state is
/// perturbed (`amplitude` times fixed per-state scales, signs from `seed`).
#[derive(Clone, Copy, Debug)]
pub struct CaseSpec {
    pub trot: bool,
    /// Forward speed, m/s.
    pub speed: f64,
    pub yaw_rate: f64,
    /// Terrain slope along x (rise over run).
    pub slope: f64,
    pub yaw0: f64,
    pub amplitude: f64,
    /// Gait time of the first MPC step, s.
    pub phase: f64,
    pub seed: u64,
}

impl CaseSpec {
    /// A seeded random problem: speed 0–0.5 m/s, yaw rate within ±0.6 rad/s, slope within ±0.2,
    /// heading within ±3 rad, any gait phase, the start state perturbed by 1.5× the scales.
    pub fn random(trot: bool, seed: u64, gait_period: f64) -> Self {
        let n = |i| noise(seed + 1000, i);
        CaseSpec {
            trot,
            speed: 0.25 * (1.0 + n(20)),
            yaw_rate: 0.6 * n(21),
            slope: 0.2 * n(22),
            yaw0: 3.0 * n(23),
            amplitude: 1.5,
            phase: 0.5 * (1.0 + n(24)) * gait_period,
            seed: seed + 1000,
        }
    }
}

/// Deterministic pseudo-random numbers in [-1, 1].
fn noise(seed: u64, i: usize) -> f64 {
    let mut z = seed
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add((i as u64).wrapping_mul(0xBF58_476D_1CE4_E5B9));
    z ^= z >> 31;
    z = z.wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 29;
    (z % 2_000_001) as f64 / 1_000_000.0 - 1.0
}

/// Builds problems for one robot (standing pose, composite inertia, gait of the default
/// configuration).
pub struct CaseBuilder {
    pub config: ControllerConfig,
    /// CoM height above flat ground when standing, m.
    pub body_z: f64,
    /// CoM in the body frame at the standing pose, m.
    pub com: [f64; 3],
    /// Feet in the body frame at the standing pose, m.
    pub feet: [[f64; 3]; 4],
    pub gait: Gait,
}

/// The MPC of the default configuration at horizon 10 for `model`, and a problem builder.
pub fn mpc_and_cases(model: &RobotModel) -> (ConvexMpc, CaseBuilder) {
    let config = ControllerConfig::default();
    let ctrl = Controller::new(model.clone(), config.clone()).expect("controller");
    let q = ctrl.stand_joint_positions();
    let (inertia, com) = model.composite_inertia(&q);
    let mpc = ConvexMpc::new(MpcParams {
        horizon: HORIZON,
        ..MpcParams::from_config(&config, model.total_mass(), inertia)
    })
    .expect("MPC");
    let feet = Leg::ALL.map(|leg| {
        let l = leg.index();
        model.foot_position_body(leg, [q[3 * l], q[3 * l + 1], q[3 * l + 2]])
    });
    let builder = CaseBuilder {
        body_z: config.body_height + com[2],
        gait: Gait::new(GaitKind::Trot, config.gait_period),
        config,
        com,
        feet,
    };
    (mpc, builder)
}

impl CaseBuilder {
    pub fn build(&self, name: impl Into<String>, spec: &CaseSpec) -> Case {
        let CaseSpec {
            trot,
            speed,
            yaw_rate,
            slope,
            yaw0,
            amplitude,
            phase,
            seed,
        } = *spec;
        let (z, com, dt) = (self.body_z, self.com, self.config.mpc_dt);
        let n = |i| amplitude * noise(seed, i);
        let x0 = [
            0.03 * n(0),
            0.03 * n(1),
            yaw0 + 0.05 * n(2),
            0.02 * n(3),
            0.02 * n(4),
            z + 0.01 * n(5),
            0.2 * n(6),
            0.2 * n(7),
            yaw_rate + 0.1 * n(8),
            speed * yaw0.cos() + 0.1 * n(9),
            speed * yaw0.sin() + 0.1 * n(10),
            0.05 * n(11),
            GRAVITY,
        ];
        let mut reference = Vec::new();
        let mut contacts = Vec::new();
        let mut offsets = Vec::new();
        let mut xy = [0.0, 0.0];
        for k in 0..HORIZON {
            let t = (k + 1) as f64 * dt;
            let yaw = yaw0 + yaw_rate * t;
            let (vx, vy) = (speed * yaw.cos(), speed * yaw.sin());
            xy = [xy[0] + vx * dt, xy[1] + vy * dt];
            reference.push([
                0.0,
                -slope.atan(),
                yaw,
                xy[0],
                xy[1],
                z + slope * xy[0],
                0.0,
                0.0,
                yaw_rate,
                vx,
                vy,
                slope * vx,
                GRAVITY,
            ]);
            contacts.push(if trot {
                self.gait.contacts(phase + k as f64 * dt)
            } else {
                [true; 4]
            });
            let (s, c) = yaw.sin_cos();
            offsets.push(self.feet.map(|f| {
                let (bx, by) = (f[0] - com[0], f[1] - com[1]);
                [
                    c * bx - s * by - xy[0] * 0.5,
                    s * bx + c * by - xy[1] * 0.5,
                    f[2] - com[2],
                ]
            }));
        }
        let norm = (1.0 + slope * slope).sqrt();
        Case {
            name: name.into(),
            x0,
            reference,
            contacts,
            offsets,
            normal: [-slope / norm, 0.0, 1.0 / norm],
        }
    }
}

/// Solve the condensed QP to high accuracy; returns the forces (N). Panics unless the solve
/// succeeds and the solution satisfies the optimality conditions.
pub fn reference_solution(qp: &QpData) -> Vec<f64> {
    let n = qp.n;
    let mut colptr = vec![0];
    let mut rowval = Vec::new();
    let mut values = Vec::new();
    for c in 0..n {
        for r in 0..=c {
            rowval.push(r);
            values.push(qp.p_dense[c * n + r]);
        }
        colptr.push(rowval.len());
    }
    let p = CscMatrix::new(n, n, colptr, rowval, values);
    let a = CscMatrix::new(
        qp.m,
        n,
        qp.a_colptr.clone(),
        qp.a_rowval.clone(),
        qp.a_nzval.clone(),
    );
    let settings = DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(200)
        .tol_gap_abs(1e-11)
        .tol_gap_rel(1e-11)
        .tol_feas(1e-11)
        .build()
        .expect("settings");
    let mut solver = DefaultSolver::new(
        &p,
        &qp.q,
        &a,
        &qp.b,
        &[SupportedConeT::NonnegativeConeT(qp.m)],
        settings,
    )
    .expect("reference QP setup");
    solver.solve();
    assert_eq!(solver.solution.status, SolverStatus::Solved);
    check_kkt(qp, &solver.solution.x, &solver.solution.z);
    solver.solution.x.clone()
}

/// Optimality of (u, λ) for min ½uᵀPu + qᵀu s.t. Au ≤ b: stationarity, feasibility,
/// complementarity, dual feasibility.
fn check_kkt(qp: &QpData, u: &[f64], lambda: &[f64]) {
    let (n, m) = (qp.n, qp.m);
    let mut gradient: Vec<f64> = (0..n)
        .map(|r| qp.q[r] + (0..n).map(|c| qp.p_dense[c * n + r] * u[c]).sum::<f64>())
        .collect();
    let mut slack = qp.b.clone();
    for c in 0..n {
        for idx in qp.a_colptr[c]..qp.a_colptr[c + 1] {
            let r = qp.a_rowval[idx];
            gradient[c] += qp.a_nzval[idx] * lambda[r];
            slack[r] -= qp.a_nzval[idx] * u[c];
        }
    }
    let scale = qp.q.iter().fold(1.0f64, |acc, v| acc.max(v.abs()));
    assert!(
        gradient.iter().all(|g| g.abs() < 1e-6 * scale),
        "stationarity {gradient:?}"
    );
    for r in 0..m {
        assert!(slack[r] > -1e-7 && lambda[r] > -1e-9, "row {r}");
        assert!((slack[r] * lambda[r]).abs() < 1e-6 * scale, "row {r}");
    }
}

/// Largest difference between the step-0 forces of `solution` and the first stance-force
/// blocks of a condensed-QP solution `x` (stance legs in leg order); swing legs must be zero.
pub fn step0_force_error(solution: &MpcSolution, case: &Case, x: &[f64]) -> f64 {
    let mut block = 0;
    let mut max_error = 0.0f64;
    for leg in 0..4 {
        if case.contacts[0][leg] {
            for axis in 0..3 {
                max_error = max_error.max((solution.forces[leg][axis] - x[3 * block + axis]).abs());
            }
            block += 1;
        } else {
            assert_eq!(solution.forces[leg], [0.0; 3], "{}", case.name);
        }
    }
    max_error
}
