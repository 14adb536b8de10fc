//! Tuned settings by (algorithm, environment), as rl-baselines3-zoo picks its `hyperparams/*.yml`
//! entry: `tandem train` without `--config` uses the preset for its pair when there is one, and
//! says so on stderr, in `config.toml` and in `summary.json`.
//!
//! The presets are the files in `crates/agents/presets/` (each one's comment says where its
//! values come from; `RESULTS.md` there records what they reach). They are embedded in the binary
//! with `include_str!`, so the program finds them from any working directory.

/// One embedded preset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Preset {
    /// Algorithm name as `--algo` takes it.
    pub algo: &'static str,
    /// Environment id as `--env` takes it.
    pub env: &'static str,
    /// File name in `crates/agents/presets/`, recorded in the run's files.
    pub file: &'static str,
    /// The step budget the preset was tuned for (its learning-rate schedule or its
    /// `RESULTS.md` runs assume it); `tandem train` warns when `--steps` differs.
    pub steps: u64,
    /// The file's text: a `--config` file (`[agent]` and `[train]` tables).
    pub text: &'static str,
}

/// Every preset, one per (algorithm, environment) pair.
pub const PRESETS: &[Preset] = &[
    Preset {
        algo: "dqn",
        env: "CartPole-v1",
        file: "dqn_cartpole.toml",
        steps: 50_000,
        text: include_str!("../../crates/agents/presets/dqn_cartpole.toml"),
    },
    Preset {
        algo: "dqn",
        env: "PixelMaze-v0",
        file: "dqn_pixelmaze.toml",
        steps: 40_000,
        text: include_str!("../../crates/agents/presets/dqn_pixelmaze.toml"),
    },
    Preset {
        algo: "reinforce",
        env: "CartPole-v1",
        file: "reinforce_cartpole.toml",
        steps: 500_000,
        text: include_str!("../../crates/agents/presets/reinforce_cartpole.toml"),
    },
    Preset {
        algo: "sac",
        env: "Pendulum-v1",
        file: "sac_pendulum.toml",
        steps: 20_000,
        text: include_str!("../../crates/agents/presets/sac_pendulum.toml"),
    },
    Preset {
        algo: "ddpg",
        env: "Pendulum-v1",
        file: "ddpg_pendulum.toml",
        steps: 20_000,
        text: include_str!("../../crates/agents/presets/ddpg_pendulum.toml"),
    },
];

/// The preset for `algo` on `env`, if there is one.
pub fn find(algo: &str, env: &str) -> Option<&'static Preset> {
    PRESETS.iter().find(|p| p.algo == algo && p.env == env)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tandem::algos::model_free::TrainSettings;
    use tandem_agents::{Algo, AlgoConfig};

    #[test]
    fn every_preset_parses_for_its_algorithm_and_its_environment_exists() {
        for p in PRESETS {
            let algo: Algo = p.algo.parse().unwrap();
            let (agent, train) = super::super::train::parse_config(algo, p.text, p.file).unwrap();
            assert!(
                agent != AlgoConfig::default_for(algo) || train != TrainSettings::default(),
                "{} changes nothing",
                p.file
            );
            train.validate().unwrap();
            assert!(tandem::make_env(p.env).is_ok(), "{}", p.env);
        }
    }

    #[test]
    fn pairs_are_unique_and_found() {
        for (i, p) in PRESETS.iter().enumerate() {
            assert_eq!(find(p.algo, p.env), Some(p));
            assert!(PRESETS[..i]
                .iter()
                .all(|q| (q.algo, q.env) != (p.algo, p.env)));
        }
        assert_eq!(
            find("dqn", "CartPole-v1").unwrap().file,
            "dqn_cartpole.toml"
        );
        assert!(find("sac", "CartPole-v1").is_none());
    }

    #[test]
    fn the_dqn_cartpole_schedule_matches_its_budget() {
        // The learning rate decays to 0 over the preset's step budget: `--steps 50000` is the
        // budget the preset and RESULTS.md use.
        let p = find("dqn", "CartPole-v1").unwrap();
        assert!(p
            .text
            .contains(&format!("learning_rate_decay_steps = {}", p.steps)));
    }
}
