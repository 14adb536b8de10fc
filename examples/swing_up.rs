//! Closed-loop swing-up of the true p0 DC-motor pendulum (`DcMotorPendulumParams::real()`) with
//! each MPC planner planning through the true plant (`PlantModel`): 400 steps of 0.05 s from
//! `(π, 0)`, reward `−5 φ² − 0.1 φ̇² − 0.01 u²` with φ wrapped, `|u| ≤ 3 V`.
//!
//! `cargo run --release --example swing_up [-- cem|mppi|dmd|ilqr ...]` prints
//! each planner's episode return (p0: about −660 for its best learned policy; the target here is
//! ≥ −800), the part of it from the last 300 steps (balancing), the largest |φ| over the last 100
//! steps, and the wall time.
//!
//! Defaults: horizon 30 (iLQR 40); each sampled planner takes 4 rounds of 200 samples per step;
//! they minimize p3's discounted objective `Σ γ^h c_h` (eq. 3) with `γ = 0.95`. The sampling
//! noise (std 1.5) is drawn at knots every 5 steps and held in between (move blocking,
//! `Knots::hold`), independent between knots: 5 steps is half the period of small swings about the
//! bottom, `π/ω₀` computed from the plant's parameters, and the bang-bang swing-up switches once
//! per half swing, so each block can carry one pump. MPPI sets its temperature at every update so
//! that the effective sample size is 5% of the samples (`Temperature::EffectiveSamples`,
//! `λ = 0.05`). Override with the environment: `H`, `N`, `ITERS`, `STD`, `GAMMA`, `KNOTS` (steps
//! per knot; `KNOTS=1 BETA=0.8` is the former per-step AR(1) noise), `INTERP` (`hold`, `linear`),
//! `BETA`, `LAMBDA`, `TEMP` (`fixed`, `spread`, `ess`), `ALPHA` (CEM), `STEP` (DMD-MPC's `α`),
//! `ELITE`, `SEED` or `SEEDS=n` (seeds 0..n), `MAXIT`, `STEPS` (episode length); `TRACE=1` prints
//! the trajectory, `ONESHOT=1` one open-loop plan's cost (with `TRACE=1` its actions and angles).
//!
//! Why the discount: during balancing every open-loop plan of this unstable plant falls within
//! its 1.5 s (planned costs 270–460 where balancing costs about 0.1 a step; the tail is never
//! executed, replanning supplies the feedback it lacks). Undiscounted, that tail cost let "fall
//! now and swing round" tie with "balance, fall at the end": CEM seed 7 fell at step 291 (−993).
//! With `γ = 0.95` (an effective horizon of 1/(1 − γ) = 20 steps inside the 30 planned) near-term
//! cost dominates, and the swing-up misses below disappeared too.
//!
//! Measured (`SEEDS=10 target/release/examples/swing_up cem mppi` beside `SEEDS=10 … dmd`, 2
//! shared cores at load 1.6–2.3; seeds 0, 1, 2 and held-out 3–9; wall time 14–18 s per 400-step
//! episode for each planner, one MPPI episode 24 s while tests compiled):
//! - CEM −699, −742, −694, −733, −733, −764, −725, −774, −723, −689;
//! - MPPI −708, −751, −697, −704, −689, −751, −676, −702, −738, −696;
//! - DMD-MPC −732, −758, −708, −727, −697, −768, −706, −680, −727, −753;
//! - iLQR −606, −603, −600 (|φ| < 1e-4 over the last 100 steps, under 1 s).
//!
//! The last 300 steps (balancing, |φ| up to 0.27 rad over the last 100) cost 22–40 of each sampled
//! return. Budget: with 8 rounds of 100 samples (the former CEM and DMD-MPC setting) and `γ = 0.95`
//! CEM made −698 to −786 and DMD-MPC −736 to −802 on seeds 0–9 (seed 8 short by 2), balancing for
//! 43–75: fewer, larger rounds put more samples into each update (DMD-MPC with `α = 0.5` instead of
//! 0.8: −701 to −768). Undiscounted with knots (8 × 100 for CEM and DMD-MPC, MPPI as now), seeds
//! 0–4: CEM −672, −712, −724, −717, −715; MPPI −698, −705, −676, −683, −687; DMD-MPC −724, −725,
//! −727, −711, −723; seeds 5–9: CEM −729, −702, −993 (seed 7 fell while balancing), −962, −699,
//! MPPI −716 to −671, DMD-MPC −771 to −692. Before knots and discount (per-step noise with
//! β = 0.8, undiscounted; MPPI with the spread-normalized temperature and 3 updates), seeds 0–4:
//! CEM −773, −698, −706, −996, −867; MPPI −1107, −738, −693, −944, −955; DMD-MPC −787, −877, −734,
//! −1014, −765.
//!
//! More seeds, first 60 steps only (`STEPS=60`; a miss is a 60-step return below −750, as the
//! other 340 steps cost 40–70): with these defaults CEM misses none of seeds 0–19, MPPI none of
//! 0–19, DMD-MPC none of 10–22 (0–9 by full returns above); with 8 × 100 and `γ = 0.95` CEM none
//! of 0–19, DMD-MPC none of 0–22. With knots but undiscounted, CEM missed 2 of 0–19 (8, 19), MPPI 2
//! (13, 15), DMD-MPC 2 (10, 15; and 22 of 20–24); before both, CEM missed 8 of 20, MPPI 12 and
//! DMD-MPC 8 (seeds 0–4 counted by their full returns). A miss: arriving short of the top, the
//! pendulum is held at |φ| ≈ 0.5–0.7 rad with saturated voltage (3 V gives 45% of the gravity
//! torque) and falls back for another swing. Other discounts (CEM and DMD-MPC with 8 × 100):
//! `γ = 0.9` CEM none of seeds 0–9, returns about 30 lower; `γ = 0.98` CEM none of 0–19, but
//! DMD-MPC missed seed 3 and MPPI seed 1; `γ = 0.99` CEM none of 0–19. The discount with per-step
//! noise (`KNOTS=1 BETA=0.8`): CEM and MPPI none of seeds 0–9, returns about 20 lower than with
//! knots. Knot spacing matters
//! (undiscounted, CEM seeds 0–4): held knots of 4 or 6 steps missed 2 each, against none for 5;
//! linear interpolation between knots every 3 steps was no better than per-step noise.
//!
//! Tried and dropped (undiscounted): longer horizons with per-step noise (MPPI with 60 steps never
//! left the bottom, seed 0; one open-loop plan from the bottom by CEM over 60 steps costs
//! 1500–1800 against about 620 for iLQR's, the needle is too small for 100–300 samples); with
//! knots, horizon 40 (CEM 5 misses in seeds 5–14, DMD-MPC 1 in 10–19 against 2); carrying CEM
//! elites to the next iteration and call (iCEM's keep/shift elites: 3 kept, 9 misses in seeds
//! 0–19; 1 kept, 3 in 0–9) — it commits to the first plan found; a terminal cost of 10× the state
//! cost at the horizon (punishes plans that end mid-swing: most seeds miss); noise std 2 (DMD-MPC
//! recovered seeds 10, 15, 22 but missed 3; CEM still missed 8, and 6 too); more iterations for
//! the first, cold plan (one open-loop plan from the bottom with 30 iterations still costs
//! 680–940 by CEM and DMD-MPC, 930–1120 by MPPI).
//!
//! Why MPPI failed with a fixed temperature (best −2455 before): the sampled cost spread is
//! hundreds while swinging and below one while balancing, so no single `λ` fits. Raw `λ = 1` is
//! greedy (one sample carries the update): it swings up, but the noisy first action cannot balance.
//! Hotter, it averages mirror-image swing-ups (left first / right first) from the symmetric start
//! into nothing and never leaves the bottom (−13 000 with `λ = 0.1 × spread`, or with `σ = 3` where
//! clamped ±3 V samples cancel). Normalizing by the spread or fixing the effective sample size
//! fixes both phases; with knots the effective-sample rule (5%) missed 0 of seeds 0–4 in 60 steps
//! against 3–4 for spread normalization (`λ` 0.02–0.1).

