//! Fuzz targets for the inputs a user hands the `tandem` program: URDF files, the TOML configs
//! of `tandem train --config` and `tandem reproduce <study> --config`, the JSON state and
//! actions of `tandem env replay`, and checkpoint bytes (`--resume`).
//!
//! Each target is a plain `fn(&[u8])` that runs the program's own code on the input (the
//! `src/cli` modules are compiled in from the main crate) and panics only on a bug: bad input
//! must come back as an error, never a panic, a stack overflow, an abort on allocation or a
//! `null` in the JSON output. Two drivers call them:
//!
//! - libFuzzer: `cargo +nightly fuzz run <target>` (the `fuzz_targets/*.rs` binaries);
//! - a stable, seeded mutation driver: the main workspace's `tests/fuzz_smoke.rs`, which runs
//!   [`mutate::Mutator`] over the seed corpora in `fuzz/corpus/<target>/`.

// The program's command modules, as the `tandem` binary compiles them; the targets use a few
// of their functions.
#[allow(dead_code, unused_imports)]
#[path = "../../src/cli/mod.rs"]
mod cli;

pub mod mutate;

use serde_json::{json, Value};
use tandem::agents::{Algo, AlgoConfig, QNetwork};
use tandem::algos::driver::Algorithm;
use tandem::algos::model_free::{ModelFree, TrainSettings};
use tandem::dynamics::rigid::Model;
use tandem::envs::{Env, EnvSpec};
use tandem::make_env as make;
use tandem::nn::budget::MemoryEstimate;
use tandem::nn::Checkpoint;

/// A fuzz target.
pub type Target = fn(&[u8]);

/// The targets by name, as `cargo fuzz run` and `fuzz/corpus/<name>/` call them.
pub const TARGETS: [(&str, Target); 6] = [
    ("urdf", urdf),
    ("train_config", train_config),
    ("reproduce_config", reproduce_config),
    ("env_replay", env_replay),
    ("checkpoint", checkpoint),
    ("study_config", study_config),
];

/// Agents whose estimate is below this are built (allocated, initialized) by the config target;
/// larger ones are only estimated, so that a million inputs stay fast.
const BUILD_BELOW: u64 = 8 << 20;

/// Robots up to this many joints are evaluated by the URDF target.
const EVAL_MAX_DOF: usize = 64;

/// A successful JSON output must hold no `null` (what a non-finite number turns into).
fn assert_no_null(v: &Value, input: &str) {
    let text = v.to_string();
    assert!(
        !text.contains("null"),
        "{input}: output holds null (a non-finite number): {text}"
    );
}

/// `tandem urdf inspect` and `tandem urdf eval`: the URDF loader on the input, then (for up to
/// 64 joints) the dynamics at rest, at moderate values, and at values whose results overflow.
pub fn urdf(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(model) = Model::from_urdf_str(text) else {
        return;
    };
    let _ = cli::urdf::inspect(&model);
    let nv = model.nv();
    if nv > EVAL_MAX_DOF {
        return;
    }
    let states = json!([
        {"q": vec![0.0; nv]},
        {"q": vec![0.3; nv], "v": vec![-1.0; nv], "tau": vec![2.0; nv], "a": vec![0.5; nv]},
        {"q": vec![1e6; nv], "v": vec![1e200; nv], "tau": vec![-1e300; nv]},
    ]);
    if let Ok(out) = cli::urdf::eval(&model, &states, "fuzz states") {
        assert_no_null(&out, "urdf eval");
    }
}

/// The environment a run of `cfg` trains on: pendulum for continuous agents, the pixel maze
/// for a conv DQN, CartPole otherwise.
fn env_for(cfg: &AlgoConfig) -> Box<dyn Env> {
    let id = match cfg {
        AlgoConfig::Ddpg(_) | AlgoConfig::Sac(_) => "Pendulum-v1",
        AlgoConfig::Dqn(c) if c.network == QNetwork::Conv => "PixelMaze-v0",
        _ => "CartPole-v1",
    };
    make(id).expect("a registered environment")
}

/// The environments without MuJoCo, in registry order: `tandem-envs`' and `tandem-robots`'.
fn registered() -> Vec<EnvSpec> {
    let mut specs = tandem::envs::registered();
    specs.extend(tandem::robots::registered());
    specs
}

