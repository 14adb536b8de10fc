//! p3's 2R leg against the analytic two-link formulas: foot kinematics, Jacobian, inverse
//! kinematics, energy conservation of the free leg and the idealized/true pair.

use nalgebra::DVector;
use tandem_dynamics::actuators::Actuator;
use tandem_dynamics::rigid::{rnea, Data};
use tandem_dynamics::rigid_plant::{RigidBodyPlant, RigidPlantConfig};
use tandem_dynamics::Plant;
use tandem_robots::leg2r::{
    joint_motors, leg2r_model, leg2r_plant, FootKinematics, Leg2RParams, SHANK, THIGH,
};

/// Configurations across the workspace, both knee bends and the straight leg included.
const CONFIGS: [[f64; 2]; 6] = [
    [0.0, 0.0],
    [-0.6, 1.2],
    [0.4, 0.3],
    [1.2, 2.5],
    [-1.4, 0.05],
    [0.9, -0.7],
];

/// The textbook foot position of a planar 2R leg hanging from its hip, angles about +y.
fn analytic_foot(q: [f64; 2]) -> [f64; 2] {
    let (l1, l2) = (0.15, 0.15);
    [
        -l1 * q[0].sin() - l2 * (q[0] + q[1]).sin(),
        -l1 * q[0].cos() - l2 * (q[0] + q[1]).cos(),
    ]
}

/// Its Jacobian, differentiated by hand.
fn analytic_jacobian(q: [f64; 2]) -> [[f64; 2]; 2] {
    let (l1, l2) = (0.15, 0.15);
    let c12 = (q[0] + q[1]).cos();
    let s12 = (q[0] + q[1]).sin();
    [
        [-l1 * q[0].cos() - l2 * c12, -l2 * c12],
        [l1 * q[0].sin() + l2 * s12, l2 * s12],
    ]
}

fn foot() -> FootKinematics {
    FootKinematics::new(&leg2r_model().unwrap()).unwrap()
}

#[test]
fn the_urdf_gives_the_papers_lengths_and_our_limits() {
    let f = foot();
    assert_eq!(f.lengths(), [THIGH, SHANK]);
    assert_eq!((THIGH, SHANK), (0.15, 0.15));
    let m = leg2r_model().unwrap();
    assert!((m.total_mass() - 0.55).abs() < 1e-12);
    for motor in joint_motors(&m).unwrap() {
        assert_eq!((motor.peak_torque, motor.no_load_speed), (3.0, 40.0));
    }
}

#[test]
fn foot_position_matches_the_two_link_formula() {
    let f = foot();
    for q in CONFIGS {
        let p = f.position(&q);
        let e = analytic_foot(q);
        assert!(
            (p[0] - e[0]).abs() < 1e-14 && (p[1] - e[1]).abs() < 1e-14,
            "{q:?}: {p:?} vs {e:?}"
        );
    }
}

#[test]
fn foot_velocity_is_j_qdot_and_the_derivative_of_the_position() {
    let f = foot();
    let qdot = [1.7, -2.3];
    for q in CONFIGS {
        let j = f.jacobian(&q);
        let ja = analytic_jacobian(q);
        let (p, v) = f.state(&q, &qdot);
        assert_eq!(p, f.position(&q));
        // Central differences of the position along q̇: d/dt p(q + t q̇) at t = 0.
        let h = 1e-6;
        let plus = f.position(&[q[0] + h * qdot[0], q[1] + h * qdot[1]]);
        let minus = f.position(&[q[0] - h * qdot[0], q[1] - h * qdot[1]]);
        for r in 0..2 {
            for c in 0..2 {
                assert!((j[r][c] - ja[r][c]).abs() < 1e-14, "{q:?} J[{r}][{c}]");
            }
            let jv = ja[r][0] * qdot[0] + ja[r][1] * qdot[1];
            let fd = (plus[r] - minus[r]) / (2.0 * h);
            assert!((v[r] - jv).abs() < 1e-13, "{q:?}: {v:?}");
            assert!((v[r] - fd).abs() < 1e-8, "{q:?}: {} vs {fd}", v[r]);
        }
    }
}

