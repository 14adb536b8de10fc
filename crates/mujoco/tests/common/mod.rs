//! Reading the gymnasium fixtures of `tests/fixtures/gymnasium-mujoco/`.
#![allow(dead_code)]

use serde_json::Value;

/// One recorded step.
pub struct FixtureStep {
    pub action: Vec<f64>,
    pub obs: Vec<f64>,
    pub reward: f64,
    pub terminated: bool,
    pub truncated: bool,
    pub qpos: Vec<f64>,
    pub qvel: Vec<f64>,
    pub info: Vec<(String, f64)>,
}

/// One recorded episode.
pub struct Episode {
    pub seed: u64,
    pub init_qpos: Vec<f64>,
    pub init_qvel: Vec<f64>,
    pub reset_obs: Vec<f64>,
    pub steps: Vec<FixtureStep>,
}

/// A task's file: its model's default pose and its episodes.
pub struct Fixture {
    pub init_qpos: Vec<f64>,
    pub episodes: Vec<Episode>,
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

/// Loads `<id>.json`.
pub fn load(id: &str) -> Fixture {
    let path = format!(
        "{}/tests/fixtures/gymnasium-mujoco/{id}.json",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let v: Value = serde_json::from_str(&text).expect("fixture JSON");
    let episodes = v["episodes"]
        .as_array()
        .expect("episodes")
        .iter()
        .map(|e| Episode {
            seed: e["reset_seed"].as_u64().expect("seed"),
            init_qpos: floats(&e["init_qpos"]),
            init_qvel: floats(&e["init_qvel"]),
            reset_obs: floats(&e["reset_obs"]),
            steps: e["steps"]
                .as_array()
                .expect("steps")
                .iter()
                .map(|s| FixtureStep {
                    action: floats(&s["action"]),
                    obs: floats(&s["obs"]),
                    reward: s["reward"].as_f64().expect("reward"),
                    terminated: s["terminated"].as_bool().expect("terminated"),
                    truncated: s["truncated"].as_bool().expect("truncated"),
                    qpos: floats(&s["qpos"]),
                    qvel: floats(&s["qvel"]),
                    info: s["info"]
                        .as_object()
                        .expect("info")
                        .iter()
                        .map(|(k, x)| (k.clone(), x.as_f64().expect("info value")))
                        .collect(),
                })
                .collect(),
        })
        .collect();
    Fixture {
        init_qpos: floats(&v["init_qpos"]),
        episodes,
    }
}
