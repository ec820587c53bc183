//! Kinematics and leg dynamics of the URDF model against independent references.
#![allow(clippy::needless_range_loop)] // parallel indexing of joints, axes and legs
use crate::common;

use quad_controller::{Leg, ModelError, RobotModel};

/// SplitMix64: a tiny explicit-seed generator for test configurations.
struct SplitMix(u64);

impl SplitMix {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }

    /// A configuration inside the leg's workspace: knee bent, away from singularities, foot at
    /// least 5 cm below the hip axis in the leg plane (the IK's domain).
    fn leg_q(&mut self) -> [f64; 3] {
        loop {
            let q = [
                self.uniform(-0.6, 0.6),
                self.uniform(-0.8, 1.8),
                self.uniform(-2.5, -0.6),
            ];
            let below_hip = -0.2 * q[1].cos() - 0.2 * (q[1] + q[2]).cos();
            if below_hip < -0.05 {
                return q;
            }
        }
    }
}

#[test]
fn urdf_masses_limits_and_foot_radius() {
    let model = common::model();
    assert!(
        (model.total_mass() - 12.0).abs() < 1e-9,
        "mass {}",
        model.total_mass()
    );
    let effort = model.effort_limits();
    for leg in 0..4 {
        assert_eq!(&effort[3 * leg..3 * leg + 3], &[25.0, 25.0, 35.0]);
    }
    assert!((model.foot_radius() - 0.02).abs() < 1e-12);
    assert_eq!(model.link_lengths(Leg::RL), (0.2, 0.2));
}

#[test]
fn forward_kinematics_matches_hand_computed_poses() {
    let model = common::model();
    for leg in Leg::ALL {
        let hip = model.hip_position_body(leg);
        let side = 0.08 * leg.side_sign();
        let straight = model.foot_position_body(leg, [0.0, 0.0, 0.0]);
        let expected = [hip[0], hip[1] + side, -0.4];
        // Hip flexed 90°: the straight leg points backwards (rotation about +y).
        let flexed = model.foot_position_body(leg, [0.0, std::f64::consts::FRAC_PI_2, 0.0]);
        let expected_flexed = [hip[0] - 0.4, hip[1] + side, 0.0];
        // Abducted 90°: the leg points sideways; +x rotation takes −z to +y.
        let abducted = model.foot_position_body(leg, [std::f64::consts::FRAC_PI_2, 0.0, 0.0]);
        let expected_abducted = [hip[0], hip[1] + 0.4, side];
        for i in 0..3 {
            assert!(
                (straight[i] - expected[i]).abs() < 1e-12,
                "{leg:?} straight"
            );
            assert!(
                (flexed[i] - expected_flexed[i]).abs() < 1e-12,
                "{leg:?} flexed"
            );
            assert!(
                (abducted[i] - expected_abducted[i]).abs() < 1e-12,
                "{leg:?} abducted"
            );
        }
    }
}

#[test]
fn jacobian_matches_finite_differences() {
    let model = common::model();
    let mut rng = SplitMix(7);
    let h = 1e-6;
    for _ in 0..50 {
        for leg in Leg::ALL {
            let q = rng.leg_q();
            let jac = model.foot_jacobian_body(leg, q);
            for j in 0..3 {
                let (mut qp, mut qm) = (q, q);
                qp[j] += h;
                qm[j] -= h;
                let (fp, fm) = (
                    model.foot_position_body(leg, qp),
                    model.foot_position_body(leg, qm),
                );
                for r in 0..3 {
                    let fd = (fp[r] - fm[r]) / (2.0 * h);
                    assert!(
                        (fd - jac[r][j]).abs() < 1e-8,
                        "{leg:?} J[{r}][{j}] {} vs {fd}",
                        jac[r][j]
                    );
                }
            }
        }
    }
}

#[test]
fn inverse_kinematics_inverts_forward_kinematics() {
    let model = common::model();
    let mut rng = SplitMix(11);
    for _ in 0..200 {
        for leg in Leg::ALL {
            let q = rng.leg_q();
            let p = model.foot_position_body(leg, q);
            let solved = model
                .inverse_kinematics(leg, p)
                .expect("reachable by construction");
            for j in 0..3 {
                assert!(
                    (solved[j] - q[j]).abs() < 1e-9,
                    "{leg:?} q {q:?} → {solved:?}"
                );
            }
        }
    }
}

