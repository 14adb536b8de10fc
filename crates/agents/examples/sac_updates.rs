//! A fixed number of SAC updates at the `sac_update` bench's sizes (Pendulum-v1: 3 observations,
//! 1 action; minibatch 256; SAC defaults), for instruction counts under callgrind, which do not
//! depend on how busy the machine is. Two counts with different `UPDATES` give the cost of one
//! update without the set-up (filling the replay buffer, building the networks):
//!
//! ```text
//! cargo build --release -p tandem-agents --example sac_updates
//! RAYON_NUM_THREADS=1 valgrind --tool=callgrind target/release/examples/sac_updates 100
//! RAYON_NUM_THREADS=1 valgrind --tool=callgrind target/release/examples/sac_updates 300
//! ```
//!
//! The whole run is one task of rayon's pool, so with one rayon thread the twin-critic `join`s
//! run in turn on that thread and no worker spins while waiting (spinning would add a varying
//! number of instructions). Prints a checksum of the metrics and actor parameters.

use rand::Rng as _;
use tandem_agents::{Batch, OffPolicyAgent, ReplayBuffer, Sac, SacConfig, TransitionRef};
use tandem_core::seeding::rng_from_seed;
use tandem_core::Space;

fn run(updates: usize) -> f64 {
    tandem_nn::set_gemm_threads(1);
    let mut rng = rng_from_seed(0);
    let obs = Space::boxed(vec![-1.0, -1.0, -8.0], vec![1.0, 1.0, 8.0]);
    let act = Space::symmetric(1, 2.0);
    let mut buf = ReplayBuffer::new(20_000, 3, 1).expect("buffer");
    for _ in 0..20_000 {
        let o: Vec<f64> = (0..3).map(|_| rng.random_range(-1.0..1.0)).collect();
        let next: Vec<f64> = (0..3).map(|_| rng.random_range(-1.0..1.0)).collect();
        buf.push(TransitionRef {
            obs: &o,
            action: &[rng.random_range(-2.0..2.0)],
            reward: rng.random_range(-16.0..0.0),
            next_obs: &next,
            terminated: false,
        })
        .expect("push");
    }
    let mut batch = Batch::zeros(256, 3, 1);
    let mut sac = Sac::new(SacConfig::default(), &obs, &act, 0).expect("sac");
    let mut sum = 0.0;
    for _ in 0..updates {
        buf.sample_into(&mut rng, &mut batch, 0..256)
            .expect("sample");
        let m = sac.update(&batch).expect("update");
        sum += m.get("critic_loss").unwrap_or(0.0) + m.get("actor_loss").unwrap_or(0.0);
    }
    sum + sac
        .actor_params()
        .iter()
        .map(|p| f64::from(*p))
        .sum::<f64>()
}

fn main() {
    let updates = std::env::args()
        .nth(1)
        .map_or(Ok(100), |a| a.parse::<usize>())
        .expect("usage: sac_updates [UPDATES]");
    let (sum, ()) = tandem_nn::join(|| run(updates), || ());
    println!("{updates} updates, checksum {sum:.9e}");
}
