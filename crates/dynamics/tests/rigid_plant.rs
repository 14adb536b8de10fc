//! `RigidBodyPlant` against analytic truths: DC-motor terminal speed, energy conservation,
//! viscous decay, overrides and configuration errors.

use nalgebra::DVector;
use tandem_dynamics::actuators::{Actuator, DcMotor, JointFriction};
use tandem_dynamics::rigid::Model;
use tandem_dynamics::rigid_plant::{
    LimitSpring, Overrides, RigidBodyPlant, RigidPlantConfig, RigidPlantError,
};
use tandem_dynamics::{check_dims, Plant};

/// A pendulum about `axis` (bob 0.3 m below the pivot, 0.5 kg).
fn pendulum(axis: &str) -> Model {
    Model::from_urdf_str(&format!(
        r#"<robot name="p"><link name="base"/>
        <joint name="pivot" type="continuous"><parent link="base"/><child link="bob"/>
          <axis xyz="{axis}"/></joint>
        <link name="bob"><inertial><origin xyz="0 0 -0.3"/><mass value="0.5"/>
          <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
        </robot>"#
    ))
    .unwrap()
}

fn cfg() -> RigidPlantConfig {
    RigidPlantConfig {
        control_period: 0.02,
        internal_step: 1e-3,
    }
}

#[test]
fn dc_motor_reaches_its_no_load_speed() {
    // Axis along gravity: no gravity torque; the motor alone sets the speed U / (K G).
    let m = DcMotor {
        armature: 0.0,
        ..DcMotor::default()
    };
    let p = RigidBodyPlant::new(pendulum("0 0 1"), cfg())
        .unwrap()
        .with_actuator("pivot", Actuator::Motor(m))
        .unwrap();
    assert_eq!((p.state_dim(), p.action_dim()), (2, 1));
    let mut x = DVector::from_vec(vec![0.0, 0.0]);
    let u = DVector::from_vec(vec![3.0]);
    for _ in 0..200 {
        x = p.step(&x, &u);
    }
    let expected = 3.0 / (m.torque_constant * m.gear);
    assert!(
        (x[1] - expected).abs() < 1e-6 * expected,
        "{} vs {expected}",
        x[1]
    );
}

#[test]
fn free_pendulum_conserves_energy_and_viscous_friction_dissipates_it() {
    let p = RigidBodyPlant::new(pendulum("0 1 0"), cfg()).unwrap();
    assert_eq!(p.action_dim(), 0);
    let x0 = DVector::from_vec(vec![1.2, 0.0]);
    let e0 = p.energy(x0.as_slice());
    let mut x = x0.clone();
    for _ in 0..250 {
        x = p.step(&x, &DVector::zeros(0));
    }
    assert!((p.energy(x.as_slice()) - e0).abs() < 1e-8 * e0.abs());
    let damped = RigidBodyPlant::new(pendulum("0 1 0"), cfg())
        .unwrap()
        .with_friction(
            "pivot",
            JointFriction {
                viscous: 0.05,
                ..JointFriction::default()
            },
        )
        .unwrap();
    let mut x = x0;
    let mut last = damped.energy(x.as_slice());
    for _ in 0..250 {
        x = damped.step(&x, &DVector::zeros(0));
        let e = damped.energy(x.as_slice());
        assert!(e <= last + 1e-12);
        last = e;
    }
    assert!(last < e0 - 0.1 * (e0 - (-0.5 * 9.81 * 0.3)));
}

#[test]
fn overrides_make_a_true_system() {
    let base = || {
        RigidBodyPlant::new(pendulum("0 1 0"), cfg())
            .unwrap()
            .with_actuator("pivot", Actuator::Torque { limit: 1.0 })
            .unwrap()
    };
    let ov = Overrides {
        link_mass: [("bob".to_string(), 0.8)].into_iter().collect(),
        viscous_friction: Some(0.02),
        ..Overrides::default()
    };
    let ideal = base();
    let real = base().with_overrides(&ov).unwrap();
    assert!((real.model().total_mass() - 0.8).abs() < 1e-12);
    assert!((ideal.model().total_mass() - 0.5).abs() < 1e-12);
    let x = DVector::from_vec(vec![0.5, 1.0]);
    let u = DVector::from_vec(vec![0.3]);
    let (a, b) = (ideal.step(&x, &u), real.step(&x, &u));
    assert!((a - b).norm() > 1e-4);
    // Torque limit: 5 N m is clipped to 1 N m.
    assert_eq!(
        ideal.step(&x, &DVector::from_vec(vec![5.0])),
        ideal.step(&x, &DVector::from_vec(vec![1.0]))
    );
    assert!(check_dims(&ideal, &[0.0, 0.0], &[f64::NAN]).is_err());
}

