//! p4 Fig. 3 in miniature: LQR-FLM, PI² and PILQR on a 2-link reacher with abrupt contact
//! dynamics, at the same number of samples per iteration, over several seeds.
//!
//! `cargo run --release -p tandem-planners --example wall_reacher` (the pusher, 3 seeds);
//! `SEEDS=10 ITERS=20 CURVES=1` for the table below; `TASK=wall` for the walled reacher.
//!
//! Tasks (`tests/common/reacher.rs`; two damped joints, dt = 0.05, T = 30, start at rest):
//! - **pusher** (default; p4's gripper pusher): a block on link 1's arc at joint angle 0.3 must
//!   be pushed to 0.8. Link 1 carries it along when `q₁` passes it, losing half its velocity per
//!   contact step (`LOSS`), and cannot pull it back. Cost `(q₁ − b)² + 4 (b − 0.8)²` per step, ×20
//!   at the end. The samples reach the block at different time steps (the test
//!   `pusher_contact_happens_at_different_steps`), so each step's TVLG fit mixes "block still"
//!   and "block carried". `KICK > 0`: the block also slides on after a hit (hockey).
//! - **wall** (`TASK=wall`): a sticky wall at `q₁ = 0.6` (`WALL`, `BOUNCE`), end-effector target
//!   behind it (`TX`, `TY`), so good trajectories press into the wall.
//!
//! Each method starts from the same zero-mean controller with variance 2 (`VAR`), draws 20
//! trajectories per iteration (`SAMPLES`), and its controller is scored by the mean cost of 200
//! rollouts on fixed noise. LQR-FLM: p4 §II-A with a fixed per-step bound ε = 1 (`KL_LQR`), or
//! with GPS's predicted-vs-actual step rule (`LQR_STEP=classic`, [`classic_step_mult`]). PI²:
//! the authors' `TrajOptPI2` settings (`Pilqr::default_pi2`: feedforward and covariance only,
//! covariance damping 2, KL 0.5). PILQR: defaults, base ε = 1, residual-ratio step rule.
//!
//! Measured (release, 2 cores shared with 2 other engineers, load average 2.7–3.6; seeds 0–9 on
//! the pusher, 0–5 on the wall; mean cost of 200 rollouts, lower is better; one iteration = 20
//! samples). Seed means, and the seeds on which PILQR is below both LQR-FLM (fixed ε) and PI²:
//!
//! | iteration (samples) | 1 (20) | 2 (40) | 3 (60) | 4 (80) | 6 (120) | 8 (160) | 10 (200) | 15 (300) | 20 (400) |
//! |---|---|---|---|---|---|---|---|---|---|
//! | pusher: LQR-FLM, fixed ε | 39.6 | 27.7 | 21.7 | 18.1 | 14.2 | 12.0 | 10.7 | 8.7 | 8.1 |
//! | pusher: PI² | 51.2 | 48.0 | 44.7 | 41.3 | 35.9 | 30.9 | 26.7 | 20.1 | 17.0 |
//! | pusher: **PILQR** | 39.2 | 24.6 | 17.2 | 12.9 | 9.0 | 7.8 | 7.2 | 7.0 | 7.0 |
//! | pusher: PILQR best on | 7/10 | 10/10 | 10/10 | 10/10 | 10/10 | 10/10 | 10/10 | 10/10 | 9/10 |
//! | pusher: LQR-FLM, GPS step rule | 39.6 | 19.7 | 13.6 | 11.2 | 9.0 | 8.0 | 7.6 | 7.4 | 7.3 |
//! | pusher: PILQR below it on | 7/10 | 0/10 | 1/10 | 1/10 | 5/10 | 6/10 | 6/10 | 5/10 | 5/10 |
//! | wall: LQR-FLM, fixed ε | 67.4 | 41.2 | | 27.9 | 23.1 | 20.5 | 18.9 | | 16.0 |
//! | wall: PI² | 138.0 | 110.8 | | 75.3 | 57.7 | 45.5 | 39.8 | | 30.0 |
//! | wall: **PILQR** | 68.0 | 36.2 | | 21.4 | 17.5 | 16.3 | 15.8 | | 15.6 |
//! | wall: PILQR best on | 3/6 | 6/6 | | 6/6 | 6/6 | 6/6 | 6/6 | | 6/6 |
//! | wall: LQR-FLM, GPS step rule | 67.4 | 38.5 | | 20.4 | 17.3 | 16.2 | 15.9 | | 15.9 |
//! | wall: PILQR below it on | 0/6 | 6/6 | | 0/6 | 1/6 | 2/6 | 2/6 | | 5/6 |
//!
//! ("PILQR below it on" compares the per-seed curves as printed, to one decimal.) Per seed,
//! pusher (seeds 0–9):
//!
//! | iteration | method | mean | seeds |
//! |---|---|---|---|
//! | 10 | LQR-FLM, fixed ε | 10.7 | 9.9, 9.1, 22.5, 8.7, 8.2, 8.8, 12.2, 8.4, 9.7, 9.7 |
//! | 10 | LQR-FLM, GPS step rule | 7.6 | 6.9, 9.5, 10.6, 6.8, 7.5, 6.6, 7.1, 7.0, 7.0, 7.4 |
//! | 10 | PI² | 26.7 | 28.0, 27.4, 26.0, 24.1, 27.9, 25.4, 27.4, 27.4, 25.1, 28.4 |
//! | 10 | PILQR | 7.2 | 7.3, 7.5, 7.8, 7.0, 7.3, 7.2, 6.8, 7.0, 6.9, 6.7 |
//! | 20 | LQR-FLM, fixed ε | 8.1 | 8.7, 7.9, 11.2, 7.7, 6.6, 7.5, 7.9, 8.2, 7.7, 7.7 |
//! | 20 | LQR-FLM, GPS step rule | 7.3 | 6.6, 8.4, 10.3, 6.5, 7.0, 6.6, 6.9, 7.4, 6.5, 6.8 |
//! | 20 | PI² | 17.0 | 16.7, 17.8, 17.2, 15.5, 18.2, 16.6, 17.1, 17.3, 14.5, 19.1 |
//! | 20 | PILQR | 7.0 | 7.0, 7.2, 6.7, 6.9, 6.9, 7.4, 6.7, 6.9, 7.0, 7.6 |
//!
//! Held-out seeds 10–19 on the pusher (`SEED0=10 SEEDS=10 ITERS=20`, run after the task and the
//! settings were fixed on seeds 0–5): seed means LQR-FLM (fixed ε) / PI² / PILQR at iterations
//! 2, 4, 10, 20: 29.1 / 46.2 / **25.9**, 19.2 / 39.1 / **13.3**, 11.0 / 26.0 / **8.1**, 8.5 /
//! 17.0 / **7.3**; PILQR below both on 10/10 seeds at every iteration from 2 to 20 (9/10 at 1).
//! LQR-FLM with GPS's step rule on the same seeds: 20.9, 11.9, 7.9, 7.4 (PILQR below it on 0, 3,
//! 5 and 3 of 10 seeds).
//!
//! Reading: against p4's LQR-FLM (one fixed ε for both) and PI², PILQR is lowest on every seed
//! from 40 samples on (pusher: 10/10 seeds at every budget from 40 to 300 samples, 9–10/10 up to
//! 400; wall: 6/6 from 40 to 400). Where the lead comes from: PILQR with its step rule switched
//! off (`ADJUST=0`, seeds 0–9) ends the pusher at 9.0 (7.4–13.0), no better than LQR-FLM, so the
//! gain is the residual-driven per-step bound (steps whose cost the model predicts grow their ε,
//! up to 10×; the few steps whose residual ratio passes 0.2 halve theirs) with PI² on the residuals
//! keeping those larger steps stable — LQR-FLM alone at a fixed ε of 4 or 8 diverges on seed 2
//! (37.2, 50.3 at 20 iterations). LQR-FLM with GPS's own adaptive step rule is the stronger
//! baseline: it is faster over the first 2–5 iterations (its multiplier grows ×5 per iteration,
//! PILQR's ×2) and afterwards PILQR's seed mean is lower (7.0 vs 7.3 at 400 samples, driven by
//! LQR-FLM's bad seeds 1 and 2) but PILQR is below it on only about half the seeds. A block
//! far from the arm (`BLOCK=1.2 GOAL=1.6`, seeds 0–5; p4's hard pusher condition) keeps
//! PILQR below fixed-ε LQR-FLM and PI² on 6/6 seeds from 40 to 240 samples and 5/6 to 400
//! (seed means 13.2 / 25.4 / 12.9 there), and lowers the seed mean below GPS-step LQR-FLM from
//! 160 samples on (12.9 vs 14.4 at 400), below it on 4–5 of 6 seeds. The sliding
//! block (`KICK=1`, seeds 0–9) makes LQR-FLM erratic (seed-mean spikes) but PILQR's lead is not
//! consistent per seed either: below fixed-ε LQR-FLM and PI² on 10/10 seeds at 40 samples, 2/10
//! at 400 (seed means 9.0 / 13.4 / 9.3 there); below GPS-step LQR-FLM on 3–8/10.
//!
//! Environment overrides: `TASK` (`push`, `wall`), `LOSS`, `KICK`, `BLOCK`, `GOAL`, `WALL`,
//! `BOUNCE`, `TX`, `TY`, `SAMPLES`, `ITERS`, `SEEDS`, `SEED0` (first seed), `T`, `VAR`, `KL_LQR`, `LQR_STEP`
//! (`const`, `classic`), `KL_PI2`, `PI2_GAINS` (1: PI² refits `K_t`), `DAMP`, `ADJUST` (0: PILQR
//! with constant ε), `METHODS` (comma-separated subset of `lqr,pi2,pilqr`), `CURVES=1` (every
//! iteration per seed), `DEBUG=1` (PILQR's residual ratios and multipliers).

