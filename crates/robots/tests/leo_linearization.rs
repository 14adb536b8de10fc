//! The Leo-like biped's analytical linearization (ABA derivatives through contact, friction and
//! the DC motors) against finite differences, in contact and in the air: `RigidBodyPlant`'s
//! linearization on the papers' largest robot.

use nalgebra::DVector;
use tandem_dynamics::actuators::JointFriction;
use tandem_dynamics::rigid::Model;
use tandem_dynamics::rigid_plant::{RigidBodyPlant, RigidPlantConfig};
use tandem_dynamics::Plant;

/// Largest entry-wise difference relative to the largest entry (at least 1).
fn rel_err(a: &nalgebra::DMatrix<f64>, b: &nalgebra::DMatrix<f64>) -> f64 {
    (a - b).abs().max() / a.abs().max().max(1.0)
}

/// Central differences of one control period with step `h` on every component.
fn jacobians_fd(
    p: &RigidBodyPlant,
    x: &DVector<f64>,
    u: &DVector<f64>,
    h: f64,
) -> (nalgebra::DMatrix<f64>, nalgebra::DMatrix<f64>) {
    let col = |xp: DVector<f64>, xm: DVector<f64>, up: DVector<f64>, um: DVector<f64>| {
        (p.step(&xp, &up) - p.step(&xm, &um)) / (2.0 * h)
    };
    let mut a = nalgebra::DMatrix::zeros(x.len(), x.len());
    let mut b = nalgebra::DMatrix::zeros(x.len(), u.len());
    for i in 0..x.len() {
        let (mut xp, mut xm) = (x.clone(), x.clone());
        xp[i] += h;
        xm[i] -= h;
        a.set_column(i, &col(xp, xm, u.clone(), u.clone()));
    }
    for j in 0..u.len() {
        let (mut up, mut um) = (u.clone(), u.clone());
        up[j] += h;
        um[j] -= h;
        b.set_column(j, &col(x.clone(), x.clone(), up, um));
    }
    (a, b)
}

/// Analytical vs finite-difference Jacobians of one control period; returns the two errors
/// against the plant's own oracle ([`RigidBodyPlant::linearize_fd`], `h = 1e-6`).
fn check_linearization(p: &RigidBodyPlant, x: &DVector<f64>, u: &DVector<f64>) -> (f64, f64) {
    let (a, b) = p.linearize(x, u);
    let (fa, fb) = p.linearize_fd(x, u);
    assert_eq!((a.shape(), b.shape()), (fa.shape(), fb.shape()));
    (rel_err(&fa, &a), rel_err(&fb, &b))
}

/// The Leo-like biped (true configuration: viscous joint friction; plus Coulomb friction on the
/// knees) at `x`, with a mid-range voltage on every motor.
fn biped_case(
    x_of: impl Fn(&Model) -> DVector<f64>,
) -> (RigidBodyPlant, DVector<f64>, DVector<f64>) {
    use tandem_robots::leo::{leo_plant, leo_true_overrides};
    let p = leo_plant(RigidPlantConfig::default(), &leo_true_overrides())
        .unwrap()
        .with_friction(
            "left_knee",
            JointFriction {
                viscous: 0.03,
                coulomb: 0.02,
                stiction_velocity: 0.05,
            },
        )
        .unwrap();
    let x = x_of(p.model());
    let u = DVector::from_vec(vec![1.5, -2.0, 0.7, -1.0, 2.5, -0.4]);
    (p, x, u)
}

#[test]
fn biped_linearization_in_contact_matches_finite_differences() {
    use tandem_robots::leo::standing_state;
    let (p, x, u) = biped_case(|m| {
        let mut x = standing_state(m);
        let n = m.nv();
        x[1] -= 0.001; // pressed 1.2 mm into the ground
        for (i, q) in [
            (3, 0.05),
            (4, -0.08),
            (5, 0.03),
            (6, -0.04),
            (7, 0.06),
            (9, 0.2),
        ] {
            x[i] = q;
        }
        // Sliding forwards 3 cm/s, pitching slowly, limbs moving.
        for (i, v) in [
            (0, 0.03),
            (2, 0.1),
            (3, 0.2),
            (4, -0.3),
            (8, 0.25),
            (9, 0.5),
        ] {
            x[n + i] = v;
        }
        x
    });
    let heights = p.contact_heights(x.as_slice());
    assert!(
        heights.iter().filter(|h| **h < 0.0).count() >= 3,
        "feet in contact: {heights:?}"
    );
    // The stiff contact (k = 2e4 N/m on sub-kilogram links) makes the h = 1e-6 oracle's
    // truncation error visible (1.4e-3 on ∂/∂boom_z, about 8e-6 relative); it shrinks as h²
    // towards the analytical value, so the oracle here is h = 1e-7, and h = 1e-6 must be about
    // 100 times further off (a plain FD bug would not converge).
    let (a, b) = p.linearize(&x, &u);
    let (fa6, _) = p.linearize_fd(&x, &u);
    let (fa7, fb7) = jacobians_fd(&p, &x, &u, 1e-7);
    let (ea, eb) = (rel_err(&fa7, &a), rel_err(&fb7, &b));
    assert!(ea < 1e-6 && eb < 1e-6, "A err {ea:e}, B err {eb:e}");
    let ea6 = rel_err(&fa6, &a);
    assert!(ea < ea6 / 20.0, "h = 1e-7: {ea:e}, h = 1e-6: {ea6:e}");
}

#[test]
fn biped_linearization_in_the_air_matches_finite_differences() {
    use tandem_robots::leo::standing_state;
    let (p, x, u) = biped_case(|m| {
        let mut x = standing_state(m);
        let n = m.nv();
        x[1] += 0.3;
        for (i, q) in [
            (2, 0.2),
            (3, 0.5),
            (4, -0.9),
            (5, 0.3),
            (6, -0.4),
            (7, 0.6),
            (9, 1.0),
        ] {
            x[i] = q;
        }
        for i in 0..n {
            x[n + i] = 0.3 * ((i as f64) - 4.5).sin();
        }
        x
    });
    assert!(p.contact_heights(x.as_slice()).iter().all(|h| *h > 0.05));
    let (ea, eb) = check_linearization(&p, &x, &u);
    assert!(ea < 1e-6 && eb < 1e-6, "A err {ea:e}, B err {eb:e}");
}
