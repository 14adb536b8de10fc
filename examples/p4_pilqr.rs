//! p4 Fig. 3 on one condition: LQR-FLM, PI² and PILQR train a time-varying linear-Gaussian
//! controller for the gripper pusher or the door (MuJoCo), 20 trajectories per iteration, and
//! print the mean final block–goal distance (door angle) of each iteration's trajectories.
//!
//! `cargo run --release --features mujoco --example p4_pilqr -- [TASK] [CONDITION] [SEED] [METHODS]`
//! (`pusher` or `door`; the pusher's hard condition 3, seed 0 and `lqr_flm,pi2,pilqr` by
//! default); `P4_CONFIG=FILE` reads
//! the loop's settings (`LocalConfig`, every field) from a TOML file; `--print-config` prints the
//! defaults in that form.
//!
//! The loop ([`tandem::algos::gps::train_local`]) is GPS's: per iteration, sample the
//! controller, fit TVLG dynamics to the samples, and update the controller (PILQR: LQR-FLM under
//! per-step KL bounds, then PI² on the residual costs-to-go the fitted model does not explain).

use tandem::algos::gps::{train_local, LocalConfig, LocalMethod, LocalProblem};
use tandem::algos::manipulation::{door_problem, pusher_problem};
use tandem::algos::Ephemeral;
use tandem::robots::p4::{DoorCost, PusherCost};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("--print-config") {
        print!("{}", toml::to_string(&LocalConfig::default())?);
        return Ok(());
    }
    let task = args.get(1).map_or("pusher", |a| a.as_str());
    let cond: usize = args.get(2).map_or(Ok(3), |a| a.parse())?;
    let seed: u64 = args.get(3).map_or(Ok(0), |a| a.parse())?;
    let methods = args.get(4).map_or("lqr_flm,pi2,pilqr", |a| a.as_str());
    let full = match task {
        "pusher" => pusher_problem(PusherCost::default())?,
        "door" => door_problem(DoorCost::default())?,
        other => return Err(format!("unknown task {other}: pusher or door").into()),
    };
    if cond >= full.conditions.len() {
        return Err(format!("condition {cond}: the {task} has {}", full.conditions.len()).into());
    }
    // Keep the one condition.
    let LocalProblem {
        system,
        mut conditions,
        horizon,
        measure,
        ..
    } = full;
    let problem = LocalProblem {
        system,
        conditions: vec![conditions.swap_remove(cond)],
        horizon,
        measure: Box::new(move |_, x| measure(cond, x)),
        policy_input: None,
    };
    // P4_CONFIG=FILE: a TOML file with LocalConfig's fields (all of them), for experiments.
    let cfg = match std::env::var_os("P4_CONFIG") {
        Some(path) => toml::from_str(&std::fs::read_to_string(path)?)?,
        None => LocalConfig::default(),
    };
    println!(
        "{task} condition {cond}, seed {seed}, {} iterations of {} trajectories",
        cfg.iterations, cfg.samples
    );
    for name in methods.split(',') {
        let method = LocalMethod::from_name(name).ok_or(format!("unknown method {name}"))?;
        let t0 = std::time::Instant::now();
        let run = train_local(method, &problem, &cfg, seed, &mut Ephemeral, &mut |_| {})?;
        let curve: Vec<String> = run.curves[0]
            .iter()
            .map(|p| format!("{:.3}", p.measure))
            .collect();
        println!(
            "{name:>8}: final measure per iteration {} (cost {:.1} -> {:.1}; {} failed updates; {:.1} s)",
            curve.join(" "),
            run.curves[0][0].mean_cost,
            run.curves[0].last().map_or(f64::NAN, |p| p.mean_cost),
            run.failed_updates[0],
            t0.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
