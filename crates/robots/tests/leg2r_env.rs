//! p3's leg task (`Leg2R-v0`): reward (15) on hand-computed values, the trajectory against its
//! own derivatives, observations against the two-link formula, seeded starts, bad input, and a
//! computed-torque controller (our inverse dynamics + PD) that tracks the foot trajectory within
//! the torque limit: the task is feasible.

use std::f64::consts::{PI, TAU};

use tandem_dynamics::rigid::{rnea, Data};
use tandem_dynamics::Plant;
use tandem_envs::{Action, Env, EnvError, Task};
use tandem_robots::{
    leg2r_reward, make, FootTrajectory, Leg2RConfig, Leg2REnv, Leg2REnvExt, Leg2RModel, Leg2RTask,
};

/// The textbook foot position of the leg (angles about +y, 0.15 m links).
fn analytic_foot(q: &[f64]) -> [f64; 2] {
    [
        -0.15 * q[0].sin() - 0.15 * (q[0] + q[1]).sin(),
        -0.15 * q[0].cos() - 0.15 * (q[0] + q[1]).cos(),
    ]
}

fn phase(state: &[f64]) -> f64 {
    state[5].atan2(state[4]).rem_euclid(TAU)
}

#[test]
fn reward_15_on_hand_computed_values() {
    // |e_p|² = 0.3² + 0.4² = 0.25, |e_v|² = 1: 0.8 e^{-0.25} + 0.2 e^{-1}.
    let r = leg2r_reward([0.3, -0.4], [0.0, 1.0]);
    assert!((r - 0.696_616_514_691_412_5).abs() < 1e-15, "{r}");
    assert_eq!(leg2r_reward([0.0; 2], [0.0; 2]), 1.0);
    // Far off in both: only a sliver is left.
    assert!(leg2r_reward([3.0, 0.0], [0.0, 5.0]) < 0.8 * 2e-4);
}

#[test]
fn the_task_scores_the_foot_error_after_the_step_in_the_configured_units() {
    let env = Leg2REnv::new(Leg2RModel::Idealized);
    let task = env.task();
    // A state whose foot is 3 cm behind and 4 cm above the stance target, at rest.
    let mut s = task.state_on_trajectory(0.5);
    let t = task.target(&s);
    let q = task
        .foot()
        .inverse([t.position[0] - 0.03, t.position[1] + 0.04])
        .unwrap();
    s[..4].copy_from_slice(&[q[0], q[1], 0.0, 0.0]);
    let v = t.velocity;
    let expected = 0.8 * (-0.0025f64).exp() + 0.2 * (-(v[0] * v[0] + v[1] * v[1])).exp();
    let r = task.reward(&[0.0; 6], &[0.0; 2], &s);
    assert!((r - expected).abs() < 1e-12, "{r} vs {expected}");
    // In centimetres (and cm/s... here 0.1 m/s units) the same error is costly.
    let config = Leg2RConfig {
        position_scale: 0.01,
        velocity_scale: 0.1,
        ..Leg2RConfig::default()
    };
    let sharp = Leg2REnv::with_config("sharp", config).unwrap();
    let r = sharp.task().reward(&[0.0; 6], &[0.0; 2], &s);
    let vs = (v[0] * v[0] + v[1] * v[1]) / 0.01;
    assert!((r - (0.8 * (-25.0f64).exp() + 0.2 * (-vs).exp())).abs() < 1e-12);
}

#[test]
fn trajectory_is_a_closed_half_ellipse_and_stance_line_with_consistent_derivatives() {
    let tr = FootTrajectory::default();
    let (a, b, z0, period) = (0.06, 0.05, -0.24, 0.5);
    // Corners: front of stance at φ = 0 (and 2π), back at φ = π; apex at φ = 3π/2.
    let at = |phi: f64| tr.at(phi).position;
    assert!((at(0.0)[0] - a).abs() < 1e-15 && at(0.0)[1] == z0);
    assert!((at(PI)[0] + a).abs() < 1e-15 && (at(PI)[1] - z0).abs() < 1e-15);
    assert!((at(TAU - 1e-12)[0] - a).abs() < 1e-9);
    let apex = at(1.5 * PI);
    assert!(apex[0].abs() < 1e-15 && (apex[1] - (z0 + b)).abs() < 1e-15);
    // Stance speed: the 12 cm stride in half a period.
    assert!((tr.at(1.0).velocity[0] + 2.0 * a / (period / 2.0)).abs() < 1e-12);
    // Velocity and acceleration are time derivatives of position and velocity inside segments
    // (φ̇ = 2π / period).
    let w = TAU / period;
    for phi in [0.3, 1.7, 3.3, 4.0, 5.5, 6.1] {
        let h = 1e-6;
        let (p, m) = (tr.at(phi + h), tr.at(phi - h));
        let t = tr.at(phi);
        for i in 0..2 {
            let v = (p.position[i] - m.position[i]) / (2.0 * h) * w;
            let acc = (p.velocity[i] - m.velocity[i]) / (2.0 * h) * w;
            assert!((t.velocity[i] - v).abs() < 1e-7, "φ {phi}: {t:?}");
            assert!((t.acceleration[i] - acc).abs() < 1e-5, "φ {phi}: {t:?}");
        }
    }
    // The ellipse: ((x − cx) / a)² + ((z − z0) / b)² = 1 during swing.
    for phi in [3.5, 4.2, 5.0, 6.0] {
        let [x, z] = at(phi);
        assert!(((x / a).powi(2) + ((z - z0) / b).powi(2) - 1.0).abs() < 1e-12);
    }
}