#[test]
fn inverse_kinematics_rejects_unreachable_targets() {
    let model = common::model();
    let far = model.inverse_kinematics(Leg::FR, [0.183, -0.127, -0.45]);
    assert!(
        matches!(far, Err(ModelError::Unreachable { leg: Leg::FR, .. })),
        "{far:?}"
    );
    let nan = model.inverse_kinematics(Leg::FL, [f64::NAN, 0.0, -0.3]);
    assert!(matches!(nan, Err(ModelError::Unreachable { .. })));
}

fn is_spd(m: &[[f64; 3]; 3]) -> bool {
    // Sylvester's criterion on the leading principal minors.
    let d1 = m[0][0];
    let d2 = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    let d3 = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    d1 > 0.0 && d2 > 0.0 && d3 > 0.0
}

#[test]
fn mass_matrix_is_symmetric_positive_definite() {
    let model = common::model();
    let mut rng = SplitMix(3);
    for _ in 0..100 {
        for leg in Leg::ALL {
            let m = model.leg_mass_matrix(leg, rng.leg_q());
            for r in 0..3 {
                for c in 0..3 {
                    assert!((m[r][c] - m[c][r]).abs() < 1e-12);
                }
            }
            assert!(is_spd(&m), "{m:?}");
        }
    }
}

#[test]
fn mass_matrix_diagonal_matches_hand_computed_knee_inertia() {
    // The knee sees only the calf (0.2 kg, CoM 0.1 m, I_yy = 0.2/12·(0.016² + 0.2²)) and the foot
    // (0.05 kg point-like sphere 0.2 m away, I = 0.4·0.05·0.02²) rotating about the knee axis.
    let model = common::model();
    let calf = 0.2 * 0.1 * 0.1 + 0.2 / 12.0 * (0.016f64.powi(2) + 0.04);
    let foot = 0.05 * 0.04 + 0.4 * 0.05 * 0.0004;
    let m = model.leg_mass_matrix(Leg::FL, [0.3, 0.7, -1.4]);
    assert!(
        (m[2][2] - (calf + foot)).abs() < 1e-6,
        "{} vs {}",
        m[2][2],
        calf + foot
    );
}

#[test]
fn gravity_torque_is_the_gradient_of_potential_energy() {
    // V(q) = m_total g z_com(q) from the composite CoM (an independent code path).
    let model = common::model();
    let mut rng = SplitMix(5);
    let g = 9.81;
    for _ in 0..20 {
        let mut q_all = [0.0; 12];
        for leg in 0..4 {
            q_all[3 * leg..3 * leg + 3].copy_from_slice(&rng.leg_q());
        }
        for leg in Leg::ALL {
            let l = leg.index();
            let q = [q_all[3 * l], q_all[3 * l + 1], q_all[3 * l + 2]];
            let bias = model.leg_bias(leg, q, [0.0; 3], [0.0, 0.0, -g]);
            for j in 0..3 {
                let h = 1e-6;
                let (mut qp, mut qm) = (q_all, q_all);
                qp[3 * l + j] += h;
                qm[3 * l + j] -= h;
                let zp = model.composite_inertia(&qp).1[2];
                let zm = model.composite_inertia(&qm).1[2];
                let dv = model.total_mass() * g * (zp - zm) / (2.0 * h);
                assert!(
                    (dv - bias[j]).abs() < 1e-6,
                    "{leg:?} joint {j}: {} vs {dv}",
                    bias[j]
                );
            }
        }
    }
}