#[test]
fn inverse_kinematics_is_knee_forward_and_refuses_unreachable_points() {
    let f = foot();
    for q in CONFIGS.into_iter().filter(|q| q[1] >= 0.0) {
        let back = f.inverse(f.position(&q)).unwrap();
        assert!(
            (back[0] - q[0]).abs() < 1e-9 && (back[1] - q[1]).abs() < 1e-9,
            "{q:?} -> {back:?}"
        );
    }
    // The other knee bend reaches the same point; the inverse returns the knee-forward one.
    let back = f.inverse(analytic_foot([0.9, -0.7])).unwrap();
    assert!(back[1] > 0.0);
    let p = f.position(&back);
    let e = analytic_foot([0.9, -0.7]);
    assert!((p[0] - e[0]).abs() < 1e-12 && (p[1] - e[1]).abs() < 1e-12);
    assert_eq!(f.inverse([0.0, -0.31]), None);
    assert_eq!(f.inverse([f64::NAN, -0.2]), None);
    // J⁻¹ ṗ inverts J q̇; the straight knee is singular.
    let q = [-0.6, 1.2];
    let pdot = [0.4, -0.3];
    let qdot = f.joint_velocity(&q, pdot).unwrap();
    let (_, v) = f.state(&q, &qdot);
    assert!((v[0] - pdot[0]).abs() < 1e-13 && (v[1] - pdot[1]).abs() < 1e-13);
    assert_eq!(f.joint_velocity(&[0.3, 0.0], pdot), None);
}

#[test]
fn the_free_leg_conserves_energy_at_500_hz_over_an_episode() {
    // No torque, no friction, no hard stops: a double pendulum released from a bent pose.
    let params = Leg2RParams {
        joint_limits: None,
        ..Leg2RParams::idealized()
    };
    let p = leg2r_plant(&params).unwrap();
    let mut x = DVector::from_vec(vec![-1.0, 1.6, 0.0, 0.0]);
    let u = DVector::zeros(2);
    let e0 = p.energy(x.as_slice());
    let mut drift: f64 = 0.0;
    let mut swing: f64 = 0.0;
    for _ in 0..1000 {
        x = p.step(&x, &u);
        drift = drift.max((p.energy(x.as_slice()) - e0).abs());
        swing = swing.max(x[2].abs());
    }
    // It really moved (the hip reaches about 11 rad/s), and the energy (−0.42 J, zero at the hip's
    // height) stayed put: RK4 at 0.5 ms drifts by 5e-10 J over the 2 s (1e-7 J at one 2 ms step).
    assert!(swing > 5.0, "{swing}");
    assert!(drift < 1e-8, "energy drift {drift} J");
}

#[test]
fn the_real_leg_is_heavier_and_dissipates() {
    let ideal = leg2r_plant(&Leg2RParams::idealized()).unwrap();
    let real = leg2r_plant(&Leg2RParams::real()).unwrap();
    assert!((real.model().total_mass() - 0.61).abs() < 1e-12);
    // The same torque accelerates the heavier leg less, and friction drains a free swing.
    let x = DVector::from_vec(vec![-0.6, 1.2, 0.0, 0.0]);
    let u = DVector::from_vec(vec![0.0, 1.0]);
    assert!(ideal.step(&x, &u)[3] > real.step(&x, &u)[3]);
    let mut xr = x.clone();
    let zero = DVector::zeros(2);
    let e0 = real.total_energy(xr.as_slice());
    for _ in 0..500 {
        xr = real.step(&xr, &zero);
    }
    assert!(real.total_energy(xr.as_slice()) < e0 - 1e-3);
}

#[test]
fn torques_are_clipped_to_the_peak_at_rest() {
    let p = leg2r_plant(&Leg2RParams::idealized()).unwrap();
    let x = DVector::from_vec(vec![-0.6, 1.2, 0.0, 0.0]);
    let at_limit = p.step(&x, &DVector::from_vec(vec![3.0, -3.0]));
    let beyond = p.step(&x, &DVector::from_vec(vec![30.0, -30.0]));
    assert_eq!(at_limit, beyond);
}

