//! GPS's LQR initial controller (`TvlgController::init_lqr`) against hand-solved LQR and a
//! batch least-squares solution of the same problem.

use nalgebra::{DMatrix, DVector};
use tandem_planners::{InitLqr, PlanError, TvlgController};

/// One joint at non-GPS indices (angle 3, velocity 1) in a state of 5, other entries arbitrary.
fn one_joint(gain: f64) -> InitLqr {
    InitLqr {
        gains: vec![gain],
        stiffness: 2.0,
        stiffness_vel: 0.3,
        final_weight: 3.0,
        variance: 0.7,
        ..InitLqr::new(0.1, vec![3], vec![1])
    }
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + b.abs())
}

/// With `T = 2` the recursion solves by hand. The last step sees only its own cost:
/// `K = 0, k = 0, Σ = variance / final_weight`. The first sees the last's value
/// `w L_xx` through `F`, with `D = 1 + w s g² h² (h² + s_v)`: `Σ = variance / D`,
/// `K = −w s g h [h, h² + s_v] / D` on (angle, velocity), `k = w s g h (h q₀ + s_v v₀) / D`.
#[test]
fn two_steps_match_the_hand_solved_lqr() {
    let g = 1.7;
    let cfg = one_joint(g);
    let x0 = [0.7, -0.2, -2.0, 0.4, 5.0];
    let c = TvlgController::init_lqr(&cfg, &x0, 1, 2).unwrap();
    let (s, sv, w, h, v) = (
        cfg.stiffness,
        cfg.stiffness_vel,
        cfg.final_weight,
        cfg.dt,
        cfg.variance,
    );
    let (q0, v0) = (x0[3], x0[1]);
    let d = 1.0 + w * s * g * g * h * h * (h * h + sv);
    assert!(close(c.cov[1][(0, 0)], v / w, 1e-14), "{}", c.cov[1]);
    assert!(c.gains[1].iter().all(|&k| k == 0.0), "{}", c.gains[1]);
    assert!(c.offsets[1][0].abs() < 1e-15);
    assert!(close(c.cov[0][(0, 0)], v / d, 1e-14), "{}", c.cov[0]);
    let k = &c.gains[0];
    assert!(close(k[(0, 3)], -w * s * g * h * h / d, 1e-13), "{k}");
    assert!(
        close(k[(0, 1)], -w * s * g * h * (h * h + sv) / d, 1e-13),
        "{k}"
    );
    for i in [0, 2, 4] {
        assert_eq!(k[(0, i)], 0.0, "no gain on the unactuated entry {i}");
    }
    let k0 = w * s * g * h * (h * q0 + sv * v0) / d;
    assert!(
        close(c.offsets[0][0], k0, 1e-13),
        "{} vs {k0}",
        c.offsets[0][0]
    );
}

/// Two joints in GPS's own layout would be angles 0, 1 and velocities 2, 3; here they are
/// interleaved with unactuated entries. At rest at `x0` (zero velocities, no constant
/// acceleration) the controller's mean action is zero at every step: it holds `x0`.
#[test]
fn the_controller_holds_x0() {
    let cfg = InitLqr {
        gains: vec![0.8, 3.0],
        ..InitLqr::new(0.05, vec![0, 2], vec![4, 5])
    };
    let x0 = [0.3, 0.75, -1.1, 0.35, 0.0, 0.0];
    let c = TvlgController::init_lqr(&cfg, &x0, 2, 100).unwrap();
    let x = DVector::from_column_slice(&x0);
    for t in 0..100 {
        let u = c.mean(t, &x);
        assert!(u.amax() < 1e-12, "step {t}: {u}");
        // Nothing on the unactuated entries (the block of the pusher, say).
        for i in [1, 3] {
            assert_eq!(c.gains[t].column(i).amax(), 0.0, "step {t}, entry {i}");
        }
    }
    // Pushed off x0, it pulls back: a larger angle asks for a negative action.
    let mut off = x.clone();
    off[2] += 0.1;
    assert!(c.mean(0, &off)[1] < 0.0);
}

