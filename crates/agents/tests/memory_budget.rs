//! Oversized configurations are refused with their memory estimate before anything is
//! allocated. A counting allocator records the largest single allocation, so "before
//! allocation" is measured, not assumed. (One test in this binary: the count is process-wide.)

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use tandem_agents::{AgentError, DdpgConfig, Sac, SacConfig};
use tandem_agents::{Ddpg, ReplayBuffer};
use tandem_core::Space;

struct Counting;

static LARGEST: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        System.alloc(layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        System.alloc_zeroed(layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LARGEST.fetch_max(new_size, Ordering::Relaxed);
        System.realloc(ptr, layout, new_size)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Runs `f`, returning its result and the largest single allocation it made.
fn largest_allocation<T>(f: impl FnOnce() -> T) -> (T, usize) {
    LARGEST.store(0, Ordering::Relaxed);
    let out = f();
    (out, LARGEST.load(Ordering::Relaxed))
}

fn assert_memory_error(e: AgentError, needles: &[&str]) {
    let msg = e.to_string();
    assert!(matches!(e, AgentError::Memory(_)), "{msg}");
    for n in needles {
        assert!(msg.contains(n), "lacks {n:?}: {msg}");
    }
}

#[test]
fn oversized_networks_and_buffers_are_refused_before_allocation() {
    let pendulum_obs = Space::symmetric(3, 8.0);
    let torque = Space::symmetric(1, 2.0);

    // Four hidden layers of 16384 pass the per-layer range check...
    let sac = SacConfig {
        hidden: vec![16384; 4],
        ..Default::default()
    };
    sac.validate().unwrap();
    // ... and need, by hand: actor 3·16384 + 16384 + 3·(16384² + 16384) + 16384·2 + 2 params
    // in 4 buffers (params, gradients, Adam's moments), two critics of 4·16384 + 16384 +
    // 3·(16384² + 16384) + 16384 + 1 params in 5 (and a target), 4 B each: about 42 GiB.
    let actor: u64 = 3 * 16384 + 16384 + 3 * (16384 * 16384 + 16384) + 16384 * 2 + 2;
    let critic: u64 = 4 * 16384 + 16384 + 3 * (16384 * 16384 + 16384) + 16384 + 1;
    let params_bytes = 4 * (4 * actor + 2 * 5 * critic);
    // Activations: 3 nets × batch 256 × 65541 widths × 3 buffers × 4 B; the replay buffer:
    // 10^6 transitions × (2·3 + 1 + 2) floats × 4 B; a minibatch of 256 of them.
    let activations: u64 = 3 * 256 * 65541 * 3 * 4;
    let replay: u64 = 1_000_000 * 9 * 4 + 256 * 9 * 4;
    assert_eq!(
        sac.memory(3, 1).total(),
        Some(params_bytes + activations + replay)
    );
    let (r, largest) = largest_allocation(|| Sac::new(sac, &pendulum_obs, &torque, 0));
    assert_memory_error(
        r.unwrap_err(),
        &[
            "sac (obs 3, act 1)",
            "estimated memory 42.",
            "GiB",
            "TANDEM_MEMORY_LIMIT",
        ],
    );
    assert!(
        largest < 1 << 20,
        "allocated {largest} bytes before refusing"
    );

    #[cfg(feature = "pixels")]
    {
        use tandem_agents::{ConvQNetConfig, Dqn, DqnConfig, QNetwork};
        // A conv layer of 100,000 channels on p2's 16x16 images: feature maps of gigabytes.
        let dqn = DqnConfig {
            network: QNetwork::Conv,
            conv: ConvQNetConfig {
                channels: vec![100_000],
                kernels: vec![3],
                strides: vec![1],
                ..Default::default()
            },
            ..Default::default()
        };
        dqn.validate().unwrap();
        let image = Space::Box {
            low: vec![0.0; 768],
            high: vec![1.0; 768],
            shape: vec![16, 16, 3],
        };
        let (r, largest) =
            largest_allocation(|| Dqn::new(dqn, &image, &Space::discrete(4), 0).map(|_| ()));
        assert_memory_error(
            r.unwrap_err(),
            &["dqn (obs 768, 4 actions)", "fully connected layers"],
        );
        assert!(
            largest < 1 << 20,
            "allocated {largest} bytes before refusing"
        );
    }

    // A replay buffer of 10^12 transitions; its size overflows nothing but the machine.
    let ddpg = DdpgConfig {
        buffer_size: 1_000_000_000_000,
        ..Default::default()
    };
    let (r, largest) =
        largest_allocation(|| Ddpg::new(ddpg, &pendulum_obs, &torque, 0).map(|_| ()));
    assert_memory_error(r.unwrap_err(), &["largest part: replay buffer", "TiB"]);
    assert!(
        largest < 1 << 20,
        "allocated {largest} bytes before refusing"
    );
    let (r, largest) = largest_allocation(|| ReplayBuffer::new(usize::MAX / 2, 3, 1).map(|_| ()));
    assert_memory_error(r.unwrap_err(), &["replay buffer of", "more than 16 EiB"]);
    assert!(
        largest < 1 << 20,
        "allocated {largest} bytes before refusing"
    );

    // The defaults still build.
    Sac::new(SacConfig::default(), &pendulum_obs, &torque, 0).unwrap();
}