#[test]
fn observation_holds_joints_phase_and_the_foot_error() {
    let mut env = Leg2REnv::new(Leg2RModel::Idealized);
    let obs = env.reset(Some(11));
    let s = env.state();
    assert_eq!(s.len(), 6);
    assert_eq!(&obs[..6], &s[..]);
    assert!((s[4] * s[4] + s[5] * s[5] - 1.0).abs() < 1e-12);
    let target = FootTrajectory::default().at(phase(&s));
    let p = analytic_foot(&s);
    assert!((obs[6] - (p[0] - target.position[0])).abs() < 1e-12);
    assert!((obs[7] - (p[1] - target.position[1])).abs() < 1e-12);
    // The foot velocity error: the analytic foot velocity by differencing along q̇.
    let h = 1e-6;
    let fwd = analytic_foot(&[s[0] + h * s[2], s[1] + h * s[3]]);
    let back = analytic_foot(&[s[0] - h * s[2], s[1] - h * s[3]]);
    for i in 0..2 {
        let v = (fwd[i] - back[i]) / (2.0 * h);
        assert!((obs[8 + i] - (v - target.velocity[i])).abs() < 1e-7);
    }
    assert_eq!(env.observation_space().flat_dim(), obs.len());
}

#[test]
fn the_phase_turns_by_half_a_turn_in_half_a_period() {
    let mut env = Leg2REnv::new(Leg2RModel::Idealized);
    env.reset(Some(2));
    let phi0 = phase(&env.state());
    for _ in 0..125 {
        env.step(&Action::Continuous(vec![0.0, 0.0])).unwrap();
    }
    // 125 steps of 2 ms are half the 0.5 s period.
    let d = (phase(&env.state()) - phi0 - PI).rem_euclid(TAU);
    assert!(d.min(TAU - d) < 1e-10, "{d}");
}

#[test]
fn seeded_starts_reproduce_and_lie_near_the_trajectory() {
    let mut a = Leg2REnv::new(Leg2RModel::Idealized);
    let mut b = Leg2REnv::new(Leg2RModel::Idealized);
    assert_eq!(a.reset(Some(7)), b.reset(Some(7)));
    assert_ne!(a.reset(Some(7)), b.reset(Some(8)));
    let mut phases = Vec::new();
    for seed in 0..20 {
        let obs = a.reset(Some(seed));
        // ±0.05 rad on each joint moves the foot by at most 0.3 · 0.05 · √2 ≈ 2.1 cm.
        let err = (obs[6] * obs[6] + obs[7] * obs[7]).sqrt();
        assert!(err < 0.022, "seed {seed}: {err}");
        phases.push(phase(&a.state()));
    }
    // Starts spread over the whole period.
    let (lo, hi) = phases
        .iter()
        .fold((TAU, 0.0f64), |(l, h), p| (l.min(*p), h.max(*p)));
    assert!(lo < 1.0 && hi > TAU - 1.0, "{phases:?}");
    // Without noise the start is on the trajectory, moving with it.
    let exact = Leg2RConfig {
        start_angle_noise: 0.0,
        start_velocity_noise: 0.0,
        ..Leg2RConfig::default()
    };
    let mut e = Leg2REnv::with_config("exact", exact).unwrap();
    let obs = e.reset(Some(3));
    assert!(obs[6..].iter().all(|v| v.abs() < 1e-12), "{obs:?}");
}