#[test]
fn coriolis_terms_are_energy_consistent() {
    // Without gravity, q̇ᵀ h(q, q̇) = ½ q̇ᵀ Ṁ q̇ (skew-symmetry of Ṁ − 2C), with Ṁ by finite
    // differences of M along q̇; and h is quadratic in q̇.
    let model = common::model();
    let mut rng = SplitMix(9);
    for _ in 0..50 {
        for leg in Leg::ALL {
            let q = rng.leg_q();
            let dq = [
                rng.uniform(-5.0, 5.0),
                rng.uniform(-5.0, 5.0),
                rng.uniform(-5.0, 5.0),
            ];
            let h = model.leg_bias(leg, q, dq, [0.0; 3]);
            let h2 = model.leg_bias(leg, q, dq.map(|v| 2.0 * v), [0.0; 3]);
            let eps = 1e-6;
            let qp = [q[0] + eps * dq[0], q[1] + eps * dq[1], q[2] + eps * dq[2]];
            let qm = [q[0] - eps * dq[0], q[1] - eps * dq[1], q[2] - eps * dq[2]];
            let (mp, mm) = (
                model.leg_mass_matrix(leg, qp),
                model.leg_mass_matrix(leg, qm),
            );
            let mut power = 0.0;
            let mut half_mdot = 0.0;
            for r in 0..3 {
                power += dq[r] * h[r];
                assert!((h2[r] - 4.0 * h[r]).abs() < 1e-9 * (1.0 + h[r].abs()));
                for c in 0..3 {
                    half_mdot += 0.5 * dq[r] * (mp[r][c] - mm[r][c]) / (2.0 * eps) * dq[c];
                }
            }
            assert!(
                (power - half_mdot).abs() < 1e-6 * (1.0 + power.abs()),
                "{power} vs {half_mdot}"
            );
        }
    }
}

#[test]
fn urdf_missing_a_leg_is_a_clear_error() {
    let text = common::urdf_text();
    // Drop every element of the RL leg.
    let start = text.find("<!-- RL leg -->").expect("RL section");
    let end = text.find("</robot>").expect("end");
    let without_rl = format!("{}{}", &text[..start], &text[end..]);
    match common::our_robot_with_urdf(&without_rl)
        .as_ref()
        .map_err(ModelError::innermost)
    {
        Err(ModelError::Missing(what)) => assert!(what.contains("RL_foot"), "{what}"),
        other => panic!("expected Missing, got {other:?}"),
    }
    let renamed = text.replace("FL_knee_joint", "FL_elbow_joint");
    match common::our_robot_with_urdf(&renamed)
        .as_ref()
        .map_err(ModelError::innermost)
    {
        Err(ModelError::Missing(what)) => assert!(what.contains("FL_knee_joint"), "{what}"),
        other => panic!("expected Missing, got {other:?}"),
    }
    let no_sphere = text.replace("<collision><origin xyz=\"0 0 0\" rpy=\"0 0 0\"/><geometry><sphere radius=\"0.02\"/></geometry></collision>", "");
    match common::our_robot_with_urdf(&no_sphere) {
        Err(ModelError::Config { reason, .. }) => {
            assert!(reason.contains("foot radius"), "{reason}")
        }
        other => panic!("expected a config error, got {other:?}"),
    }
    assert!(matches!(
        common::our_robot_with_urdf("<robot")
            .as_ref()
            .map_err(ModelError::innermost),
        Err(ModelError::Parse(_))
    ));
    let missing_file =
        RobotModel::from_config_file(std::path::Path::new("/nonexistent/robot.toml"));
    assert!(matches!(missing_file, Err(ModelError::Io { .. })));
    let negative_mass = text.replacen("<mass value=\"5.0\"/>", "<mass value=\"-5.0\"/>", 1);
    assert!(matches!(
        common::our_robot_with_urdf(&negative_mass)
            .as_ref()
            .map_err(ModelError::innermost),
        Err(ModelError::InvalidValue(_))
    ));
}

#[test]
fn repository_robot_config_gives_the_same_model_from_its_file_and_from_its_texts() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robot/quadruped.toml");
    let from_config = RobotModel::from_config_file(&path).expect("robot/quadruped.toml loads");
    let from_texts = common::model();
    assert_eq!(from_config.total_mass(), from_texts.total_mass());
    assert_eq!(from_config.effort_limits(), from_texts.effort_limits());
    assert_eq!(from_config.foot_radius(), from_texts.foot_radius());
    // The controller's default standing height is our robot's configured one.
    assert_eq!(
        from_config.stand_height(),
        quad_controller::ControllerConfig::default().body_height
    );
    for leg in Leg::ALL {
        let q = [0.2, 0.7, -1.4];
        assert_eq!(
            from_config.foot_position_body(leg, q),
            from_texts.foot_position_body(leg, q)
        );
    }
}