/// `variance` divides the whole cost, so `Σ` scales with it and `K`, `k` do not; a power of two
/// scales every rounding alike, so the scaling is exact.
#[test]
fn the_variance_scales_the_covariance_exactly() {
    let cfg = InitLqr {
        gains: vec![0.8, 3.0],
        acc: vec![0.1, -0.2],
        ..InitLqr::new(0.05, vec![0, 2], vec![4, 5])
    };
    let x0 = [0.3, 0.75, -1.1, 0.35, 0.1, 0.0];
    let a = TvlgController::init_lqr(&cfg, &x0, 2, 20).unwrap();
    let scaled = InitLqr {
        variance: 4.0 * cfg.variance,
        ..cfg.clone()
    };
    let b = TvlgController::init_lqr(&scaled, &x0, 2, 20).unwrap();
    for t in 0..20 {
        assert_eq!(b.cov[t], &a.cov[t] * 4.0, "step {t}");
        assert_eq!(b.gains[t], a.gains[t], "step {t}");
        assert_eq!(b.offsets[t], a.offsets[t], "step {t}");
    }
}

/// The controller is the optimum of its problem: from a state off `x0`, its mean actions rolled
/// out on the guessed dynamics equal the minimizer of the whole horizon's cost over the action
/// sequence, solved as one least-squares problem (with constant accelerations and a final
/// weight, so that every term of the recursion counts).
#[test]
fn the_controller_is_the_batch_optimum() {
    let cfg = InitLqr {
        gains: vec![0.8, 3.0],
        acc: vec![0.4, -0.7],
        final_weight: 5.0,
        variance: 2.0,
        ..InitLqr::new(0.1, vec![3, 0], vec![1, 4])
    };
    let (n, m, t_len) = (5, 2, 6);
    let x0 = [0.2, 0.0, 1.3, -0.5, 0.0];
    let c = TvlgController::init_lqr(&cfg, &x0, m, t_len).unwrap();
    // The guessed dynamics and cost, written out directly.
    let step = |x: &DVector<f64>, u: &DVector<f64>| {
        let mut y = DVector::zeros(n);
        for j in 0..m {
            let (p, v) = (cfg.positions[j], cfg.velocities[j]);
            let a = cfg.gains[j] * u[j] + cfg.acc[j];
            y[p] = x[p] + cfg.dt * x[v] + cfg.dt * cfg.dt * a;
            y[v] = x[v] + cfg.dt * a;
        }
        y
    };
    let mut l = DVector::zeros(n + m);
    for j in 0..m {
        l[cfg.positions[j]] = cfg.stiffness;
        l[cfg.velocities[j]] = cfg.stiffness * cfg.stiffness_vel;
        l[n + j] = 1.0;
    }
    let l = DMatrix::from_diagonal(&(l / cfg.variance));
    let start = DVector::from_column_slice(&[0.5, 0.3, -0.4, 0.1, -0.2]);
    // z_t = [x_t; u_t] is affine in the stacked actions U: columns by unit actions.
    let z_of = |us: &DVector<f64>| -> Vec<DVector<f64>> {
        let mut x = start.clone();
        (0..t_len)
            .map(|t| {
                let u = us.rows(t * m, m).into_owned();
                let mut z = DVector::zeros(n + m);
                z.rows_mut(0, n).copy_from(&x);
                z.rows_mut(n, m).copy_from(&u);
                x = step(&x, &u);
                z
            })
            .collect()
    };
    let base = z_of(&DVector::zeros(t_len * m));
    let mut z0 = DVector::zeros(n + m);
    z0.rows_mut(0, n).copy_from_slice(&x0);
    let (mut h, mut g) = (
        DMatrix::zeros(t_len * m, t_len * m),
        DVector::zeros(t_len * m),
    );
    let cols: Vec<Vec<DVector<f64>>> = (0..t_len * m)
        .map(|i| {
            let mut e = DVector::zeros(t_len * m);
            e[i] = 1.0;
            z_of(&e).iter().zip(&base).map(|(z, b)| z - b).collect()
        })
        .collect();
    for t in 0..t_len {
        let w = if t + 1 == t_len {
            cfg.final_weight
        } else {
            1.0
        };
        let a = DMatrix::from_fn(n + m, t_len * m, |r, i| cols[i][t][r]);
        h += a.transpose() * &l * &a * w;
        g += a.transpose() * &l * (&base[t] - &z0) * w;
    }
    let best = -h.cholesky().unwrap().solve(&g);
    let mut x = start.clone();
    for t in 0..t_len {
        let u = c.mean(t, &x);
        for j in 0..m {
            assert!(
                close(u[j], best[t * m + j], 1e-9),
                "step {t}, action {j}: {} vs {}",
                u[j],
                best[t * m + j]
            );
        }
        x = step(&x, &u);
    }
}