#[test]
fn bad_actions_and_states_are_errors_and_large_actions_are_clipped() {
    let mut env = Leg2REnv::new(Leg2RModel::Idealized);
    assert!(matches!(
        env.step(&Action::Continuous(vec![0.0, 0.0])),
        Err(EnvError::NeedsReset { .. })
    ));
    env.reset(Some(0));
    for bad in [
        Action::Continuous(vec![0.0]),
        Action::Continuous(vec![0.0, 0.0, 0.0]),
        Action::Continuous(vec![f64::NAN, 0.0]),
        Action::Continuous(vec![0.0, f64::INFINITY]),
        Action::Discrete(1),
    ] {
        let err = env.step(&bad).err().unwrap();
        assert!(matches!(err, EnvError::InvalidAction { .. }), "{err}");
        assert!(err.to_string().contains("Leg2R-v0"));
    }
    assert!(env.set_state(&[0.0; 4]).is_err());
    assert!(env.set_state(&[0.0, 1.0, 0.0, 0.0, f64::NAN, 0.0]).is_err());
    // ±1 is the full 3 N m; beyond it the torque is clipped.
    let s = env.state();
    let full = env.step(&Action::Continuous(vec![1.0, -1.0])).unwrap();
    env.set_state(&s).unwrap();
    let beyond = env.step(&Action::Continuous(vec![40.0, -7.0])).unwrap();
    assert_eq!(full, beyond);
    assert_eq!(
        env.task().control(&Action::Continuous(vec![0.5, -2.0])),
        vec![1.5, -3.0]
    );
}

#[test]
fn invalid_configurations_are_errors_naming_the_problem() {
    let cases: [(Leg2RConfig, &str); 4] = [
        (
            Leg2RConfig {
                trajectory: FootTrajectory {
                    stance_z: -0.31,
                    ..FootTrajectory::default()
                },
                ..Leg2RConfig::default()
            },
            "reach",
        ),
        (
            Leg2RConfig {
                trajectory: FootTrajectory {
                    period: 0.0,
                    ..FootTrajectory::default()
                },
                ..Leg2RConfig::default()
            },
            "period",
        ),
        (
            Leg2RConfig {
                position_scale: 0.0,
                ..Leg2RConfig::default()
            },
            "position_scale",
        ),
        (
            Leg2RConfig {
                start_angle_noise: f64::NAN,
                ..Leg2RConfig::default()
            },
            "start_angle_noise",
        ),
    ];
    for (config, word) in cases {
        let err = Leg2REnv::with_config("bad", config).err().unwrap();
        assert!(err.to_string().contains(word), "{err}");
    }
}