#[path = "../tests/common/reacher.rs"]
mod reacher;

use reacher::{evaluate, objective, push_objective_dim, Reacher};
use tandem_core::seeding::rng_from_seed;
use tandem_models::{DynamicsModel, TvlgConfig, TvlgDynamics, TvlgFit};
use tandem_planners::{
    classic_step_mult, pi2_update, quadratize_cost, sample_trajectories, LqrFlm, LqrFlmConfig,
    Objective, Pi2Config, Pilqr, PilqrConfig, QuadraticCost, SampleConfig, TvlgController,
};

fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn run(method: &str, seed: u64, sys: &Reacher, obj: &Objective, x0: &[f64]) -> Vec<f64> {
    let n = x0.len();
    let scfg = SampleConfig {
        samples: env_or("SAMPLES", 20),
        ..Default::default()
    };
    let kl_lqr = env_or("KL_LQR", 1.0);
    let base = Pilqr::default_pi2();
    let pi2_cfg = Pi2Config {
        kl_step: env_or("KL_PI2", base.kl_step),
        update_gains: env_or("PI2_GAINS", base.update_gains as u8) == 1,
        covariance_damping: env_or("DAMP", base.covariance_damping),
        ..base
    };
    let mut ctrl = TvlgController::constant(env_or("T", 30), n, &[0.0, 0.0], env_or("VAR", 2.0))
        .expect("controller");
    let mut rng = rng_from_seed(seed);
    let mut fit = TvlgFit::new(TvlgConfig::default());
    let lqr = LqrFlm::new(LqrFlmConfig {
        kl_step: kl_lqr,
        ..Default::default()
    })
    .expect("LQR-FLM");
    let mut pilqr = Pilqr::new(PilqrConfig {
        lqr: LqrFlmConfig {
            kl_step: kl_lqr,
            ..Default::default()
        },
        pi2: pi2_cfg.clone(),
        adjust_step: env_or("ADJUST", 1u8) == 1,
        ..Default::default()
    })
    .expect("PILQR");
    // GPS's step adjustment for LQR-FLM alone ("classic": predicted vs actual improvement).
    let classic = env_or("LQR_STEP", String::from("const")) == "classic";
    let mut step_mult = 1.0;
    let mut prev: Option<(TvlgController, TvlgDynamics, Vec<QuadraticCost>)> = None;
    let mut evals = vec![evaluate(&ctrl, sys, obj, x0)];
    for _ in 0..env_or("ITERS", 10) {
        let samples = sample_trajectories(&ctrl, sys, obj, x0, &scfg, &mut rng).expect("samples");
        let next = match method {
            "pi2" => pi2_update(
                &ctrl,
                &samples.states,
                &samples.actions,
                &samples.cost_to_go(),
                &pi2_cfg,
            )
            .map(|s| s.controller),
            _ => fit
                .fit(samples.states.view(), samples.actions.view())
                .map_err(tandem_planners::PlanError::from)
                .and_then(|dynamics| {
                    if method == "lqr" {
                        let cost = quadratize_cost(obj, &samples)?;
                        if classic {
                            if let Some((pc, pd, pq)) = &prev {
                                step_mult = classic_step_mult(
                                    step_mult, pc, pd, pq, &ctrl, &dynamics, &cost,
                                )?;
                            }
                            prev = Some((ctrl.clone(), dynamics.clone(), cost.clone()));
                        }
                        lqr.update(&ctrl, &dynamics, &cost, Some(kl_lqr * step_mult))
                            .map(|s| s.controller)
                    } else {
                        pilqr.update(&ctrl, &samples, &dynamics, obj).map(|s| {
                            if std::env::var("DEBUG").is_ok() {
                                let t = s.step_mult.len() as f64;
                                eprintln!(
                                    "seed {seed}: mean ratio {:.3} mean mult {:.2} min mult {:.2}",
                                    s.residual_ratio.iter().sum::<f64>() / t,
                                    s.step_mult.iter().sum::<f64>() / t,
                                    s.step_mult.iter().copied().fold(f64::INFINITY, f64::min)
                                );
                            }
                            s.controller
                        })
                    }
                }),
        };
        match next {
            Ok(c) => ctrl = c,
            Err(e) => {
                eprintln!("{method} seed {seed}: update failed ({e}); keeping the controller")
            }
        }
        evals.push(evaluate(&ctrl, sys, obj, x0));
    }
    evals
}