use std::f64::consts::PI;
use std::time::Instant;

use tandem_models::PlantModel;
use tandem_planners::{
    Bounds, Cem, CemConfig, DmdMpc, DmdMpcConfig, Ilqr, IlqrConfig, Knots, Mppi, MppiConfig, Noise,
    Objective, Planner, Temperature, Utility,
};
use tandem_robots::{DcMotorPendulum, DcMotorPendulumParams};

fn wrap(phi: f64) -> f64 {
    (phi + PI).rem_euclid(2.0 * PI) - PI
}

fn reward(x: &[f64], u: &[f64]) -> f64 {
    let phi = wrap(x[0]);
    -5.0 * phi * phi - 0.1 * x[1] * x[1] - 0.01 * u[0] * u[0]
}

/// Reads an override `NAME=value` from the environment (for sweeps), else `default`.
fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Steps per knot: half the period of small swings about the hanging equilibrium,
/// `π / ω₀` with `ω₀ = √(m g l / J)` (0.26 s, 5 steps of 0.05 s for the true pendulum). The
/// time-optimal swing-up under the voltage bound is bang-bang with one switch per half swing
/// (each pump pushes with the motion), so blocks of this length can express it with about one
/// random number per pump instead of one per step.
fn half_swing_steps(p: &DcMotorPendulumParams) -> usize {
    let omega0 = (p.m * p.g * p.l / p.j).sqrt();
    ((PI / omega0) / p.dt).round().max(1.0) as usize
}

