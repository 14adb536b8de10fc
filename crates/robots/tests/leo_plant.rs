//! The planar Leo-like biped stands, falls and walks plausibly under hand-written policies.

use nalgebra::DVector;
use tandem_dynamics::rigid_plant::{Overrides, RigidPlantConfig};
use tandem_dynamics::Plant;
use tandem_robots::leo::*;

fn run(
    policy: Option<BipedTestPolicy>,
    x0: DVector<f64>,
    seconds: f64,
    overrides: &Overrides,
) -> (Vec<DVector<f64>>, f64) {
    let plant = leo_plant(RigidPlantConfig::default(), overrides).unwrap();
    let steps = (seconds / plant.dt()).round() as usize;
    let mut x = x0;
    let mut traj = vec![x.clone()];
    let mut min_h = f64::INFINITY;
    for t in 0..steps {
        let u = match &policy {
            Some(p) => p.act(&plant, t as f64 * plant.dt(), &x),
            None => DVector::zeros(6),
        };
        x = plant.step(&x, &u);
        assert!(
            x.iter().all(|z| z.is_finite()),
            "state diverged at step {t}"
        );
        min_h = plant
            .contact_heights(x.as_slice())
            .into_iter()
            .fold(min_h, f64::min);
        traj.push(x.clone());
    }
    (traj, min_h)
}

#[test]
fn biped_has_seven_actuators_and_ten_dof() {
    let p = leo_plant(RigidPlantConfig::default(), &Overrides::default()).unwrap();
    assert_eq!(p.model().nv(), 10);
    assert_eq!(p.action_dim(), 6);
    assert_eq!(p.actuators().len(), 7);
    assert_eq!(p.action_joints(), MOTOR_JOINTS);
    assert_eq!(
        p.model().joint_names(),
        [
            "boom_x",
            "boom_z",
            "torso_pitch",
            "left_hip",
            "left_knee",
            "left_ankle",
            "right_hip",
            "right_knee",
            "right_ankle",
            "shoulder"
        ]
    );
}

#[test]
fn biped_stands() {
    let p = leo_plant(RigidPlantConfig::default(), &Overrides::default()).unwrap();
    let x0 = standing_state(p.model());
    let (traj, min_h) = run(
        Some(BipedTestPolicy::stand()),
        x0.clone(),
        3.0,
        &Overrides::default(),
    );
    let xe = traj.last().unwrap();
    eprintln!(
        "stand: final boom x {:.4} z {:.4} pitch {:.4}; min contact height {min_h:.5}",
        xe[0], xe[1], xe[2]
    );
    assert!(
        (xe[1] - x0[1]).abs() < 0.01,
        "hip height drifted to {}",
        xe[1]
    );
    assert!(xe[2].abs() < 0.1 && xe[0].abs() < 0.05);
    assert!(min_h > -0.003, "penetration {min_h}");
}

#[test]
fn biped_falls_without_gaining_energy() {
    let p = leo_plant(RigidPlantConfig::default(), &Overrides::default()).unwrap();
    let mut x0 = standing_state(p.model());
    // Torso leaning forward with the legs still vertical; motors off.
    x0[2] = 0.3;
    x0[3] = -0.3;
    x0[6] = -0.3;
    let (traj, min_h) = run(None, x0, 3.0, &Overrides::default());
    let e: Vec<f64> = traj.iter().map(|x| p.total_energy(x.as_slice())).collect();
    let max_gain = e
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f64::NEG_INFINITY, f64::max);
    let xe = traj.last().unwrap();
    eprintln!("fall: energy {:.4} -> {:.4}, max gain per step {max_gain:.2e}, hip z {:.4}, min contact height {min_h:.5}", e[0], e.last().unwrap(), xe[1]);
    assert!(xe[1] < HIP_HEIGHT - 0.05, "did not fall: hip at {}", xe[1]);
    // No energy gain (the contact spring stores a little energy; allow 1 mJ per step).
    assert!(max_gain < 1e-3, "energy gained {max_gain}");
    assert!(e.last().unwrap() < &e[0]);
    assert!(min_h > -0.005, "penetration {min_h}");
}

#[test]
fn biped_walks() {
    // The same hand-written gait on the idealized and on the true biped (p0, Table I).
    for (name, ov) in [
        ("idealized", Overrides::default()),
        ("true", leo_true_overrides()),
    ] {
        let p = leo_plant(RigidPlantConfig::default(), &ov).unwrap();
        let x0 = standing_state(p.model());
        let (traj, min_h) = run(Some(BipedTestPolicy::walk()), x0, 10.0, &ov);
        let min_z = traj.iter().map(|x| x[1]).fold(f64::INFINITY, f64::min);
        let max_pitch = traj.iter().map(|x| x[2].abs()).fold(0.0, f64::max);
        let xe = traj.last().unwrap();
        eprintln!(
            "walk ({name}): {:.3} m in 10 s, min hip z {min_z:.3}, max |pitch| {max_pitch:.3}, min contact height {min_h:.5}",
            xe[0]
        );
        assert!(xe[0] > 0.3, "{name}: walked only {} m", xe[0]);
        assert!(min_z > 0.18, "{name}: fell, hip at {min_z}");
        assert!(max_pitch < 0.5, "{name}: torso pitched to {max_pitch}");
        assert!(min_h > -0.005, "{name}: penetration {min_h}");
    }
}

#[test]
fn skeleton_of_the_standing_biped_has_its_dimensions() {
    let p = leo_plant(RigidPlantConfig::default(), &Overrides::default()).unwrap();
    let x = standing_state(p.model());
    let lines = skeleton(p.model(), &x.as_slice()[..10]).unwrap();
    assert_eq!(lines.len(), 6);
    let len = |a: [f64; 2], b: [f64; 2]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    for leg in [&lines[2], &lines[4]] {
        // Vertical leg: hip above knee above ankle by the link lengths.
        assert!((len(leg[0], leg[1]) - THIGH).abs() < 1e-12);
        assert!((len(leg[1], leg[2]) - SHIN).abs() < 1e-12);
        assert!((leg[0][0] - leg[2][0]).abs() < 1e-12);
    }
    // Flat feet on the ground (the standing state's 0.2 mm sinkage).
    for foot in [&lines[3], &lines[5]] {
        assert!(foot.iter().all(|p| p[1].abs() < 1e-3), "{foot:?}");
        assert!((len(foot[0], foot[1]) - (TOE[0] - HEEL[0])).abs() < 1e-12);
    }
    // The heights agree with the plant's contact points (heel, toe, head, hand).
    let h = p.contact_heights(x.as_slice());
    assert!((lines[3][0][1] - h[0]).abs() < 1e-12 && (lines[3][1][1] - h[1]).abs() < 1e-12);
    assert!((lines[0][1][1] - h[7]).abs() < 1e-12 && (lines[1][1][1] - h[8]).abs() < 1e-12);
    assert!(skeleton(p.model(), &[0.0; 3]).is_err());
}
