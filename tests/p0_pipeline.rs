//! Smoke tests of p0's pipeline (seconds): exact true-sample accounting, the data the difference
//! model is fitted on, determinism, and the `tandem reproduce p0-pendulum --quick` outputs.

use tandem::agents::NoiseConfig;
use tandem::dynamics::classic::{DcMotorPendulum, DcMotorPendulumParams};
use tandem::envs::{make, SampleCounter};
use tandem::pipelines::p0::{
    agent_spaces, collect, ddpg_agent, p0_loop, pendulum_problem, run_seed, Method, P0Config,
    RunRecord,
};

/// A configuration small enough for a test: tiny networks and budgets.
fn tiny() -> P0Config {
    let mut c = P0Config::default();
    c.ddpg.actor_hidden = vec![16];
    c.ddpg.critic_hidden = vec![16];
    c.ddpg.buffer_size = 5000;
    c.residual.hidden = vec![16];
    c.pretrain_steps = 300;
    c.real_batch = 250;
    c.real_budget = 500;
    c.baseline_max_samples = 700;
    c.baseline_stop_early = false;
    c.eval_interval = 300;
    c.model_steps = 200;
    c.fit.epochs = 2;
    c
}

fn run(cfg: &P0Config, seed: u64) -> Vec<RunRecord> {
    let problem = pendulum_problem();
    run_seed(
        &problem,
        cfg,
        &Method::ALL,
        seed,
        &|m, s| ddpg_agent(cfg, &problem.task, m, s),
        &mut |_| {},
    )
    .unwrap()
}

#[test]
fn true_samples_are_counted_exactly_and_runs_are_deterministic() {
    let cfg = tiny();
    let a = run(&cfg, 3);
    let by = |m: Method| a.iter().find(|r| r.method == m).unwrap();
    // The difference method: 0 before any true sample, then one point per batch of 250.
    let d = by(Method::Difference);
    let xs: Vec<u64> = d.curve.iter().map(|p| p.true_samples).collect();
    assert_eq!(xs, vec![0, 250, 500]);
    assert_eq!(d.true_samples, 500);
    assert_eq!(d.simulated_steps, 400);
    assert_eq!(d.fit_holdout_loss.len(), 2);
    // Cold and warm: evaluated every 300 true samples, capped at 700.
    for m in [Method::Cold, Method::Warm] {
        let xs: Vec<u64> = by(m).curve.iter().map(|p| p.true_samples).collect();
        assert_eq!(xs, vec![0, 300, 600, 700], "{m:?}");
        assert_eq!(by(m).true_samples, 700);
    }
    // Warm start and the difference method start from the same pre-trained policy.
    assert_eq!(by(Method::Warm).curve[0], d.curve[0]);
    assert!(a.iter().all(|r| r
        .curve
        .iter()
        .all(|p| p.eval_return.is_finite() && p.eval_return < 0.0)));
    // Same seed, same numbers.
    let b = run(&cfg, 3);
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(
            (x.method, &x.curve, x.updates),
            (y.method, &y.curve, y.updates)
        );
        assert_eq!(x.fit_holdout_loss, y.fit_holdout_loss);
    }
}

/// The transitions the difference model learns from are true-plant transitions from canonical
/// (wrapped) states, without 2π jumps when the pendulum passes the bottom.
#[test]
fn collected_transitions_are_true_plant_steps_from_wrapped_states() {
    let mut cfg = tiny();
    cfg.cold_noise = NoiseConfig::OrnsteinUhlenbeck {
        theta: 0.15,
        sigma: 1.0,
        dt: 1.0,
    };
    let problem = pendulum_problem();
    let agent = ddpg_agent(&cfg, &problem.task, Method::Cold, 0).unwrap();
    let (obs, act) = agent_spaces(&problem.task);
    let rng = tandem::core::seeding::rng_from_seed(0);
    let mut lp = p0_loop(agent, &cfg.ddpg, &obs, &act, rng).unwrap();
    let (mut env, count) = SampleCounter::new(make("DcMotorPendulum-real-v0").unwrap());
    let data = collect(&mut lp, &mut env, &problem.task, 900, 5, &mut || {}).unwrap();
    // Collecting neither stores nor learns.
    assert_eq!((lp.primary().len(), lp.counts().updates), (0, 0));
    assert_eq!(lp.counts().real_steps, 900);
    assert_eq!((data.len(), count.get()), (900, 900));
    let real = DcMotorPendulum::new(DcMotorPendulumParams::real());
    let mut crossed = 0;
    for i in 0..data.len() {
        let s = [data.states[[i, 0]], data.states[[i, 1]]];
        assert!((-std::f64::consts::PI..std::f64::consts::PI).contains(&s[0]));
        let want = real.step_array(&s, data.actions[[i, 0]]);
        for (k, w) in want.iter().enumerate() {
            assert!((data.next_states[[i, k]] - w).abs() < 1e-9, "row {i}");
        }
        crossed += usize::from(want[0].abs() > std::f64::consts::PI);
    }
    assert!(
        crossed > 0,
        "the noisy policy should swing past the bottom (±π) at least once"
    );
}

#[test]
fn reproduce_quick_writes_table_ii_and_fig_5() {
    let out = std::env::temp_dir().join(format!("tandem-p0-quick-{}", std::process::id()));
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_tandem"))
        .args([
            "reproduce",
            "p0-pendulum",
            "--quick",
            "--seeds",
            "2",
            "--quiet",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let table: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table.json")).unwrap()).unwrap();
    for m in ["cold", "warm", "difference"] {
        let r = &table[m]["return_at_budget"];
        assert!(r["mean"].as_f64().unwrap() < 0.0, "{m}");
        assert!(r["stderr"].as_f64().unwrap() >= 0.0);
        assert_eq!(r["per_seed"].as_array().unwrap().len(), 2);
        let t = &table[m]["samples_to_target"];
        assert_eq!(t["per_seed"].as_array().unwrap().len(), 2);
        assert!(t.get("mean").is_some());
        assert!(out.join(format!("runs/{m}__seed1/curve.csv")).exists());
    }
    let md = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(md.contains("Difference model") && md.contains("not counted"));
    let svg = std::fs::read_to_string(out.join("fig5.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("difference"));
    std::fs::remove_dir_all(&out).ok();
}
