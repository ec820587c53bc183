use super::*;

#[test]
fn zero_mass_properties_merge_is_identity() {
    let mut a = MassProperties {
        mass: 0.0,
        com: Vector3::zeros(),
        inertia_com: Matrix3::zeros(),
    };
    let b = MassProperties {
        mass: 2.0,
        com: Vector3::new(0.1, 0.0, 0.0),
        inertia_com: Matrix3::identity() * 0.01,
    };
    a.merge(&b, &Transform::identity());
    assert!((a.mass - 2.0).abs() < 1e-15);
    assert!((a.com.x - 0.1).abs() < 1e-15);
    assert!((a.inertia_com[(0, 0)] - 0.01).abs() < 1e-15);
}
