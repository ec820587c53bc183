//! MPC solve time at horizon 10 (Clarabel on the sparse QP, incl. model building and assembly),
//! median and p99, on a trotting and a standing problem; the same problem, as the condensed QP of
//! the test oracle (`tests/support/mpc_oracle.rs`), is also solved by OSQP for comparison (with
//! `--features osqp-comparison`: OSQP's C sources build with cmake). Then 300 seeded random trot and
//! stand problems: interior-point iterations, solve time and the step-0 force error against the
//! exact optimum of each problem (one benchmark instance says little about the spread).
use std::time::Instant;

#[path = "../tests/support/mpc_cases.rs"]
mod mpc_cases;
#[cfg(feature = "osqp-comparison")]
#[path = "support/osqp_qp.rs"]
mod osqp_qp;
mod mpc_api {
    pub use quad_controller::math::rot_z;
    pub use quad_controller::mpc::*;
    pub use quad_controller::NUM_LEGS;
}
#[path = "../tests/support/mpc_oracle.rs"]
mod mpc_oracle;

use criterion::{criterion_group, criterion_main, Criterion};
use quad_controller::mpc::{ConvexMpc, MpcSolution, MpcStatus};
use quad_controller::{RobotModel, GRAVITY};

/// The benchmark instance: a perturbed start, walking straight at 0.5 m/s (trot) or standing.
struct Problem {
    mpc: ConvexMpc,
    case: mpc_cases::Case,
}

fn robot() -> RobotModel {
    let robot = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robot/quadruped.toml");
    RobotModel::from_config_file(&robot).expect("URDF")
}

impl Problem {
    fn new(trot: bool) -> Self {
        let (mpc, builder) = mpc_cases::mpc_and_cases(&robot());
        let (config, com, z) = (&builder.config, builder.com, builder.body_z);
        let speed = 0.5;
        // Slightly perturbed start so the QP has work to do.
        let x0 = [
            0.02,
            -0.03,
            0.05,
            -0.02,
            0.01,
            z - 0.01,
            0.1,
            -0.2,
            0.05,
            0.4,
            0.05,
            0.0,
            GRAVITY,
        ];
        let mut reference = Vec::new();
        let mut contacts = Vec::new();
        let mut offsets = Vec::new();
        for k in 0..mpc_cases::HORIZON {
            let t = (k + 1) as f64 * config.mpc_dt;
            reference.push([
                0.0,
                0.0,
                0.0,
                speed * t,
                0.0,
                z,
                0.0,
                0.0,
                0.0,
                speed,
                0.0,
                0.0,
                GRAVITY,
            ]);
            contacts.push(if trot {
                builder.gait.contacts(0.05 + k as f64 * config.mpc_dt)
            } else {
                [true; 4]
            });
            offsets.push(builder.feet.map(|foot| {
                [
                    foot[0] - com[0] - speed * t,
                    foot[1] - com[1],
                    foot[2] - com[2],
                ]
            }));
        }
        let case = mpc_cases::Case {
            name: if trot { "trot" } else { "stand" }.into(),
            x0,
            reference,
            contacts,
            offsets,
            normal: [0.0, 0.0, 1.0],
        };
        Problem { mpc, case }
    }

    fn solve(&mut self) -> MpcSolution {
        self.mpc.solve(&self.case.input())
    }
}

fn percentiles(mut samples: Vec<f64>) -> (f64, f64) {
    samples.sort_by(f64::total_cmp);
    let at = |p: f64| samples[((samples.len() - 1) as f64 * p).round() as usize];
    (at(0.5), at(0.99))
}

fn report(name: &str, mut solve: impl FnMut() -> bool) {
    let mut samples = Vec::with_capacity(2000);
    for _ in 0..2000 {
        let start = Instant::now();
        assert!(solve(), "{name}: solve failed");
        samples.push(start.elapsed().as_secs_f64() * 1e3);
    }
    let (median, p99) = percentiles(samples);
    println!("{name}: median {median:.3} ms, p99 {p99:.3} ms (2000 solves)");
}

