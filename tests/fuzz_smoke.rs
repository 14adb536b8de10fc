//! The fuzz targets of `fuzz/` on the stable toolchain: each target runs on its seed corpus
//! (`fuzz/corpus/<target>/`) and on seeded mutations of it, and must not panic (a panic is a bug:
//! bad input is an error). A few thousand inputs per target by default, so `cargo test` stays
//! fast; `TANDEM_FUZZ_INPUTS=1000000` runs a million (see `fuzz/README.md`). An input that
//! panics is saved under the target's temporary directory and named in the failure.

#[allow(dead_code)]
#[path = "../fuzz/src/lib.rs"]
mod fuzz;

use std::path::PathBuf;
use std::time::Instant;

use fuzz::mutate::Mutator;
use tandem::algos::driver::Algorithm;

/// Inputs per target (mutations, on top of the seeds themselves).
fn inputs() -> usize {
    std::env::var("TANDEM_FUZZ_INPUTS")
        .ok()
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(2000)
}

fn corpus(target: &str) -> Vec<Vec<u8>> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/corpus")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    files.iter().map(|p| std::fs::read(p).unwrap()).collect()
}

/// The checkpoints of the small runs the checkpoint target restores into, as bytes.
fn checkpoint_seeds() -> Vec<Vec<u8>> {
    fuzz::small_runs()
        .into_iter()
        .map(|run| {
            let mut ckpt = tandem::nn::Checkpoint::new();
            run.save(&mut ckpt).unwrap();
            ckpt.to_bytes().unwrap()
        })
        .collect()
}

/// Runs `target` on its seeds and `inputs()` mutations; panics naming a saved failing input.
fn fuzz_target(name: &str, extra_seeds: Vec<Vec<u8>>) {
    let (_, target) = fuzz::TARGETS
        .iter()
        .find(|(n, _)| *n == name)
        .expect("a known target");
    let mut seeds = corpus(name);
    seeds.extend(extra_seeds);
    let seed = name
        .bytes()
        .fold(0u64, |h, b| h.wrapping_mul(31) ^ u64::from(b));
    let mut m = Mutator::new(seeds.clone(), seed, 1 << 16);
    let n = inputs();
    let start = Instant::now();
    for (k, x) in seeds
        .into_iter()
        .chain(std::iter::repeat_with(|| m.next_input()).take(n))
        .enumerate()
    {
        if std::panic::catch_unwind(|| target(&x)).is_err() {
            let path =
                PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("fuzz-{name}-crash-{k}"));
            std::fs::write(&path, &x).unwrap();
            panic!("{name}: input {k} panicked; saved at {}", path.display());
        }
    }
    eprintln!(
        "{name}: {n} mutated inputs in {:.1} s",
        start.elapsed().as_secs_f64()
    );
}

#[test]
fn urdf_loader_survives_mutated_urdfs() {
    fuzz_target("urdf", Vec::new());
}

#[test]
fn train_config_survives_mutated_toml() {
    fuzz_target("train_config", Vec::new());
}

#[test]
fn reproduce_config_survives_mutated_toml() {
    fuzz_target("reproduce_config", Vec::new());
}

#[test]
fn every_study_config_is_checked_without_a_crash() {
    fuzz_target("study_config", Vec::new());
}

#[test]
fn env_replay_survives_mutated_json() {
    fuzz_target("env_replay", Vec::new());
}

#[test]
fn checkpoint_loading_survives_mutated_bytes() {
    fuzz_target("checkpoint", checkpoint_seeds());
}

/// The checkpoint target is not vacuous: a checkpoint of each small run restores into a
/// fresh one, so mutations of it reach `ModelFree::load`.
#[test]
fn checkpoint_seeds_restore_into_the_small_runs() {
    let seeds = checkpoint_seeds();
    for (mut run, bytes) in fuzz::small_runs().into_iter().zip(&seeds) {
        let ckpt = tandem::nn::Checkpoint::from_bytes(bytes).unwrap();
        run.load(&ckpt).unwrap();
    }
}

/// Writes the checkpoint seeds into `fuzz/corpus/checkpoint/` for libFuzzer
/// (`cargo test --test fuzz_smoke -- --ignored write_checkpoint_corpus`).
#[test]
#[ignore = "writes into the source tree; run once after the checkpoint format changes"]
fn write_checkpoint_corpus() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/checkpoint");
    for (i, c) in checkpoint_seeds().iter().enumerate() {
        std::fs::write(dir.join(format!("small_{i}.safetensors")), c).unwrap();
    }
}