#[test]
fn full_torque_cannot_drive_the_joints_far_past_the_no_load_speed() {
    // Without hard stops, full torque on both joints for 2 s. The motors' back-EMF envelope
    // keeps the joints within reach of 40 rad/s (inertial coupling lets the knee overshoot it a
    // little); ideal 3 N m sources on the same leg spin it up several times faster.
    let top_speed = |plant: &RigidBodyPlant| {
        let mut x = DVector::from_vec(vec![-0.6, 1.2, 0.0, 0.0]);
        let u = DVector::from_vec(vec![3.0, 3.0]);
        let mut top: f64 = 0.0;
        for _ in 0..1000 {
            x = plant.step(&x, &u);
            top = top.max(x[2].abs()).max(x[3].abs());
        }
        top
    };
    let params = Leg2RParams {
        joint_limits: None,
        ..Leg2RParams::idealized()
    };
    let motors = top_speed(&leg2r_plant(&params).unwrap());
    let config = RigidPlantConfig {
        control_period: params.control_period,
        internal_step: params.internal_step,
    };
    let mut ideal = RigidBodyPlant::new(leg2r_model().unwrap(), config).unwrap();
    for j in ["hip", "knee"] {
        ideal = ideal
            .with_actuator(j, Actuator::Torque { limit: 3.0 })
            .unwrap();
    }
    let sources = top_speed(&ideal);
    eprintln!("top joint speed: motors {motors:.1} rad/s, ideal sources {sources:.1} rad/s");
    assert!(motors > 35.0 && motors < 60.0, "{motors}");
    assert!(sources > 2.0 * motors, "{sources}");
}

#[test]
fn holding_still_takes_the_gravity_torque_of_inverse_dynamics() {
    // τ = RNEA(q, 0, 0) keeps the leg where it is; by hand, the hip carries both links' weight
    // at their horizontal lever arms, the knee the shank's.
    let p = leg2r_plant(&Leg2RParams::idealized()).unwrap();
    let model = p.model();
    let q = [-0.6, 1.2];
    let mut data = Data::new(model);
    let tau = rnea(model, &mut data, &q, &[0.0, 0.0], &[0.0, 0.0]).clone();
    let g = 9.81;
    let shank_x = -THIGH * q[0].sin() - 0.075 * (q[0] + q[1]).sin();
    let thigh_x = -0.075 * q[0].sin();
    // Torque about +y of a weight −m g e_z at lever x is +m g x; holding it needs the opposite.
    let hip = -g * (0.35 * thigh_x + 0.20 * shank_x);
    let knee = -g * 0.20 * (-0.075 * (q[0] + q[1]).sin());
    assert!(
        (tau[0] - hip).abs() < 1e-12 && (tau[1] - knee).abs() < 1e-12,
        "{tau}"
    );
    let x0 = DVector::from_vec(vec![q[0], q[1], 0.0, 0.0]);
    let mut x = x0.clone();
    for _ in 0..250 {
        x = p.step(&x, &tau);
    }
    assert!((&x - &x0).abs().max() < 1e-9, "{x}");
}

#[test]
fn analytic_linearization_matches_finite_differences_inside_and_on_the_motor_envelope() {
    for params in [Leg2RParams::idealized(), Leg2RParams::real()] {
        let p = leg2r_plant(&params).unwrap();
        // Inside the envelope; the knee on its back-EMF bound (3 N m asked at 20 rad/s); the hip
        // against its hard stop.
        let cases = [
            ([-0.6, 1.2, 1.5, -2.0], [0.4, -0.3]),
            ([-0.6, 1.2, 0.5, 20.0], [0.4, 3.0]),
            ([-1.6, 1.2, -0.5, 1.0], [0.1, 0.2]),
        ];
        for (x, u) in cases {
            let (x, u) = (DVector::from_vec(x.to_vec()), DVector::from_vec(u.to_vec()));
            let (a, b) = p.linearize(&x, &u);
            let (fa, fb) = p.linearize_fd(&x, &u);
            // Central differences carry about 5e-6 of relative error against the stiff hard stop.
            let scale = fa.abs().max().max(1.0);
            assert!((&a - &fa).abs().max() < 1e-5 * scale, "{x}: A\n{a}\n{fa}");
            assert!(
                (&b - &fb).abs().max() < 1e-5 * fb.abs().max().max(1.0),
                "{x}: B"
            );
        }
    }
}
