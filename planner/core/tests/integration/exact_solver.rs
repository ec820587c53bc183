//! The exact SSP solver against Clarabel and the graph, its certificate, and its limits.

use crate::support;

use pf_planner::basis::BasisKind;
use pf_planner::certificate::certify;
use pf_planner::generators::{Generators, SparseColumns, SparseMatrix};
use pf_planner::grid::{GoalRegion, PlanningGrid};
use pf_planner::lp::{self, LpProblem, LpSettings, LpSolution, LpSolver, LpStatus, SolverUsed};
use pf_planner::pf::{self, PfGenerators, PfOptions, StartDensity};
use pf_planner::ssp::{self, Structure};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use support::{graph_value, random_free_point, random_grid, settings};

const TOLERANCE: f64 = 1e-6;

/// A stochastic version of Ulam's generators: each move lands where it should with probability
/// 0.8 and, with 0.2, where the next direction's move from the same cell lands (or stays put when
/// that move is a wall). Markov, not deterministic: the SSP solver must use policy iteration.
fn slippery(gens: &Generators) -> Generators {
    let n = gens.basis.len();
    let k_count = gens.directions.len();
    let destination = |k: usize, i: usize| {
        gens.generators[k]
            .column(i)
            .find(|&(j, v)| j != i && v > 0.0)
            .map(|(j, _)| j)
    };
    let generators = (0..k_count)
        .map(|k| {
            let step = gens.directions[k].step;
            let columns = (0..n)
                .map(|i| match destination(k, i) {
                    None => Vec::new(),
                    Some(j) => {
                        let mut col = vec![(j, 0.8 / step)];
                        match destination((k + 1) % k_count, i) {
                            Some(j2) => col.extend([(j2, 0.2 / step), (i, -1.0 / step)]),
                            None => col.push((i, -0.8 / step)),
                        }
                        col
                    }
                })
                .collect();
            SparseMatrix::from_columns(n, columns)
        })
        .collect();
    Generators {
        basis: gens.basis.clone(),
        directions: gens.directions.clone(),
        generators,
        stats: gens.stats.clone(),
    }
}

fn assert_certified(label: &str, sol: &LpSolution) {
    assert_eq!(
        sol.report.status,
        LpStatus::Solved,
        "{label}: {:?}",
        sol.report
    );
    assert!(
        sol.report.certificate.holds(),
        "{label}: certificate {:?}",
        sol.report.certificate
    );
}

#[test]
fn exact_solver_and_clarabel_agree_on_random_maps() {
    let mut rng = ChaCha8Rng::seed_from_u64(20261125);
    let mut compared = 0;
    for terrain in 0..16 {
        let grid = random_grid(&mut rng);
        let start = random_free_point(&mut rng, &grid);
        let goal = GoalRegion {
            center: random_free_point(&mut rng, &grid),
            radius: grid.cell_size * rng.random_range(0.0..2.0),
        };
        let u_max = rng.random_range(0.3..2.0);
        let directions = if terrain % 2 == 0 { 4 } else { 8 };
        let gens =
            PfGenerators::build(&grid, &BasisKind::Indicator, directions).expect("generators");
        let density = if terrain % 4 < 2 {
            StartDensity::PointMass
        } else {
            StartDensity::UniformFree
        };
        let Ok(prepared) = pf::prepare(&gens, &grid, start, &goal, density) else {
            continue;
        };
        let problem = prepared.problem(&gens, u_max);
        let exact = lp::solve(&problem, &settings(LpSolver::Exact)).expect("exact");
        if exact.report.status == LpStatus::Trivial {
            continue; // the start lies in the goal region
        }
        let clarabel = lp::solve(&problem, &settings(LpSolver::Clarabel)).expect("clarabel");
        assert_eq!(exact.report.solver, SolverUsed::Dijkstra);
        assert_certified("exact", &exact);
        assert_certified("clarabel", &clarabel);
        let (a, b) = (exact.report.objective, clarabel.report.objective);
        assert!(
            (a - b).abs() <= TOLERANCE * a,
            "terrain {terrain}: {a} vs {b}"
        );
        // The duals agree too wherever mass starts (the optimal dual is unique there).
        for i in (0..prepared.start.len()).filter(|&i| prepared.start[i] > 0.0) {
            let (va, vb) = (exact.potential[i], clarabel.potential[i]);
            assert!(
                (va - vb).abs() <= 1e-5 * va.abs().max(1e-9),
                "terrain {terrain}, function {i}: V {va} vs {vb}"
            );
        }
        compared += 1;
    }
    assert!(compared >= 10, "only {compared} reachable cases");
}

