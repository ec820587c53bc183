//! Assembly of the sparse QP (CSC pattern and values of P and A, q and b) from the per-step
//! model; see the module documentation of [`super`] for the formulation.

use nalgebra::{Matrix3, Vector3};

use super::model::terrain_frame;
use super::{ConvexMpc, MpcInput, COST_SCALE, MPC_STATES, NS, RATE_ROWS, ROWS_PER_FOOT};

impl ConvexMpc {
    /// The Θ and ω costs as blocks on the c variables (`c_diag`, `c_off`, `c_linear`): per step
    /// k, `Θ_{k+1} = E_k [c_k; c_{k+1}]` with `E_k = [I − G_k, G_k]` and
    /// `ω_{k+1} = F_k [c_k; c_{k+1}]` with `F_k = [−N_k, N_k]`, so the cost
    /// `(Θ_{k+1} − Θ_ref)ᵀ Q_Θ (…) + (ω_{k+1} − ω_ref)ᵀ Q_ω (…)` adds `2(EᵀQ_ΘE + FᵀQ_ωF)` to P and
    /// `−2(EᵀQ_Θ Θ_ref + FᵀQ_ω ω_ref)` to q; the known c_0 moves its part into q of c_1.
    fn rotational_cost(&mut self, input: &MpcInput<'_>, c0: &Vector3<f64>) {
        let n = self.params.horizon;
        let w = self.params.q_weights.map(|w| COST_SCALE * w);
        let q_theta = Matrix3::from_diagonal(&Vector3::new(w[0], w[1], w[2]));
        let q_omega = Matrix3::from_diagonal(&Vector3::new(w[6], w[7], w[8]));
        for k in 0..n {
            let g = self.stages.theta_of_c[k];
            let nk = self.stages.omega_of_c[k];
            let keep = Matrix3::identity() - g;
            let omega_part = nk.transpose() * q_omega * nk;
            let h00 = (keep.transpose() * q_theta * keep + omega_part) * 2.0;
            let h01 = (keep.transpose() * q_theta * g - omega_part) * 2.0;
            let h11 = (g.transpose() * q_theta * g + omega_part) * 2.0;
            let reference = &input.reference[k];
            let theta_ref = q_theta * Vector3::new(reference[0], reference[1], reference[2]);
            let omega_ref = q_omega * Vector3::new(reference[6], reference[7], reference[8]);
            let linear_k = (keep.transpose() * theta_ref - nk.transpose() * omega_ref) * -2.0;
            let linear_next = (g.transpose() * theta_ref + nk.transpose() * omega_ref) * -2.0;
            // c_{k+1} is variable j = k; c_k is variable j = k − 1 (known for k = 0).
            self.c_diag[k] = h11;
            self.c_linear[k] = linear_next;
            if k == 0 {
                self.c_linear[0] += h01.transpose() * c0;
            } else {
                self.c_diag[k - 1] += h00;
                self.c_linear[k - 1] += linear_k;
                self.c_off[k] = h01;
            }
        }
    }

