//! The condensed MPC QP ([`QpData`], `min ½uᵀPu + qᵀu s.t. Au ≤ b`) as an OSQP problem, for the
//! MPC benchmark's solver comparison.
use super::mpc_oracle::QpData;

/// OSQP with the given absolute/relative tolerance and solution polishing.
pub fn osqp_problem(qp: &QpData, eps: f64) -> Result<osqp::Problem, osqp::SetupError> {
    let n = qp.n;
    // p_dense is column-major and symmetric, so its columns are also its rows.
    let dense: Vec<Vec<f64>> = qp.p_dense.chunks(n).map(<[f64]>::to_vec).collect();
    let p = osqp::CscMatrix::from(&dense).into_upper_tri();
    let a = osqp::CscMatrix {
        nrows: qp.m,
        ncols: n,
        indptr: qp.a_colptr.clone().into(),
        indices: qp.a_rowval.clone().into(),
        data: qp.a_nzval.clone().into(),
    };
    let lower = vec![f64::NEG_INFINITY; qp.m];
    let settings = osqp::Settings::default()
        .verbose(false)
        .eps_abs(eps)
        .eps_rel(eps)
        .max_iter(20_000)
        .polish(true);
    osqp::Problem::new(p, &qp.q, a, &lower, &qp.b, &settings)
}