#[test]
fn policy_iteration_matches_clarabel_on_stochastic_generators() {
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    let mut compared = 0;
    for terrain in 0..8 {
        let grid = random_grid(&mut rng);
        let start = random_free_point(&mut rng, &grid);
        let goal = GoalRegion {
            center: random_free_point(&mut rng, &grid),
            radius: grid.cell_size,
        };
        let directions = if terrain % 2 == 0 { 4 } else { 8 };
        let gens =
            PfGenerators::build(&grid, &BasisKind::Indicator, directions).expect("generators");
        let Ok(prepared) = pf::prepare(&gens, &grid, start, &goal, StartDensity::UniformFree)
        else {
            continue;
        };
        let slip = slippery(gens.generators());
        let problem = LpProblem {
            generators: &slip,
            ..prepared.problem(&gens, 1.0)
        };
        assert_eq!(ssp::structure(&problem), Structure::Stochastic);
        let exact = lp::solve(&problem, &settings(LpSolver::Exact)).expect("exact");
        let clarabel = lp::solve(&problem, &settings(LpSolver::Clarabel)).expect("clarabel");
        assert_eq!(exact.report.solver, SolverUsed::PolicyIteration);
        assert!(exact.report.iterations >= 1);
        assert_certified("policy iteration", &exact);
        assert_certified("clarabel", &clarabel);
        let (a, b) = (exact.report.objective, clarabel.report.objective);
        assert!(
            (a - b).abs() <= TOLERANCE * a,
            "terrain {terrain}: {a} vs {b}"
        );
        // Slipping never helps: the stochastic optimum costs at least the deterministic one.
        let det = lp::solve(&prepared.problem(&gens, 1.0), &settings(LpSolver::Exact))
            .expect("deterministic");
        assert!(a >= det.report.objective * (1.0 - 1e-12));
        compared += 1;
    }
    assert!(compared >= 5, "only {compared} reachable cases");
}

#[test]
fn the_certificate_rejects_a_perturbed_solution() {
    let scenario = pf_planner::scenarios::by_name("pits").expect("scenario");
    let grid = PlanningGrid::from_map(&scenario.map, &scenario.traversability, 32).expect("grid");
    let gens = PfGenerators::build(&grid, &BasisKind::Indicator, 8).expect("generators");
    let prepared = pf::prepare(
        &gens,
        &grid,
        scenario.start,
        &scenario.goal,
        StartDensity::PointMass,
    )
    .expect("prepared");
    let problem = prepared.problem(&gens, 1.0);
    let sol = lp::solve(&problem, &settings(LpSolver::Exact)).expect("solved");
    assert!(certify(&problem, &sol.flux, &sol.potential).holds());
    // Too much flux: the mass balance breaks.
    let more: Vec<Vec<f64>> = sol
        .flux
        .iter()
        .map(|z| z.iter().map(|v| v * 1.001).collect())
        .collect();
    let cert = certify(&problem, &more, &sol.potential);
    assert!(!cert.holds() && cert.primal_residual > 1e-4, "{cert:?}");
    // A potential raised above the cost-to-go somewhere: a Bellman inequality breaks.
    let start_fn = (0..prepared.start.len())
        .find(|&i| prepared.start[i] > 0.0)
        .expect("start mass");
    let mut raised = sol.potential.clone();
    raised[start_fn] *= 1.01;
    let cert = certify(&problem, &sol.flux, &raised);
    assert!(!cert.holds() && cert.dual_residual > 1e-4, "{cert:?}");
}