/// The estimate an agent's constructor checks.
fn estimate(cfg: &AlgoConfig, env: &dyn Env) -> MemoryEstimate {
    let od = env.observation_space().flat_dim();
    let act = env.action_space();
    let n = match act {
        tandem::core::Space::Discrete { n } => *n,
        _ => act.flat_dim(),
    };
    match cfg {
        AlgoConfig::Ddpg(c) => c.memory(od, n),
        AlgoConfig::Sac(c) => c.memory(od, n),
        AlgoConfig::Dqn(c) => c.memory(od, n),
        AlgoConfig::Reinforce(c) => c.memory(od, n),
    }
}

/// `tandem train --config`: the file parsed for each of the four algorithms; a config that
/// parses is built into a run (validation, the memory check, allocation) when its estimate
/// is small, otherwise validated and estimated only.
pub fn train_config(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    for algo in [Algo::Ddpg, Algo::Sac, Algo::Dqn, Algo::Reinforce] {
        let Ok((cfg, settings)) = cli::train::parse_config(algo, text, "fuzz config") else {
            continue;
        };
        let env = env_for(&cfg);
        let est = estimate(&cfg, &*env);
        if est.total().is_some_and(|b| b < BUILD_BELOW) {
            let eval_env = env_for(&cfg);
            let _ = ModelFree::new(cfg, settings, env, eval_env, 1, 0);
        } else {
            let _ = est.check("fuzz");
        }
    }
}

/// `tandem reproduce p0-pendulum --config`: the overrides applied to both base configurations
/// and validated; the DDPG agent is built when its estimate is small.
pub fn reproduce_config(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    for base in [
        tandem::studies::p0::quick_config(),
        tandem::algos::difference_models::P0Config::default(),
    ] {
        let Ok(cfg) = tandem::studies::p0::parse_config(base, text, "fuzz config") else {
            continue;
        };
        let agent = AlgoConfig::Ddpg(cfg.ddpg.clone());
        let env = env_for(&agent);
        if estimate(&agent, &*env)
            .total()
            .is_some_and(|b| b < BUILD_BELOW)
        {
            let eval_env = env_for(&agent);
            let _ = ModelFree::new(agent, TrainSettings::default(), env, eval_env, 1, 0);
        }
    }
}

/// `tandem env replay`: the first byte picks the environment, the rest is the `--state` JSON,
/// a newline, and the actions JSON. A replay that succeeds must print finite numbers only.
pub fn env_replay(data: &[u8]) {
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(rest) else {
        return;
    };
    let (state, actions) = text.split_once('\n').unwrap_or((text, "[]"));
    let envs = registered();
    let id = &envs[pick as usize % envs.len()].id;
    let mut env = make(id).expect("a registered environment");
    // `--state` as the program reads a JSON argument (a path is never opened here).
    let Ok(state) =
        cli::json::parse(state, "--state").and_then(|v| cli::json::numbers(&v, "--state"))
    else {
        return;
    };
    if let Ok(out) = cli::env::replay_from(&mut *env, &state, actions, "fuzz actions") {
        assert_no_null(&out, "env replay");
    }
}

/// The small agents the checkpoint target restores into (DQN on CartPole, SAC on the
/// pendulum): a few hundred parameters and a 64-transition replay, so a million loads are fast.
pub fn small_runs() -> Vec<ModelFree> {
    let table = |s: &str| s.parse::<toml::Table>().expect("valid TOML");
    [
        (Algo::Dqn, "hidden = [8]\nbuffer_size = 64\nbatch_size = 8"),
        (Algo::Sac, "hidden = [8]\nbuffer_size = 64\nbatch_size = 8"),
    ]
    .into_iter()
    .map(|(algo, t)| {
        let cfg = AlgoConfig::from_toml(algo, table(t)).expect("a valid config");
        let (env, eval_env) = (env_for(&cfg), env_for(&cfg));
        ModelFree::new(cfg, TrainSettings::default(), env, eval_env, 1, 0).expect("small")
    })
    .collect()
}

/// `tandem train --resume`: the bytes read as a checkpoint and, if they are one, restored into
/// each small run (which must either accept them or say why).
pub fn checkpoint(data: &[u8]) {
    let Ok(ckpt) = Checkpoint::from_bytes(data) else {
        return;
    };
    for mut run in small_runs() {
        let _ = run.load(&ckpt);
    }
}

