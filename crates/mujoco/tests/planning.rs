//! A planner through a MuJoCo scene (feature `mujoco`): iLQR on the slider of `scenes/slider.xml`
//! (with one substep per plant step, exactly a discrete double integrator) reaches the optimal cost
//! of the Riccati recursion, computed here by hand.
#![cfg(feature = "mujoco")]

use nalgebra::{DMatrix, DVector};
use ndarray::Array2;
use tandem_models::PlantModel;
use tandem_mujoco::MujocoPlant;
use tandem_planners::{Ilqr, IlqrConfig, Objective};

#[test]
fn ilqr_through_mujoco_matches_riccati() {
    let path = format!("{}/tests/scenes/slider.xml", env!("CARGO_MANIFEST_DIR"));
    let model = PlantModel::new(MujocoPlant::from_xml(path, 1).unwrap());
    // x' = x + h v', v' = v + h u / m (semi-implicit Euler, h = 0.01, m = 2).
    let (h, m) = (0.01, 2.0);
    let a = DMatrix::from_row_slice(2, 2, &[1.0, h, 0.0, 1.0]);
    let b = DMatrix::from_row_slice(2, 1, &[h * h / m, h / m]);
    let q = DMatrix::from_diagonal(&DVector::from_vec(vec![10.0, 1.0]));
    let r = DMatrix::from_element(1, 1, 0.01);
    let qf = &q * 10.0;
    let horizon = 30;
    // Riccati: P_T = Qf; K = (R + BᵀPB)⁻¹ BᵀPA; P = Q + AᵀPA − AᵀPB K.
    let mut p = qf.clone();
    for _ in 0..horizon {
        let bpb = &r + b.transpose() * &p * &b;
        let k = bpb.try_inverse().unwrap() * b.transpose() * &p * &a;
        p = &q + a.transpose() * &p * &a - a.transpose() * &p * &b * k;
    }
    let x0 = DVector::from_vec(vec![0.3, -0.2]);
    let optimal = (x0.transpose() * &p * &x0)[0];

    let (q2, r2, qf2) = (q.clone(), r[(0, 0)], qf.clone());
    let objective = Objective::new(2, 1, move |x, u| {
        let x = DVector::from_column_slice(x);
        (x.transpose() * &q2 * &x)[0] + r2 * u[0] * u[0]
    })
    .with_terminal(move |x| {
        let x = DVector::from_column_slice(x);
        (x.transpose() * &qf2 * &x)[0]
    });
    let ilqr = Ilqr::new(IlqrConfig::default()).unwrap();
    let sol = ilqr
        .solve(
            &model,
            &objective,
            x0.as_slice(),
            &Array2::zeros((horizon, 1)),
        )
        .unwrap();
    // The plan stays inside ctrlrange [-4, 4], where MuJoCo's dynamics are exactly linear.
    assert!(sol.actions.iter().all(|u| u.abs() < 4.0));
    assert!(
        (sol.cost - optimal).abs() < 1e-6 * optimal,
        "iLQR {} vs Riccati {optimal}",
        sol.cost
    );
}