#[test]
fn generators_with_negative_mass_are_left_to_clarabel() {
    let grid = PlanningGrid::from_parts([0.0, 0.0], 1.0, 6, 1, vec![0.5; 6], vec![false; 6])
        .expect("grid");
    let gens = PfGenerators::build(&grid, &BasisKind::Indicator, 4).expect("generators");
    let goal = GoalRegion {
        center: grid.cell_center(5, 0),
        radius: 0.0,
    };
    let prepared = pf::prepare(
        &gens,
        &grid,
        grid.cell_center(0, 0),
        &goal,
        StartDensity::PointMass,
    )
    .expect("prepared");
    // Overshoot: 1.1 of the mass moves east and −0.1 stays (a negative transition).
    let mut odd = gens.generators().clone();
    let n = odd.basis.len();
    let columns = (0..n)
        .map(|i| {
            odd.generators[0]
                .column(i)
                .map(|(j, v)| (j, 1.1 * v))
                .collect()
        })
        .collect();
    odd.generators[0] = SparseMatrix::from_columns(n, columns);
    let problem = LpProblem {
        generators: &odd,
        ..prepared.problem(&gens, 1.0)
    };
    assert!(matches!(
        ssp::structure(&problem),
        Structure::General { .. }
    ));
    assert!(ssp::solve(&problem, pf_planner::deadline::Deadline::NONE)
        .expect("no error")
        .is_none());
    let sol = lp::solve(&problem, &settings(LpSolver::Exact)).expect("Clarabel fallback");
    assert_eq!(sol.report.solver, SolverUsed::Clarabel);
}

#[test]
fn exact_solver_equals_dijkstra_at_256_cells() {
    let scenario = pf_planner::scenarios::by_name("c_shape").expect("scenario");
    let grid = PlanningGrid::from_map(&scenario.map, &scenario.traversability, 256).expect("grid");
    let gens = PfGenerators::build(&grid, &BasisKind::Indicator, 8).expect("generators");
    let opts = PfOptions {
        start_density: StartDensity::UniformFree,
        ..PfOptions::default()
    };
    let sol = pf::solve(&gens, &grid, scenario.start, &scenario.goal, &opts).expect("solved");
    assert!(sol.lp.certificate.holds(), "{:?}", sol.lp.certificate);
    let reference = graph_value(&gens, &grid, &sol, 8);
    let rel = (sol.weighted_length - reference).abs() / reference;
    println!(
        "c_shape 256²: exact {} vs Dijkstra {reference} (rel {rel:.2e})",
        sol.weighted_length
    );
    assert!(rel < TOLERANCE, "rel {rel:.2e}");
    assert!(sol.outcome.reached_goal(), "{:?}", sol.outcome);
}

/// A passed deadline stops every exact path with `TimeLimit` naming the phase: Dijkstra
/// (Ulam's generators), policy iteration (stochastic generators) and the generator build.
#[test]
fn a_passed_deadline_stops_each_phase_with_a_time_limit_error() {
    use pf_planner::deadline::Deadline;
    use pf_planner::error::PlanError;
    let scenario = pf_planner::scenarios::by_name("c_shape").expect("scenario");
    let grid = PlanningGrid::from_map(&scenario.map, &scenario.traversability, 64).expect("grid");
    let passed = Deadline::after(std::time::Instant::now(), 0.0);
    let err = PfGenerators::build_until(&grid, &BasisKind::Indicator, 8, passed).unwrap_err();
    assert!(
        matches!(
            err,
            PlanError::TimeLimit {
                phase: "the generator build",
                ..
            }
        ),
        "{err}"
    );
    let gens = PfGenerators::build(&grid, &BasisKind::Indicator, 8).expect("generators");
    let opts = PfOptions {
        start_density: StartDensity::UniformFree,
        lp: LpSettings {
            time_limit_s: 0.0,
            ..settings(LpSolver::Exact)
        },
        ..PfOptions::default()
    };
    let err = pf::solve(&gens, &grid, scenario.start, &scenario.goal, &opts).unwrap_err();
    assert!(
        matches!(
            err,
            PlanError::TimeLimit {
                phase: "the LP solve (Dijkstra)",
                ..
            }
        ),
        "{err}"
    );
    let stochastic = slippery(gens.generators());
    let prepared = pf::prepare(
        &gens,
        &grid,
        scenario.start,
        &scenario.goal,
        StartDensity::UniformFree,
    )
    .expect("prepared");
    let problem = LpProblem {
        generators: &stochastic,
        ..prepared.problem(&gens, 1.0)
    };
    let err = lp::solve(&problem, &opts.lp).unwrap_err();
    assert!(
        matches!(
            err,
            PlanError::TimeLimit {
                phase: "the LP solve (policy iteration)",
                ..
            }
        ),
        "{err}"
    );
    // Without a limit the same problems solve.
    assert!(lp::solve(&problem, &settings(LpSolver::Exact)).is_ok());
}

