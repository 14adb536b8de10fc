//! `RigidBodyPlant` against analytic truths: DC-motor terminal speed, energy conservation,
//! viscous decay, overrides and configuration errors.

use nalgebra::DVector;
use tandem_dynamics::actuators::{Actuator, DcMotor, JointFriction};
use tandem_dynamics::rigid::Model;
use tandem_dynamics::rigid_plant::{Overrides, RigidBodyPlant, RigidPlantConfig, RigidPlantError};
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
