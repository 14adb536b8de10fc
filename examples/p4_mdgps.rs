//! p4 Fig. 4 for one seed, with the settings of `tandem reproduce p4-reacher`: MDGPS trains a neural policy for gymnasium's reacher (MuJoCo) from
//! per-condition local controllers updated by LQR-FLM, PI² or PILQR, and prints, per iteration,
//! the samples drawn so far and the global policy's mean final fingertip–target distance on 300
//! random test targets.
//!
//! `cargo run --release --features mujoco --example p4_mdgps -- [METHODS] [SEED] [CONDITIONS]`
//! (`lqr_flm,pi2,pilqr`, seed 0, 24 training conditions by default); `P4_CONFIG=FILE` reads the
//! loop's settings (`MdgpsConfig`, every field) from a TOML file; `--print-config` prints the
//! defaults in that form. The method `ddpg` trains p4's model-free baseline on the same task
//! (`P4_DDPG=FILE` for its settings, `ReacherDdpg`), measured on the same test targets.
//!
//! p4 Fig. 5, the door, for one seed:
//!
//! `cargo run --release --features mujoco --example p4_mdgps -- door [METHODS] [SEED]`
//! (`pilqr`, seed 0 by default) trains MDGPS on the door's four starts with
//! `tandem::studies::p4::door_mdgps_settings` (p4-door's authors' preset, the zero initial
//! controller, GPS's first iteration and linearization) and prints, per iteration, the
//! trajectories drawn so far (all starts), the global policy's mean final door angle on 100
//! random test starts (`tandem::algos::manipulation::door_test_set`) and the fraction of them it
//! opened (≥ 0.8 rad). `P4_CONFIG=FILE` reads MDGPS's settings (not the cost) here too;
//! `door --print-config` prints the door's.
//!
//! One MDGPS iteration ([`tandem::algos::mdgps::train_mdgps`]):
//!
//! 1. sample every condition's local controller on the system;
//! 2. fit TVLG dynamics per condition and linearize the global policy around the samples;
//! 3. update each local controller, its step bounded by KL against the linearized policy;
//! 4. regress the global policy onto the local controllers' actions at the sampled states.

use tandem::algos::gps::LocalMethod;
use tandem::algos::manipulation::{
    door_problem, door_test_set, reacher_config, reacher_problem, reacher_test_set,
    train_ddpg_reacher, ReacherDdpg, DOOR_TEST_CONDITIONS, DOOR_TEST_SEED, REACHER_TEST_CONDITIONS,
    REACHER_TEST_SEED,
};
use tandem::algos::mdgps::{train_mdgps, MdgpsConfig};
use tandem::algos::Ephemeral;
use tandem::robots::p4::{ReacherCost, DOOR_OPENED};
use tandem::studies::p4::{door_mdgps_settings, Preset};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("door") {
        return door(&args[2..]);
    }
    if args.get(1).map(String::as_str) == Some("--print-config") {
        print!("{}", toml::to_string(&reacher_config())?);
        return Ok(());
    }
    let methods = args.get(1).map_or("lqr_flm,pi2,pilqr", |a| a.as_str());
    let seed: u64 = args.get(2).map_or(Ok(0), |a| a.parse())?;
    let conditions: usize = args.get(3).map_or(Ok(24), |a| a.parse())?;
    let cfg: MdgpsConfig = settings_from_env("P4_CONFIG", reacher_config)?;
    let problem = reacher_problem(ReacherCost::default(), conditions, seed)?;
    let test = reacher_test_set(REACHER_TEST_CONDITIONS, REACHER_TEST_SEED);
    println!(
        "reacher, seed {seed}, {conditions} conditions, {} iterations of {} trajectories each",
        cfg.local.iterations, cfg.local.samples
    );
    for name in methods.split(',') {
        if name == "ddpg" {
            let ddpg: ReacherDdpg = settings_from_env("P4_DDPG", ReacherDdpg::default)?;
            let t0 = std::time::Instant::now();
            let curve = train_ddpg_reacher(
                ReacherCost::default(),
                &ddpg,
                &test,
                seed,
                &mut Ephemeral,
                &mut |_| {},
            )?;
            let curve: Vec<String> = curve
                .iter()
                .map(|p| format!("{}:{:.4}", p.samples, p.test_measure))
                .collect();
            println!(
                "    ddpg: samples:test {} ({:.1} s)",
                curve.join(" "),
                t0.elapsed().as_secs_f64()
            );
            continue;
        }
        let method = LocalMethod::from_name(name).ok_or(format!("unknown method {name}"))?;
        let t0 = std::time::Instant::now();
        let run = train_mdgps(
            method,
            &problem,
            &test,
            &cfg,
            seed,
            &mut Ephemeral,
            &mut |_| {},
        )?;
        let curve: Vec<String> = run
            .curve
            .iter()
            .map(|p| {
                format!(
                    "{}:{:.4}/{:.4}/{:.1e}/{:.2}",
                    p.samples, p.test_measure, p.local_measure, p.policy_loss, p.step_mult
                )
            })
            .collect();
        println!(
            "{name:>8}: samples:test/local/loss/step {} ({} failed updates; {:.1} s)",
            curve.join(" "),
            run.failed_updates,
            t0.elapsed().as_secs_f64()
        );
    }
    Ok(())
}