fn planner(name: &str, seed: u64) -> Box<dyn Planner> {
    let bounds = Some(Bounds::symmetric(1, 3.0));
    let horizon = env_or("H", if name == "ilqr" { 40 } else { 30 });
    // Each sampled planner: 4 rounds of 200 samples per step.
    let n = env_or("N", 200);
    let iterations = env_or("ITERS", 4);
    let std = env_or("STD", 1.5);
    // Noise held over knots of half a swing, independent between knots (β = 0); `KNOTS=1
    // BETA=0.8` is the former per-step AR(1) noise.
    let spacing = env_or("KNOTS", half_swing_steps(&DcMotorPendulumParams::real()));
    let knots = match std::env::var("INTERP").as_deref() {
        Ok("linear") => Knots::linear(spacing),
        _ => Knots::hold(spacing),
    };
    let beta = env_or("BETA", 0.0);
    match name {
        "cem" => Box::new(
            Cem::new(CemConfig {
                horizon,
                population: n,
                iterations,
                init_std: Some(vec![std]),
                alpha: env_or("ALPHA", 0.1),
                elite_fraction: env_or("ELITE", 0.1),
                correlation: beta,
                knots,
                bounds,
                seed,
                ..CemConfig::default()
            })
            .unwrap(),
        ),
        "mppi" => Box::new(
            Mppi::new(MppiConfig {
                horizon,
                samples: n,
                lambda: env_or("LAMBDA", 0.05),
                temperature: match std::env::var("TEMP").as_deref() {
                    Ok("fixed") => Temperature::Fixed,
                    Ok("spread") => Temperature::Spread,
                    _ => Temperature::EffectiveSamples,
                },
                noise: Noise::Isotropic(std),
                iterations,
                correlation: beta,
                knots,
                bounds,
                seed,
                ..MppiConfig::default()
            })
            .unwrap(),
        ),
        "dmd" => Box::new(
            DmdMpc::new(DmdMpcConfig {
                horizon,
                samples: n,
                iterations,
                seed,
                correlation: beta,
                knots,
                noise: Noise::Isotropic(std),
                step_size: env_or("STEP", 0.8),
                adapt_covariance: true,
                utility: Utility::CemElite {
                    elite_fraction: 0.1,
                    reward_weighted: true,
                },
                bounds,
                ..DmdMpcConfig::default()
            })
            .unwrap(),
        ),
        "ilqr" => Box::new(
            Ilqr::new(IlqrConfig {
                horizon,
                max_iterations: env_or("MAXIT", 30),
                init_std: 0.1,
                bounds,
                seed,
                ..IlqrConfig::default()
            })
            .unwrap(),
        ),
        other => panic!("unknown planner {other}: use cem, mppi, dmd or ilqr"),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let names = if args.is_empty() {
        vec!["cem".to_string(), "mppi".to_string(), "dmd".to_string()]
    } else {
        args
    };
    let plant = DcMotorPendulum::new(DcMotorPendulumParams::real());
    let model = PlantModel::new(plant);
    // p3's discounted MPC objective `Σ γ^h c_h` (eq. 3), γ = 0.95: see the module docs.
    let objective = Objective::from_reward(2, 1, reward)
        .with_discount(env_or("GAMMA", 0.95))
        .expect("discount in (0, 1]");
    // iLQR needs a smooth cost: 10 (1 − cos φ) equals 5 φ² to second order but has no jump at ±π.
    let smooth = Objective::new(2, 1, |x, u| {
        10.0 * (1.0 - x[0].cos()) + 0.1 * x[1] * x[1] + 0.01 * u[0] * u[0]
    });
    // `SEEDS=n` runs seeds 0..n (each planner and seed its own episode); else the one `SEED`.
    let seeds: Vec<u64> = match std::env::var("SEEDS").ok().and_then(|v| v.parse().ok()) {
        Some(n) => (0..n).collect(),
        None => vec![env_or("SEED", 0)],
    };
    for name in names {
        for &seed in &seeds {
            episode(&name, seed, &plant, &model, &objective, &smooth);
        }
    }
}

fn episode(
    name: &str,
    seed: u64,
    plant: &DcMotorPendulum,
    model: &PlantModel<DcMotorPendulum>,
    objective: &Objective,
    smooth: &Objective,
) {
    let mut p = planner(name, seed);
    let objective = if name == "ilqr" { smooth } else { objective };
    if std::env::var("ONESHOT").is_ok() {
        let plan = p.plan(&[PI, 0.0], model, objective).expect("plan");
        println!(
            "{name} seed {seed}: open-loop plan cost from (pi, 0): {:.1}",
            plan.total_cost
        );
        if std::env::var("TRACE").is_ok() {
            let u: Vec<String> = plan.actions.iter().map(|v| format!("{v:.1}")).collect();
            println!("  u {}", u.join(" "));
            let phi: Vec<String> = plan
                .states
                .column(0)
                .iter()
                .map(|v| format!("{:.1}", wrap(*v)))
                .collect();
            println!("  phi {}", phi.join(" "));
        }
        return;
    }
    let mut x = [PI, 0.0];
    let (mut ret, mut worst_late, mut late_ret) = (0.0, 0.0f64, 0.0);
    let start = Instant::now();
    let steps = env_or("STEPS", 400);
    for t in 0..steps {
        let u = p.plan(&x, model, objective).expect("plan").first_action();
        assert!(u[0].abs() <= 3.0);
        let r = reward(&x, &u);
        ret += r;
        if t >= 100 {
            late_ret += r;
        }
        x = plant.step_array(&x, u[0]);
        if std::env::var("TRACE").is_ok() && t % 5 == 0 {
            println!(
                "  t {t:3} phi {:7.3} phidot {:7.2} u {:6.2}",
                wrap(x[0]),
                x[1],
                u[0]
            );
        }
        if t >= 300 {
            worst_late = worst_late.max(wrap(x[0]).abs());
        }
    }
    println!(
        "{name} seed {seed}: return {ret:.1} (last 300 steps {late_ret:.1}), max |phi| over the last 100 steps {worst_late:.4}, {:.2} s",
        start.elapsed().as_secs_f64()
    );
}