/// Values a study-config input sets its chosen settings to: the edges of ranges, of `i64` and of
/// `f64`, products that wrap around, and strings, arrays and tables where numbers belong.
const STUDY_VALUES: &[&str] = &[
    "0",
    "1",
    "-1",
    "2",
    "7",
    "0.5",
    "0.50001",
    "1e-12",
    "-1e-12",
    "1e10",
    "1e12",
    "1e300",
    "-1e300",
    "inf",
    "-inf",
    "nan",
    "1000000000000",
    "4611686018427387904",
    "9223372036854775807",
    "-9223372036854775808",
    "true",
    "\"\"",
    "\"Nope-v0\"",
    "\"HalfCheetah-v5\"",
    "[]",
    "[0]",
    "[0.5, 0.50001]",
    "[100000, 100000, 100000]",
    "[30000, 30000]",
    "[2, 1000000]",
    "{}",
];

/// The leaves of `v` as TOML key paths (`p3.base.ensemble.members`, array elements as the
/// array's path), each once.
fn leaves(prefix: &str, v: &toml::Value, out: &mut Vec<String>) {
    match v {
        toml::Value::Table(t) => {
            for (k, x) in t {
                let path = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                leaves(&path, x, out);
            }
        }
        _ => out.push(prefix.to_string()),
    }
}

/// Every study's settings (quick and full) as key paths, computed once.
fn study_keys() -> &'static Vec<(String, bool, Vec<String>)> {
    static KEYS: std::sync::OnceLock<Vec<(String, bool, Vec<String>)>> = std::sync::OnceLock::new();
    KEYS.get_or_init(|| {
        let mut all = Vec::new();
        for name in tandem::studies::study_names() {
            for quick in [true, false] {
                let args = tandem::studies::StudyArgs {
                    quick,
                    ..Default::default()
                };
                let opts = tandem::studies::StudyOptions::default();
                // Studies that need MuJoCo have no settings without it: their keys stay empty
                // and their inputs exercise the error paths.
                let mut keys = Vec::new();
                if let Ok(c) = tandem::studies::check_study(&name, &opts, &args) {
                    if let Ok(v) = toml::Value::try_from(&c.settings) {
                        leaves("", &v, &mut keys);
                    }
                }
                all.push((name.clone(), quick, keys));
            }
        }
        all
    })
}

/// `tandem reproduce <study> --config FILE --check` for every study: the whole settings check
/// (ranges, products of settings, seeds, the memory of the parallel jobs), which must answer
/// with the settings or an error, never a panic, an overflow or an allocation.
///
/// Byte 0 picks the study and `--quick`; byte 1 the seeds (`--first-seed` near `u64::MAX` for
/// some); then each group of 2 bytes sets one of the study's own settings to one of
/// [`STUDY_VALUES`], until a byte `0xff`, after which the rest is appended as raw TOML.
pub fn study_config(data: &[u8]) {
    let keys = study_keys();
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let (name, quick, leaves) = &keys[pick as usize % keys.len()];
    let (seeds, rest) = rest.split_first().unwrap_or((&0, &[]));
    let (recipe, raw) = match rest.iter().position(|&b| b == 0xff) {
        Some(k) => (&rest[..k], &rest[k + 1..]),
        None => (rest, &[][..]),
    };
    let mut text = String::new();
    if !leaves.is_empty() {
        for pair in recipe.chunks_exact(2) {
            let key = &leaves[pair[0] as usize % leaves.len()];
            let value = STUDY_VALUES[pair[1] as usize % STUDY_VALUES.len()];
            // A dotted key sets one leaf and keeps the rest of its tables.
            let quoted: Vec<String> = key.split('.').map(|k| format!("\"{k}\"")).collect();
            text.push_str(&format!("{} = {value}\n", quoted.join(".")));
        }
    }
    text.push_str(&String::from_utf8_lossy(raw));
    thread_local! {
        static FILE: std::path::PathBuf = std::env::temp_dir().join(format!(
            "tandem-fuzz-study-{}-{:?}.toml",
            std::process::id(),
            std::thread::current().id()
        ));
    }
    let path = FILE.with(|p| p.clone());
    if std::fs::write(&path, &text).is_err() {
        return;
    }
    let args = tandem::studies::StudyArgs {
        quick: *quick,
        config: Some(path),
        seeds: Some(u64::from(seeds % 4) + 1),
        first_seed: (seeds & 0x80 != 0).then(|| u64::MAX - u64::from(seeds % 3)),
        jobs: u64::from(seeds % 3) + 1,
        ..Default::default()
    };
    let _ = tandem::studies::check_study(name, &tandem::studies::StudyOptions::default(), &args);
}