/// Settings that cannot make a controller are refused with their name, never a panic or NaN.
#[test]
fn bad_settings_are_named() {
    let ok = InitLqr::new(0.05, vec![0, 1], vec![2, 3]);
    let x0 = [0.0; 5];
    let err = |cfg: &InitLqr, x0: &[f64], m: usize, t: usize| -> String {
        let e: PlanError = TvlgController::init_lqr(cfg, x0, m, t).unwrap_err();
        e.to_string()
    };
    assert!(TvlgController::init_lqr(&ok, &x0, 2, 3).is_ok());
    for (bad, what) in [
        (
            InitLqr {
                variance: -1.0,
                ..ok.clone()
            },
            "variance",
        ),
        (
            InitLqr {
                variance: f64::NAN,
                ..ok.clone()
            },
            "variance",
        ),
        (
            InitLqr {
                dt: 0.0,
                ..ok.clone()
            },
            "dt",
        ),
        (
            InitLqr {
                final_weight: 0.0,
                ..ok.clone()
            },
            "final_weight",
        ),
        (
            InitLqr {
                stiffness: -0.5,
                ..ok.clone()
            },
            "stiffness",
        ),
        (
            InitLqr {
                gains: vec![1.0, 2.0, 3.0],
                ..ok.clone()
            },
            "gains",
        ),
        (
            InitLqr {
                acc: vec![f64::INFINITY, 0.0],
                ..ok.clone()
            },
            "acc",
        ),
        (
            InitLqr {
                positions: vec![0],
                ..ok.clone()
            },
            "positions",
        ),
        (
            InitLqr {
                velocities: vec![2, 7],
                ..ok.clone()
            },
            "index 7",
        ),
        (
            InitLqr {
                velocities: vec![2, 1],
                ..ok.clone()
            },
            "twice",
        ),
    ] {
        let e = err(&bad, &x0, 2, 3);
        assert!(e.contains(what), "{what}: {e}");
    }
    assert!(err(&ok, &x0, 3, 3).contains("positions"));
    assert!(err(&ok, &[0.0, 0.0, f64::NAN, 0.0], 2, 3).contains("x0"));
    assert!(err(&ok, &x0, 2, 0).contains("horizon"));
}

/// Settings without the optional keys read GPS's defaults; unknown keys are refused.
#[test]
fn optional_settings_default_to_gps() {
    let read = |s: &str| serde_json::from_str::<InitLqr>(s);
    let cfg = read(r#"{"dt": 0.05, "positions": [0], "velocities": [1]}"#).unwrap();
    assert_eq!(cfg, InitLqr::new(0.05, vec![0], vec![1]));
    assert_eq!(
        (
            cfg.variance,
            cfg.stiffness,
            cfg.stiffness_vel,
            cfg.final_weight
        ),
        (1.0, 1.0, 0.5, 1.0)
    );
    assert!(read(r#"{"dt": 0.05, "positions": [0], "velocities": [1], "x": 1}"#).is_err());
}