/// A Gaussian belief about the start: the density is normalised over the free functions that
/// reach the goal and falls off with the distance from the believed start; the optimum is the
/// belief's expected cost-to-go (exact and Clarabel agree); a vanishing σ is the point mass.
#[test]
fn a_belief_start_costs_the_expected_cost_to_go() {
    let mut rng = ChaCha8Rng::seed_from_u64(20261128);
    let mut compared = 0;
    for _ in 0..12 {
        let grid = random_grid(&mut rng);
        let start = random_free_point(&mut rng, &grid);
        let goal = GoalRegion {
            center: random_free_point(&mut rng, &grid),
            radius: grid.cell_size,
        };
        let gens = PfGenerators::build(&grid, &BasisKind::Indicator, 8).expect("generators");
        let sigma_m = 2.0 * grid.cell_size;
        let belief = StartDensity::Belief { sigma_m };
        let Ok(prepared) = pf::prepare(&gens, &grid, start, &goal, belief) else {
            continue;
        };
        let problem = prepared.problem(&gens, 1.0);
        let exact = lp::solve(&problem, &settings(LpSolver::Exact)).expect("exact");
        if exact.report.status == LpStatus::Trivial {
            continue;
        }
        let basis = &gens.generators().basis;
        let mass: f64 = (0..prepared.start.len())
            .map(|i| prepared.start[i] * gens.mass_integrals()[i])
            .sum();
        assert!((mass - 1.0).abs() < 1e-12, "belief mass {mass}");
        let weighted: Vec<usize> = (0..prepared.start.len())
            .filter(|&i| prepared.start[i] > 0.0)
            .collect();
        assert!(
            weighted.len() > 1,
            "a belief spreads over several functions"
        );
        // Nearer functions carry more of the belief (equal masses on an indicator grid).
        let distance = |i: usize| {
            let c = basis.center(i);
            (c[0] - start[0]).hypot(c[1] - start[1])
        };
        for pair in weighted.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            if distance(a) + 1e-9 < distance(b)
                && gens.mass_integrals()[a] == gens.mass_integrals()[b]
            {
                assert!(prepared.start[a] >= prepared.start[b]);
            }
        }
        // Strong duality: the optimum is the belief-weighted cost-to-go Σ h₀ᵢ Vᵢ.
        let expected: f64 = weighted
            .iter()
            .map(|&i| prepared.start[i] * exact.potential[i])
            .sum();
        let objective = exact.report.objective;
        assert!(
            (objective - expected).abs() <= 1e-9 * objective.max(1.0),
            "{objective} vs expected cost-to-go {expected}"
        );
        let clarabel = lp::solve(&problem, &settings(LpSolver::Clarabel)).expect("clarabel");
        assert_certified("clarabel", &clarabel);
        assert!((clarabel.report.objective - objective).abs() <= TOLERANCE * objective);
        // σ → 0 is the point mass.
        let narrow = pf::prepare(
            &gens,
            &grid,
            start,
            &goal,
            StartDensity::Belief { sigma_m: 0.0 },
        )
        .expect("narrow");
        let point =
            pf::prepare(&gens, &grid, start, &goal, StartDensity::PointMass).expect("point");
        assert_eq!(narrow.start, point.start);
        compared += 1;
    }
    assert!(compared >= 5, "only {compared} reachable cases");
}