#[test]
fn configurations_read_from_serde_with_the_registered_defaults() {
    let c: Leg2RConfig =
        serde_json::from_str(r#"{"position_scale": 0.02, "trajectory": {"period": 0.4}}"#).unwrap();
    assert_eq!(c.position_scale, 0.02);
    assert_eq!(c.trajectory.period, 0.4);
    assert_eq!(c.trajectory.stance_z, -0.24);
    assert_eq!(c.plant, Leg2RConfig::default().plant);
    assert!(serde_json::from_str::<Leg2RConfig>(r#"{"scale": 1.0}"#).is_err());
    let real = Leg2RConfig::for_model(Leg2RModel::Real);
    let back: Leg2RConfig = serde_json::from_str(&serde_json::to_string(&real).unwrap()).unwrap();
    assert_eq!(back, real);
}

#[test]
fn canonicalize_puts_the_clock_back_on_the_unit_circle() {
    let env = Leg2REnv::new(Leg2RModel::Idealized);
    let mut s = vec![0.1, 1.0, 0.0, 0.0, 0.6, 0.8 * 1.1];
    let before = phase(&s);
    env.task().canonicalize(&mut s);
    assert!((s[4].hypot(s[5]) - 1.0).abs() < 1e-15);
    assert!((phase(&s) - before).abs() < 1e-15);
    assert_eq!(&s[..4], &[0.1, 1.0, 0.0, 0.0]);
}

#[test]
fn registered_with_a_1000_step_limit_and_a_real_twin() {
    for id in [Leg2REnv::ID, Leg2REnv::ID_REAL] {
        let mut env = make(id).unwrap();
        assert_eq!(env.max_episode_steps(), Some(1000));
        env.reset(Some(0));
        let mut steps = 0;
        loop {
            steps += 1;
            if env
                .step(&Action::Continuous(vec![0.1, -0.1]))
                .unwrap()
                .truncated
            {
                break;
            }
        }
        assert_eq!(steps, 1000);
    }
    let (mut i, mut r) = (
        Leg2REnv::new(Leg2RModel::Idealized),
        Leg2REnv::new(Leg2RModel::Real),
    );
    assert_eq!(i.reset(Some(4)), r.reset(Some(4)));
    let a = Action::Continuous(vec![0.5, 0.5]);
    assert_ne!(i.step(&a).unwrap(), r.step(&a).unwrap());
    assert_eq!(i.plant().dt(), 0.002);
}

/// Joint-space targets of the foot trajectory at `phase`: `q_d` (inverse kinematics),
/// `q̇_d = J⁻¹ ṗ_d`, `q̈_d = J⁻¹ (p̈_d − J̇ q̇_d)` (J̇ q̇ by central differences along q̇_d).
fn joint_targets(task: &Leg2RTask, phase: f64) -> [[f64; 2]; 3] {
    let t = task.config().trajectory.at(phase);
    let foot = task.foot();
    let q = foot.inverse(t.position).unwrap();
    let qd = foot.joint_velocity(&q, t.velocity).unwrap();
    let h = 1e-6;
    let jp = foot.jacobian(&[q[0] + h * qd[0], q[1] + h * qd[1]]);
    let jm = foot.jacobian(&[q[0] - h * qd[0], q[1] - h * qd[1]]);
    let jdot_qd =
        [0, 1].map(|r| ((jp[r][0] - jm[r][0]) * qd[0] + (jp[r][1] - jm[r][1]) * qd[1]) / (2.0 * h));
    let rhs = [
        t.acceleration[0] - jdot_qd[0],
        t.acceleration[1] - jdot_qd[1],
    ];
    let qdd = foot.joint_velocity(&q, rhs).unwrap();
    [q, qd, qdd]
}

/// Runs one episode of computed-torque control `τ = RNEA(q, q̇, q̈_d + Kp e + Kd ė)` and returns
/// (mean reward, RMS foot position error (m), peak |τ| commanded before clipping (N m), fraction
/// of steps with a clipped torque, peak |τ| of the feedforward RNEA(q_d, q̇_d, q̈_d) (N m)).
fn computed_torque_episode(config: Leg2RConfig, seed: u64) -> (f64, f64, f64, f64, f64) {
    let mut env = Leg2REnv::with_config("tracked", config).unwrap();
    let limit = env.task().torque_limit();
    let dyn_model = env.plant().plant().model().clone();
    let mut data = Data::new(&dyn_model);
    let (kp, kd) = (60.0 * 60.0, 2.0 * 60.0);
    let dt = env.plant().dt();
    env.reset(Some(seed));
    let (mut total, mut sq_err, mut peak, mut peak_ff, mut clipped) = (0.0, 0.0, 0.0f64, 0.0f64, 0);
    for _ in 0..1000 {
        let s = env.state();
        // Aim at the middle of the coming step: the torque is held for 2 ms.
        let [q, qd, qdd] = joint_targets(env.task(), phase(&s) + 0.5 * dt * TAU / 0.5);
        let acc = [0, 1].map(|i| qdd[i] + kp * (q[i] - s[i]) + kd * (qd[i] - s[2 + i]));
        let tau = rnea(&dyn_model, &mut data, &s[..2], &s[2..4], &acc).clone();
        let ff = rnea(&dyn_model, &mut data, &q, &qd, &qdd).clone();
        peak_ff = peak_ff.max(ff.amax());
        peak = peak.max(tau.amax());
        if (0..2).any(|i| tau[i].abs() > limit[i]) {
            clipped += 1;
        }
        let a = Action::Continuous(vec![tau[0] / limit[0], tau[1] / limit[1]]);
        let step = env.step(&a).unwrap();
        total += step.reward;
        sq_err += step.observation[6].powi(2) + step.observation[7].powi(2);
    }
    (
        total / 1000.0,
        (sq_err / 1000.0).sqrt(),
        peak,
        clipped as f64 / 1000.0,
        peak_ff,
    )
}

#[test]
fn computed_torque_tracks_the_trajectory_within_the_torque_limit() {
    for model in [Leg2RModel::Idealized, Leg2RModel::Real] {
        let (mean, rms, peak, clipped, peak_ff) =
            computed_torque_episode(Leg2RConfig::for_model(model), 5);
        eprintln!(
            "{model:?}: mean reward {mean:.5}, RMS position error {:.2} mm, peak commanded \
             torque {peak:.2} N m ({:.1} % of steps clipped), peak feedforward {peak_ff:.2} N m",
            rms * 1e3,
            clipped * 100.0
        );
        // The trajectory itself needs a small fraction of the 3 N m; the PD asks for more only
        // for a few milliseconds where the target velocity jumps (clipped there).
        assert!(
            peak_ff < 1.0,
            "{model:?}: the trajectory alone needs {peak_ff} N m"
        );
        assert!(clipped < 0.05, "{model:?}: {clipped}");
        assert!(rms < 0.004, "{model:?}: RMS error {rms} m");
        // Reward (15) in metres: close to its maximum of 1 (holding still scores about 0.94).
        assert!(mean > 0.99, "{model:?}: mean reward {mean}");
    }
    // Measured in units of 2 cm and 0.2 m/s the same tracking still scores well, where holding
    // still would score under 0.1.
    let sharp = Leg2RConfig {
        position_scale: 0.02,
        velocity_scale: 0.2,
        ..Leg2RConfig::default()
    };
    let (mean, ..) = computed_torque_episode(sharp, 5);
    eprintln!("Idealized, errors in units of 2 cm and 0.2 m/s: mean reward {mean:.3}");
    assert!(mean > 0.9, "{mean}");
}