    /// Fill the sparse QP (CSC pattern and values of P and A, q, b) for the current model and
    /// `self.blocks`. Variables, stage by stage: the stance forces of step k (terrain frame
    /// t₁, t₂, n, in units of m·g), then c and a of step k + 1. Rows: the ω and v dynamics of
    /// steps 0..N−1 (zero cone), then 6 inequality rows per force block (nonnegative cone).
    fn assemble_sparse(&mut self, input: &MpcInput<'_>) {
        let n = self.params.horizon;
        let dt = self.params.dt;
        let half_dt = 0.5 * dt;
        let scale = self.force_scale;
        let force_to_v = dt / self.params.mass * scale;
        let n_eq = NS * n;
        let frame = terrain_frame(input.terrain_normal);
        self.terrain_frame = frame;
        let mu = self.params.mu;
        let r_diag = 2.0 * COST_SCALE * self.params.r_weight * scale * scale;
        let q_w = self.params.q_weights.map(|w| COST_SCALE * w);
        let x0 = &input.x0;
        let a0 = [0, 1, 2].map(|j| x0[3 + j] + half_dt * x0[9 + j]);
        let omega0 = Vector3::new(x0[6], x0[7], x0[8]);
        let c0 = Vector3::new(x0[0], x0[1], x0[2]) + self.stages.rate_map[0] * omega0 * half_dt;
        self.rotational_cost(input, &c0);
        self.p_colptr.clear();
        self.p_rowval.clear();
        self.p_values.clear();
        self.q_values.clear();
        self.a_colptr.clear();
        self.a_rowval.clear();
        self.a_values.clear();
        self.p_colptr.push(0);
        self.a_colptr.push(0);
        let mut col = 0;
        let mut block = 0;
        let mut prev_c_col = 0;
        let mut prev_a_col = 0;
        for k in 0..n {
            let row0 = NS * k;
            while block < self.blocks.len() && self.blocks[block].0 == k {
                let b_omega = self.stages.b_omega[k][self.blocks[block].1] * frame;
                let ineq0 = n_eq + ROWS_PER_FOOT * block;
                for axis in 0..3 {
                    for i in 0..3 {
                        self.a_rowval.push(row0 + i);
                        self.a_values.push(-b_omega[(i, axis)] * scale);
                    }
                    for i in 0..3 {
                        self.a_rowval.push(row0 + 3 + i);
                        self.a_values.push(-force_to_v * frame[(i, axis)]);
                    }
                    let rows: &[(usize, f64)] = match axis {
                        0 => &[(0, 1.0), (1, -1.0)],
                        1 => &[(2, 1.0), (3, -1.0)],
                        _ => &[(0, -mu), (1, -mu), (2, -mu), (3, -mu), (4, -1.0), (5, 1.0)],
                    };
                    for &(r, value) in rows {
                        self.a_rowval.push(ineq0 + r);
                        self.a_values.push(value);
                    }
                    self.a_colptr.push(self.a_rowval.len());
                    self.p_rowval.push(col);
                    self.p_values.push(r_diag);
                    self.p_colptr.push(self.p_rowval.len());
                    self.q_values.push(0.0);
                    col += 1;
                }
                block += 1;
            }
            // c_{k+1}: ω rows of step k (N_k), k + 1 (−N_k − N_{k+1}) and k + 2 (N_{k+1}).
            let this_c_col = col;
            let omega_of_c = &self.stages.omega_of_c;
            let next = omega_of_c[(k + 1).min(n - 1)];
            let coefficients = [omega_of_c[k], -(omega_of_c[k] + next), next];
            for j in 0..3 {
                for (step, coefficient) in (k..n).zip(&coefficients) {
                    for &i in RATE_ROWS[j] {
                        self.a_rowval.push(NS * step + i);
                        self.a_values.push(coefficient[(i, j)]);
                    }
                }
                self.a_colptr.push(self.a_rowval.len());
                // The Θ and ω cost blocks on c are full 3×3 (the z row of N_k and G_k mixes in
                // x and y).
                if k > 0 {
                    for i in 0..3 {
                        self.p_rowval.push(prev_c_col + i);
                        self.p_values.push(self.c_off[k][(i, j)]);
                    }
                }
                for i in 0..=j {
                    self.p_rowval.push(this_c_col + i);
                    self.p_values.push(self.c_diag[k][(i, j)]);
                }
                self.p_colptr.push(self.p_rowval.len());
                self.q_values.push(self.c_linear[k][j]);
                col += 1;
            }
            prev_c_col = this_c_col;
            // a_{k+1}: v rows of steps k, k + 1, k + 2 (second difference / dt).
            let this_a_col = col;
            for j in 0..3 {
                for (step, c) in [(k, 1.0), (k + 1, -2.0), (k + 2, 1.0)] {
                    if step < n {
                        self.a_rowval.push(NS * step + 3 + j);
                        self.a_values.push(c / dt);
                    }
                }
                self.a_colptr.push(self.a_rowval.len());
                // Cost of p_s = (a_s + a_{s−1})/2 and v_s = (a_s − a_{s−1})/dt for s = k + 1
                // and s = k + 2.
                let (qp, qv) = (q_w[3 + j], q_w[9 + j]);
                let same = 2.0 * (0.25 * qp + qv / (dt * dt));
                let cross = 2.0 * (0.25 * qp - qv / (dt * dt));
                if k > 0 {
                    self.p_rowval.push(prev_a_col + j);
                    self.p_values.push(cross);
                }
                self.p_rowval.push(col);
                self.p_values
                    .push(if k + 1 < n { 2.0 * same } else { same });
                self.p_colptr.push(self.p_rowval.len());
                let reference = &input.reference[k];
                let (p_ref, v_ref) = (reference[3 + j], reference[9 + j]);
                let mut linear = -qp * p_ref - 2.0 * qv / dt * v_ref;
                if k == 0 {
                    linear += qp * 0.5 * a0[j] - 2.0 * qv / (dt * dt) * a0[j];
                }
                if k + 1 < n {
                    let next = &input.reference[k + 1];
                    linear += -qp * next[3 + j] + 2.0 * qv / dt * next[9 + j];
                }
                self.q_values.push(linear);
                col += 1;
            }
            prev_a_col = this_a_col;
        }
        // b: gravity in the v rows; step 0 gets `ω_0 + N_0 c_0` and `v_0 + a_0/dt`, step 1
        // `−N_0 c_0` and `−a_0/dt` (the known c_0 and a_0 of the differences).
        self.b_values.clear();
        let g = input.x0[MPC_STATES - 1];
        for _ in 0..n {
            self.b_values.extend_from_slice(&[0.0; NS - 1]);
            self.b_values.push(-dt * g);
        }
        let omega_from_c0 = self.stages.omega_of_c[0] * c0;
        for i in 0..3 {
            self.b_values[i] += omega0[i] + omega_from_c0[i];
            self.b_values[3 + i] += x0[9 + i] + a0[i] / dt;
            if n > 1 {
                self.b_values[NS + i] -= omega_from_c0[i];
                self.b_values[NS + 3 + i] -= a0[i] / dt;
            }
        }
        let (f_min, f_max) = (self.params.f_min / scale, self.params.f_max / scale);
        for _ in 0..self.blocks.len() {
            self.b_values
                .extend_from_slice(&[0.0, 0.0, 0.0, 0.0, -f_min, f_max]);
        }
    }

    /// Fill the per-step model, the force blocks (stance legs of each step) and the sparse QP
    /// for a validated input; false when no leg is in stance over the whole horizon (no QP).
    pub(super) fn build_qp(&mut self, input: &MpcInput<'_>) -> bool {
        self.stages.update(&self.params, &self.inertia_body, input);
        self.blocks.clear();
        for (k, contacts) in input.contacts.iter().enumerate() {
            for (leg, &stance) in contacts.iter().enumerate() {
                if stance {
                    self.blocks.push((k, leg));
                }
            }
        }
        if self.blocks.is_empty() {
            return false;
        }
        self.assemble_sparse(input);
        true
    }
}
