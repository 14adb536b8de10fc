//! Min-of-N timing of one SAC update at stable-baselines3's defaults (batch 256, 2x256 hidden,
//! Pendulum-v1's 3 observations and 1 action), for comparing variants on a loaded machine, and a
//! checksum of the parameters after the run (equal checksums: bit-identical numerics).
//!
//! Run: `cargo run --release -p tandem-agents --example sac_update_timing -- [N] [gemm_threads]`.

use std::time::Instant;

use rand::Rng as _;
use tandem_agents::{Batch, OffPolicyAgent, ReplayBuffer, Sac, SacConfig, TransitionRef};
use tandem_core::seeding::rng_from_seed;
use tandem_core::Space;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(300);
    let threads: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    tandem_nn::set_gemm_threads(threads);
    let mut rng = rng_from_seed(0);
    let obs = Space::boxed(vec![-1.0, -1.0, -8.0], vec![1.0, 1.0, 8.0]);
    let act = Space::symmetric(1, 2.0);
    let mut buf = ReplayBuffer::new(20_000, 3, 1).unwrap();
    for _ in 0..20_000 {
        let o: Vec<f64> = (0..3).map(|_| rng.random_range(-1.0..1.0)).collect();
        let nx: Vec<f64> = (0..3).map(|_| rng.random_range(-1.0..1.0)).collect();
        let a: f64 = rng.random_range(-2.0..2.0);
        buf.push(TransitionRef {
            obs: &o,
            action: &[a],
            reward: rng.random_range(-16.0..0.0),
            next_obs: &nx,
            terminated: false,
        })
        .unwrap();
    }
    let mut batch = Batch::zeros(256, 3, 1);
    let mut sac = Sac::new(SacConfig::default(), &obs, &act, 0).unwrap();
    let mut times = Vec::with_capacity(n);
    for _ in 0..n {
        buf.sample_into(&mut rng, &mut batch, 0..256).unwrap();
        let t0 = Instant::now();
        sac.update(&batch).unwrap();
        times.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    let sum: u64 = sac.actor_params().iter().fold(0u64, |h, v| {
        (h ^ u64::from(v.to_bits())).wrapping_mul(0x0100_0000_01b3)
    });
    println!(
        "n {n} threads {threads}: min {:.3} ms  p10 {:.3}  median {:.3} ms  checksum {sum:016x}",
        times[0],
        times[n / 10],
        times[n / 2]
    );
}
