//! Studies check their whole settings before any work: every range, every product of settings,
//! the seed range, and the memory of all parallel jobs together. Each case here is refused with
//! an error naming the setting, before the output directory exists; runs that are merely long
//! stop within a second of a stop request.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use tandem::studies::interrupt::Stop;
use tandem::studies::{run_study, Error, StudyArgs, StudyOptions};

fn tmp(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("study-settings-{name}"))
}

/// `study --quick` with the `--config` text `toml` (and `edit` applied to the arguments).
fn args(name: &str, toml: &str, edit: impl FnOnce(&mut StudyArgs)) -> StudyArgs {
    let config = tmp(&format!("{name}.toml"));
    std::fs::write(&config, toml).unwrap();
    let out = tmp(name);
    let _ = std::fs::remove_dir_all(&out);
    let mut a = StudyArgs {
        quick: true,
        quiet: true,
        config: Some(config),
        out: Some(out),
        seeds: Some(1),
        ..StudyArgs::default()
    };
    edit(&mut a);
    a
}

/// The error `study` refuses `toml` with; asserts that nothing was written and that the message
/// holds every one of `words`.
fn refused_with(
    study: &str,
    options: &StudyOptions,
    toml: &str,
    edit: impl FnOnce(&mut StudyArgs),
    words: &[&str],
) {
    let name = format!("{study}-{:x}", fxhash(toml));
    let a = args(&name, toml, edit);
    let t0 = Instant::now();
    let e = run_study(study, options, &a).expect_err(&format!("{study} accepted {toml}"));
    let msg = e.to_string();
    assert!(
        t0.elapsed() < Duration::from_secs(10),
        "{study}: refusing took {:?}",
        t0.elapsed()
    );
    assert!(
        !a.out.as_ref().unwrap().exists(),
        "{study}: {toml}: the output directory was written before the error: {msg}"
    );
    for w in words {
        assert!(
            msg.contains(w),
            "{study}: {toml}: {msg:?} does not say {w:?}"
        );
    }
}

fn refused(study: &str, toml: &str, words: &[&str]) {
    refused_with(study, &StudyOptions::default(), toml, |_| {}, words);
}

fn fxhash(s: &str) -> u64 {
    s.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3)
    })
}

#[test]
fn ensembles_are_estimated_whole_with_their_optimizer_state() {
    // One member of 30000 x 30000 is 3.4 GiB with Adam; seven are over the 8 GiB limit.
    let wide = "[p3.base.ensemble]\nhidden = [30000, 30000]\nmembers = 7\nelites = 5\n";
    refused(
        "p3-leg",
        wide,
        &["estimated memory", "ensemble (7 members of [30000, 30000])"],
    );
    for members in ["1000000000", "9223372036854775807"] {
        refused(
            "p3-leg",
            &format!("[p3.base.ensemble]\nmembers = {members}\n"),
            &["estimated memory", "ensemble"],
        );
    }
}

#[test]
fn planner_populations_and_pixel_models_are_estimated() {
    refused(
        "p3-leg",
        "[p3.mpc]\nsamples = 1000000000000\n",
        &["estimated memory", "mpc"],
    );
    for (key, words) in [
        ("channels = [100000, 100000, 100000]", "convolutions"),
        ("features = 100000000", "dense layers"),
        ("factors = 100000000", "dense layers"),
    ] {
        refused(
            "p2-maze",
            &format!("[model]\n{key}\n"),
            &["estimated memory", words],
        );
    }
    // The F1 experiment's episodes are kept as frames.
    refused(
        "p2-maze",
        "[quality]\ncheckpoints = [2, 1000000000000]\n",
        &["estimated memory", "quality: real frames"],
    );
}

#[test]
fn parallel_jobs_are_summed() {
    // Each run's ensemble (3 x 1.5 GiB with Adam) fits alone; MBPO's and M-DeMoRL's at once do
    // not.
    let toml = "[p3.base.ensemble]\nhidden = [10000, 10000]\nmembers = 3\nelites = 2\n";
    let a = args("p3-jobs-1", toml, |a| {
        a.jobs = 1;
        a.check = true;
    });
    run_study("p3-leg", &StudyOptions::default(), &a).unwrap();
    refused_with(
        "p3-leg",
        &StudyOptions::default(),
        toml,
        |a| a.jobs = 2,
        &["2 parallel jobs (--jobs)", "estimated memory"],
    );
}

#[test]
fn seed_ranges_that_wrap_around_are_refused() {
    for (first, seeds) in [(u64::MAX, 2), (5, u64::MAX)] {
        refused_with(
            "p2-cartpole",
            &StudyOptions::default(),
            "",
            |a| {
                a.first_seed = Some(first);
                a.seeds = Some(seeds);
            },
            &["--seeds/--first-seed"],
        );
    }
    // The last seed itself is fine.
    let a = args("last-seed", "", |a| {
        a.first_seed = Some(u64::MAX - 1);
        a.check = true;
    });
    run_study("p2-cartpole", &StudyOptions::default(), &a).unwrap();
}