fn main() {
    let push = std::env::var("TASK").map(|t| t != "wall").unwrap_or(true);
    let (sys, obj) = if push {
        let sys = Reacher::hockey(env_or("LOSS", 0.5), env_or("KICK", 0.0));
        let n = sys.state_dim();
        (sys, push_objective_dim(env_or("GOAL", 0.8), n))
    } else {
        (
            Reacher::walled(env_or("WALL", 0.6), env_or("BOUNCE", 0.0)),
            objective([env_or("TX", 0.55), env_or("TY", 1.45)]),
        )
    };
    let x0 = sys.x0(env_or("BLOCK", 0.3));
    let seeds: u64 = env_or("SEEDS", 3);
    let curves = std::env::var("CURVES").is_ok();
    println!(
        "task {} (wall {:?} bounce {} push_loss {:?} kick {}) samples/iter {} iterations {} \
         LQR-FLM step {}",
        if push { "push" } else { "wall" },
        sys.wall,
        sys.bounce,
        sys.push_loss,
        sys.kick,
        env_or("SAMPLES", 20),
        env_or("ITERS", 10),
        env_or("LQR_STEP", String::from("const"))
    );
    let methods = ["lqr", "pi2", "pilqr"];
    // curves[method][seed][iteration]
    let mut all: Vec<Vec<Vec<f64>>> = Vec::new();
    let only = std::env::var("METHODS").unwrap_or_default();
    for method in methods {
        if !only.is_empty() && !only.split(',').any(|m| m == method) {
            all.push(vec![
                vec![f64::NAN; env_or::<usize>("ITERS", 10) + 1];
                seeds as usize
            ]);
            continue;
        }
        let first: u64 = env_or("SEED0", 0);
        let per_seed: Vec<Vec<f64>> = (first..first + seeds)
            .map(|seed| {
                let ev = run(method, seed, &sys, &obj, &x0);
                if curves {
                    let c: Vec<String> = ev.iter().map(|v| format!("{v:.1}")).collect();
                    println!("  {method} seed {seed}: {}", c.join(" "));
                }
                ev
            })
            .collect();
        let finals: Vec<f64> = per_seed
            .iter()
            .map(|ev| *ev.last().expect("at least the initial evaluation"))
            .collect();
        let mean = finals.iter().sum::<f64>() / finals.len() as f64;
        let f: Vec<String> = finals.iter().map(|v| format!("{v:.1}")).collect();
        println!(
            "{method:>6}: final cost mean {mean:.1} (seeds: {})",
            f.join(", ")
        );
        all.push(per_seed);
    }
    // Seed-mean learning curves and, per iteration, the seeds on which PILQR is below both.
    let iters = all[0][0].len();
    let samples: usize = env_or("SAMPLES", 20);
    println!("iteration samples | LQR-FLM PI2 PILQR (seed means) | seeds with PILQR best");
    for it in 0..iters {
        let mean = |m: usize| all[m].iter().map(|ev| ev[it]).sum::<f64>() / seeds as f64;
        let best = (0..seeds as usize)
            .filter(|&s| {
                // (A method left out by METHODS has NaN curves and is not compared.)
                let below = |m: usize| all[m][s][it].is_nan() || all[2][s][it] < all[m][s][it];
                below(0) && below(1)
            })
            .count();
        println!(
            "{it:>9} {:>7} | {:>7.1} {:>5.1} {:>5.1} | {best}/{seeds}",
            it * samples,
            mean(0),
            mean(1),
            mean(2)
        );
    }
}