#[test]
fn bad_configuration_is_an_error() {
    let e = RigidBodyPlant::new(
        pendulum("0 1 0"),
        RigidPlantConfig {
            control_period: 0.0,
            internal_step: 1e-3,
        },
    )
    .unwrap_err();
    assert!(matches!(e, RigidPlantError::Config(_)));
    let p = RigidBodyPlant::new(pendulum("0 1 0"), cfg()).unwrap();
    assert!(matches!(
        p.with_actuator("elbow", Actuator::Torque { limit: 1.0 }),
        Err(RigidPlantError::UnknownJoint(_))
    ));
    let p = RigidBodyPlant::new(pendulum("0 1 0"), cfg()).unwrap();
    let ov = Overrides {
        link_mass: [("nope".to_string(), 1.0)].into_iter().collect(),
        ..Overrides::default()
    };
    assert!(matches!(
        p.with_overrides(&ov),
        Err(RigidPlantError::UnknownLink(_))
    ));
    let p = RigidBodyPlant::new(pendulum("0 1 0"), cfg()).unwrap();
    let ov = Overrides {
        link_mass: [("bob".to_string(), -1.0)].into_iter().collect(),
        ..Overrides::default()
    };
    assert!(matches!(
        p.with_overrides(&ov),
        Err(RigidPlantError::Config(_))
    ));
    let toml_like: Result<Overrides, _> = serde_json::from_str(r#"{"link_mas": {}}"#);
    assert!(toml_like.is_err(), "unknown override keys are rejected");
}

/// Largest entry-wise difference relative to the largest entry (at least 1).
fn rel_err(a: &nalgebra::DMatrix<f64>, b: &nalgebra::DMatrix<f64>) -> f64 {
    (a - b).abs().max() / a.abs().max().max(1.0)
}

/// Analytical vs finite-difference Jacobians of one control period; returns the two errors
/// against the plant's own oracle ([`RigidBodyPlant::linearize_fd`], `h = 1e-6`).
fn check_linearization(p: &RigidBodyPlant, x: &DVector<f64>, u: &DVector<f64>) -> (f64, f64) {
    let (a, b) = p.linearize(x, u);
    let (fa, fb) = p.linearize_fd(x, u);
    assert_eq!((a.shape(), b.shape()), (fa.shape(), fb.shape()));
    (rel_err(&fa, &a), rel_err(&fb, &b))
}

#[test]
fn arm_linearization_matches_finite_differences_and_respects_clipping() {
    let model = Model::from_urdf_file(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/fixtures/pinocchio/arm7.urdf"
    ))
    .unwrap();
    let motor = DcMotor {
        torque_max: 5.0,
        ..DcMotor::default()
    };
    let mut p = RigidBodyPlant::new(model, cfg()).unwrap();
    for j in ["a1", "a2", "a3"] {
        p = p
            .with_actuator(j, Actuator::Torque { limit: 20.0 })
            .unwrap();
    }
    p = p
        .with_actuator("a4", Actuator::Motor(motor))
        .unwrap()
        .with_actuator(
            "a5",
            Actuator::Pd(tandem_dynamics::actuators::PdController {
                kp: 30.0,
                kd: 1.0,
                target: 0.2,
                torque_max: 50.0,
            }),
        )
        .unwrap()
        .with_friction(
            "a6",
            JointFriction {
                viscous: 0.05,
                coulomb: 0.1,
                stiction_velocity: 0.5,
            },
        )
        .unwrap();
    let x = DVector::from_vec(vec![
        0.3, -0.5, 1.1, -1.2, 0.4, 0.9, -2.0, 0.5, -1.0, 0.8, 0.3, -0.7, 0.6, -0.9,
    ]);
    let u = DVector::from_vec(vec![3.0, -8.0, 1.0, 4.0]);
    let (ea, eb) = check_linearization(&p, &x, &u);
    assert!(ea < 1e-6 && eb < 1e-6, "A err {ea:e}, B err {eb:e}");
    // A torque beyond its limit has no effect at the margin: its column of B is zero.
    let clipped = DVector::from_vec(vec![30.0, -8.0, 1.0, 4.0]);
    let (_, b) = p.linearize(&x, &clipped);
    assert_eq!(b.column(0).abs().max(), 0.0);
    assert!(b.column(1).abs().max() > 1e-3);
}