#[test]
fn the_leg_study_runs_the_leg_only() {
    for env in ["HalfCheetah-v5", "Nope-v0"] {
        refused(
            "p3-leg",
            &format!("env = \"{env}\"\n"),
            &[env, "Leg2R-real-v0"],
        );
    }
}

#[test]
fn elite_fractions_must_name_distinct_runs() {
    refused(
        "p3-leg",
        "ablate_elites = [0.5, 0.50001]\n",
        &["ablate_elites", "m_demorl_elites_50"],
    );
}

#[test]
fn integration_steps_per_control_step_are_bounded() {
    refused(
        "p3-leg",
        "[leg.plant]\ninternal_step = 1e-12\n",
        &["internal_step", "100000"],
    );
}

#[test]
fn model_settings_are_checked_before_any_run() {
    for (toml, words) in [
        ("[p3.base.ensemble]\nhidden = [0]\n", "hidden"),
        ("[p3.base.ensemble]\nelites = 0\n", "elites"),
        ("[p3.base.ensemble]\nelites = 8\nmembers = 7\n", "elites"),
        ("[p3.base.ensemble]\nmin_log_var = 1.0\n", "min_log_var"),
        ("[p3.base]\nrollouts_per_step = 4611686018427387904\n", "overflows"),
        ("[p3]\ntransitions_per_epoch = { from_epoch = 0, to_epoch = 1, start = 4611686018427387904, end = 4611686018427387904 }\n", "overflows"),
    ] {
        refused("p3-leg", toml, &[words]);
    }
    refused("p2-cartpole", "[model]\nhidden = [0]\n", &["hidden"]);
    refused(
        "p2-cartpole",
        "[model.optimizer.sgd]\nlr = -0.01\n",
        &["lr"],
    );
}

/// The trajectory optimizers' and the dynamics fit's settings (p4's scenes need MuJoCo).
#[cfg(feature = "mujoco")]
#[test]
fn trajectory_optimizer_settings_are_checked_before_any_run() {
    for (toml, words) in [
        (
            "[local.trajopt.lqr]\nmin_eta = 10.0\nmax_eta = 1.0\n",
            "min_eta",
        ),
        (
            "[local.trajopt.lqr]\nbracket_iterations = 0\n",
            "bracket_iterations",
        ),
        (
            "[local.trajopt.lqr]\nadam_learning_rate = 0.0\n",
            "adam_learning_rate",
        ),
        ("[local.trajopt.lqr]\neta_init = -1.0\n", "eta_init"),
        ("[local.trajopt.pi2]\nkl_step = 0.0\n", "kl_step"),
        ("[local.trajopt.pi2]\nridge = -1.0\n", "ridge"),
        (
            "[local.dynamics]\nregularization = -1.0\n",
            "regularization",
        ),
        ("[local.dynamics.prior]\nstrength = -1.0\n", "strength"),
        ("[local.dynamics.prior]\nmax_clusters = 0\n", "max_clusters"),
        (
            "[local.dynamics.prior]\nmax_iterations = 0\n",
            "max_iterations",
        ),
    ] {
        refused("p4-pusher", toml, &[words]);
    }
}

#[cfg(feature = "mujoco")]
#[test]
fn condition_sets_and_iterations_are_estimated() {
    for toml in [
        "conditions = 1000000000000\n",
        "test_conditions = 1000000000000\n",
        "[mdgps.local]\niterations = 4611686018427387904\n",
    ] {
        refused("p4-reacher", toml, &["p4-reacher"]);
    }
}

/// A cycle of many imagined episodes stops within a second of the request.
#[test]
fn imagined_episodes_stop_promptly() {
    let toml = "real_only_episodes = 1\nimagined_per_cycle = 1000000000\n";
    let mut a = args("imagined-stop", toml, |_| {});
    let stop = Stop::never();
    a.stop = stop.clone();
    let out = a.out.clone().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let r = run_study("p2-cartpole", &StudyOptions::default(), &a);
        tx.send((r, Instant::now())).unwrap();
    });
    // Let the first imagined cycle start.
    std::thread::sleep(Duration::from_secs(2));
    let asked = Instant::now();
    stop.request();
    let (r, ended) = rx
        .recv_timeout(Duration::from_secs(30))
        .expect("the run ended");
    assert!(matches!(r, Err(Error::Interrupted { .. })), "{r:?}");
    let waited = ended.duration_since(asked);
    assert!(
        waited < Duration::from_secs(1),
        "stopped {waited:?} after the request"
    );
    let config = std::fs::read_to_string(out.join("config.json")).unwrap();
    assert!(config.contains("\"interrupted\""), "{config}");
}