/// p4 Fig. 5 for one seed: MDGPS on the door with `args` = `[METHODS] [SEED]` or
/// `--print-config`.
fn door(args: &[String]) -> Result<(), Box<dyn std::error::Error>> {
    let (default_cfg, cost) = door_mdgps_settings(Preset::Authors)?;
    if args.first().map(String::as_str) == Some("--print-config") {
        print!("{}", toml::to_string(&default_cfg)?);
        return Ok(());
    }
    let methods = args.first().map_or("pilqr", |a| a.as_str());
    let seed: u64 = args.get(1).map_or(Ok(0), |a| a.parse())?;
    let cfg: MdgpsConfig = settings_from_env("P4_CONFIG", || default_cfg)?;
    let problem = door_problem(cost)?;
    let test = door_test_set(DOOR_TEST_CONDITIONS, DOOR_TEST_SEED, &cost)?;
    println!(
        "door, seed {seed}, {} starts, {} iterations of {} trajectories each, {} test starts \
         (opened: final angle >= {DOOR_OPENED} rad)",
        problem.conditions.len(),
        cfg.local.iterations,
        cfg.local.samples,
        test.starts.len()
    );
    for name in methods.split(',') {
        let method = LocalMethod::from_name(name).ok_or(format!("unknown method {name}"))?;
        let t0 = std::time::Instant::now();
        // Progress on stderr: the trajectories drawn at each iteration's sampling, with the time.
        let per_iteration = (cfg.local.samples * problem.conditions.len()) as u64;
        let run = train_mdgps(
            method,
            &problem,
            &test,
            &cfg,
            seed,
            &mut Ephemeral,
            &mut |drawn| {
                if drawn % per_iteration == 0 {
                    eprintln!(
                        "{name}: {drawn} trajectories drawn at {:.1} s",
                        t0.elapsed().as_secs_f64()
                    );
                }
            },
        )?;
        let wall = t0.elapsed().as_secs_f64();
        println!(
            "{name:>8}: trajectories, mean final test angle (rad), test starts opened, local \
             controllers' mean final angle (rad), policy loss"
        );
        for p in &run.curve {
            println!(
                "    {:>7}  {:.3}  {:.2}  {:.3}  {:.1e}",
                p.samples,
                p.test_measure,
                p.test_solved.unwrap_or(f64::NAN),
                p.local_measure,
                p.policy_loss,
            );
        }
        println!(
            "{name:>8}: {} failed updates; {wall:.1} s ({:.1} s an iteration)",
            run.failed_updates,
            wall / run.curve.len().max(1) as f64
        );
    }
    Ok(())
}

/// The settings in the TOML file the environment variable `var` names, else `default()`.
fn settings_from_env<T: serde::de::DeserializeOwned>(
    var: &str,
    default: impl FnOnce() -> T,
) -> Result<T, Box<dyn std::error::Error>> {
    Ok(match std::env::var_os(var) {
        Some(path) => toml::from_str(&std::fs::read_to_string(path)?)?,
        None => default(),
    })
}