fn bench_mpc(c: &mut Criterion) {
    for (label, trot) in [("trot", true), ("stand", false)] {
        let mut problem = Problem::new(trot);
        let first = problem.solve();
        let qp = mpc_oracle::condensed_qp(problem.mpc.params(), &problem.case.input());
        println!(
            "MPC horizon 10, {label}: {} QP variables ({} forces), {} inequality constraints, \
             {} iterations",
            first.num_variables, qp.n, qp.m, first.iterations
        );
        report(&format!("clarabel {label}"), || {
            problem.solve().status == MpcStatus::Solved
        });
        c.bench_function(&format!("mpc_clarabel_h10_{label}"), |b| {
            b.iter(|| problem.solve().status)
        });
        #[cfg(feature = "osqp-comparison")]
        osqp_compare::run(c, label, &qp);
        #[cfg(not(feature = "osqp-comparison"))]
        println!(
            "OSQP comparison of {label} ({} variables): run with --features osqp-comparison",
            qp.n
        );
    }
}

#[cfg(feature = "osqp-comparison")]
mod osqp_compare {
    use super::mpc_oracle::QpData;
    use criterion::Criterion;

    fn problem(qp: &QpData) -> osqp::Problem {
        super::osqp_qp::osqp_problem(qp, 1e-5).expect("OSQP setup")
    }

    pub fn run(c: &mut Criterion, label: &str, qp: &QpData) {
        let qp = qp.clone();
        super::report(&format!("osqp {label} (setup + solve)"), || {
            matches!(problem(&qp).solve(), osqp::Status::Solved(_))
        });
        let mut reused = problem(&qp);
        super::report(&format!("osqp {label} (solve only, warm)"), || {
            matches!(
                reused.solve(),
                osqp::Status::Solved(_) | osqp::Status::SolvedInaccurate(_)
            )
        });
        c.bench_function(&format!("mpc_osqp_h10_{label}"), |b| {
            b.iter(|| problem(&qp).solve().x().map(|x| x[0]))
        });
    }
}

/// Iterations, time and accuracy over seeded random problems (`CaseSpec::random`).
fn random_problems(_: &mut Criterion) {
    const PROBLEMS: u64 = 300;
    let (mut mpc, builder) = mpc_cases::mpc_and_cases(&robot());
    for trot in [true, false] {
        let mut iterations = Vec::new();
        let mut times = Vec::new();
        let mut errors = Vec::new();
        let mut failures = 0;
        for seed in 0..PROBLEMS {
            let spec = mpc_cases::CaseSpec::random(trot, seed, builder.config.gait_period);
            let case = builder.build(format!("random {seed}"), &spec);
            let mut samples = Vec::with_capacity(11);
            let mut timed_solve = || {
                let start = Instant::now();
                let solution = mpc.solve(&case.input());
                samples.push(start.elapsed().as_secs_f64() * 1e3);
                solution
            };
            // The first solve also builds the schedule's solver (the median of 11 ignores it);
            // repeated solves are bit-identical, so the first answer serves for the accuracy.
            let solution = timed_solve();
            for _ in 1..11 {
                timed_solve();
            }
            if solution.status != MpcStatus::Solved {
                failures += 1;
                continue;
            }
            let exact = mpc_cases::reference_solution(&mpc_oracle::condensed_qp(
                mpc.params(),
                &case.input(),
            ));
            errors.push(mpc_cases::step0_force_error(&solution, &case, &exact));
            iterations.push(f64::from(solution.iterations));
            times.push(percentiles(samples).0);
        }
        let mean_iterations = iterations.iter().sum::<f64>() / iterations.len().max(1) as f64;
        let max_iterations = iterations.iter().fold(0.0f64, |a, &b| a.max(b));
        let (median_time, p99_time) = percentiles(times);
        errors.sort_by(f64::total_cmp);
        let p95_error = errors[(errors.len() - 1) * 95 / 100];
        let max_error = errors[errors.len() - 1];
        println!(
            "{PROBLEMS} random {} problems: {mean_iterations:.2} iterations on average (max \
             {max_iterations}), solve time median {median_time:.3} ms / p99 {p99_time:.3} ms over \
             the problems, step-0 force error vs the exact optimum p95 {p95_error:.3} N / max \
             {max_error:.3} N, {failures} failed",
            if trot { "trot" } else { "stand" }
        );
    }
}

criterion_group!(benches, bench_mpc, random_problems);
criterion_main!(benches);