/// A pendulum about the vertical (no gravity torque) with the range [-0.5, 0.5] rad.
fn limited_pendulum() -> Model {
    Model::from_urdf_str(
        r#"<robot name="p"><link name="base"/>
        <joint name="pivot" type="revolute"><parent link="base"/><child link="bob"/>
          <axis xyz="0 0 1"/><limit lower="-0.5" upper="0.5" effort="5" velocity="10"/></joint>
        <link name="bob"><inertial><origin xyz="0.3 0 0"/><mass value="0.5"/>
          <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
        </robot>"#,
    )
    .unwrap()
}

#[test]
fn compliant_position_limit_bounces_the_joint_back_without_energy_gain() {
    let x0 = DVector::from_vec(vec![0.3, 2.0]);
    let none = DVector::zeros(0);
    // Off by default: the joint sails through its range.
    let free = RigidBodyPlant::new(limited_pendulum(), cfg()).unwrap();
    let mut x = x0.clone();
    for _ in 0..25 {
        x = free.step(&x, &none);
    }
    assert!((x[0] - (0.3 + 2.0 * 0.5)).abs() < 1e-9, "free: {}", x[0]);
    // Enabled: an undamped spring returns the joint with the same speed (elastic bounce) and
    // total energy (kinetic + limit spring) is conserved; a damped one loses energy monotonically.
    let spring = LimitSpring {
        stiffness: 100.0,
        damping: 0.0,
    };
    // 1 ms control period, so that the sampled peak is within 3e-4 of the true one.
    let fine = RigidPlantConfig {
        control_period: 1e-3,
        internal_step: 1e-3,
    };
    let p = RigidBodyPlant::new(limited_pendulum(), fine)
        .unwrap()
        .with_position_limits(spring)
        .unwrap();
    let e0 = p.total_energy(x0.as_slice());
    let (mut x, mut max_q) = (x0.clone(), f64::MIN);
    for _ in 0..500 {
        x = p.step(&x, &none);
        max_q = max_q.max(x[0]);
        let e = p.total_energy(x.as_slice());
        // The spring force has a kink at the limit, where RK4 drops to low order: 1e-4, not
        // the 1e-8 of smooth motion.
        assert!((e - e0).abs() < 1e-4 * e0, "{e} vs {e0}");
    }
    // Overshoot: ½ I ω² = ½ k d² with I = 0.5 · 0.3² + 0.001.
    let inertia = 0.5 * 0.09 + 0.001;
    let d = 2.0 * (inertia / spring.stiffness).sqrt();
    assert!(
        (max_q - 0.5 - d).abs() < 0.01 * d,
        "overshoot {} vs {d}",
        max_q - 0.5
    );
    assert!(x[0] < 0.5 && (x[1] + 2.0).abs() < 2e-4, "bounced back: {x}");
    let damped = RigidBodyPlant::new(limited_pendulum(), fine)
        .unwrap()
        .with_position_limits(LimitSpring::default())
        .unwrap();
    let mut x = x0.clone();
    let mut last = damped.total_energy(x.as_slice());
    for _ in 0..500 {
        x = damped.step(&x, &none);
        let e = damped.total_energy(x.as_slice());
        assert!(e <= last + 1e-12);
        last = e;
    }
    assert!(x[1] < 0.0 && x[1] > -2.0, "damped bounce: {x}");
    // Linearization inside the limit spring (motor on the joint) agrees with finite differences.
    let driven = RigidBodyPlant::new(limited_pendulum(), cfg())
        .unwrap()
        .with_actuator("pivot", Actuator::Torque { limit: 5.0 })
        .unwrap()
        .with_position_limits(LimitSpring::default())
        .unwrap();
    let xin = DVector::from_vec(vec![0.52, 0.3]);
    let (ea, eb) = check_linearization(&driven, &xin, &DVector::from_vec(vec![0.5]));
    assert!(ea < 1e-6 && eb < 1e-6, "A err {ea:e}, B err {eb:e}");
    let bad = LimitSpring {
        stiffness: -1.0,
        damping: 0.0,
    };
    assert!(matches!(
        RigidBodyPlant::new(limited_pendulum(), cfg())
            .unwrap()
            .with_position_limits(bad),
        Err(RigidPlantError::Config(_))
    ));
}
