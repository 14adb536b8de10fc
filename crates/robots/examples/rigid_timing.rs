//! Per-call timing of the rigid-body algorithms on the 7-DoF fixture arm (`arm7.urdf`) and of the
//! biped plant's linearization, robust to a loaded machine: each algorithm runs in batches, a
//! batch is timed in this thread's CPU time (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`, Linux) and the fastest batch counts (min-of-N), so other processes only ever make a batch
//! slower.
//!
//! ```text
//! cargo run --release -p tandem-robots --example rigid_timing            # all, min of 200 batches
//! cargo run --release -p tandem-robots --example rigid_timing -- crba 1000000   # one, N calls
//! cargo run --release -p tandem-robots --example rigid_timing -- pinocchio       # 5 × 100k, median
//! ```
//!
//! `rigid_timing pinocchio` times ABA, RNEA and CRBA as the Pinocchio figures it is compared with
//! were timed: the median of 5 batches of 100 000 calls, wall clock.
//!
//! `rigid_timing NAME N` runs one algorithm `N` times and prints nothing else, for instruction counts:
//! `valgrind --tool=callgrind target/release/examples/rigid_timing crba 100000`.

use nalgebra::DVector;
use std::hint::black_box;
use std::time::Instant;
use tandem_dynamics::rigid::{aba, aba_derivatives, crba, rnea, Data, Model};
use tandem_dynamics::rigid_plant::{RigidBodyPlant, RigidPlantConfig};
use tandem_robots::leo::{leo_plant, leo_true_overrides, standing_state};

/// `struct timespec` of 64-bit Linux.
#[repr(C)]
struct Timespec {
    sec: i64,
    nsec: i64,
}

extern "C" {
    /// POSIX `clock_gettime` (from the C library that std already links).
    fn clock_gettime(clock: i32, tp: *mut Timespec) -> i32;
}

/// This thread's CPU time in seconds (`CLOCK_THREAD_CPUTIME_ID`), or wall time since `t0` where
/// that clock fails.
fn now(t0: &Instant) -> f64 {
    const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
    let mut ts = Timespec { sec: 0, nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec; the call writes only into it.
    if unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut ts) } == 0 {
        ts.sec as f64 + ts.nsec as f64 * 1e-9
    } else {
        t0.elapsed().as_secs_f64()
    }
}

const Q: [f64; 7] = [0.3, -0.5, 1.1, -1.2, 0.4, 0.9, -2.0];
const V: [f64; 7] = [0.5, -1.0, 2.0, 0.3, -0.7, 1.5, -2.5];
const A: [f64; 7] = [1.0, -2.0, 3.0, -4.0, 5.0, -6.0, 7.0];
const TAU: [f64; 7] = [10.0, -20.0, 5.0, 3.0, -1.0, 2.0, 0.5];

fn arm7() -> Model {
    Model::from_urdf_file(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/fixtures/pinocchio/arm7.urdf"
    ))
    .expect("arm7.urdf parses")
}

/// The biped in contact, sliding slightly, with mid-range voltages (as in `benches/dynamics.rs`).
fn biped() -> (RigidBodyPlant, DVector<f64>, DVector<f64>) {
    let plant = leo_plant(RigidPlantConfig::default(), &leo_true_overrides()).expect("biped");
    let mut x = standing_state(plant.model());
    let n = plant.model().nv();
    x[1] -= 0.001;
    x[n] = 0.03;
    x[n + 3] = 0.2;
    let u = DVector::from_vec(vec![1.5, -2.0, 0.7, -1.0, 2.5, -0.4]);
    (plant, x, u)
}

/// Runs `name` once.
fn call(
    name: &str,
    model: &Model,
    data: &mut Data,
    b: &(RigidBodyPlant, DVector<f64>, DVector<f64>),
) {
    match name {
        "aba" => {
            aba(model, data, black_box(&Q), black_box(&V), black_box(&TAU));
        }
        "rnea" => {
            rnea(model, data, black_box(&Q), black_box(&V), black_box(&A));
        }
        "crba" => {
            crba(model, data, black_box(&Q));
        }
        "aba_derivatives" => {
            aba_derivatives(model, data, black_box(&Q), black_box(&V), black_box(&TAU))
        }
        "linearize_analytic" => {
            black_box(b.0.linearize_analytic(b.1.as_slice(), b.2.as_slice()));
        }
        "linearize_fd" => {
            black_box(b.0.linearize_fd(&b.1, &b.2));
        }
        other => panic!("unknown algorithm '{other}'"),
    }
}

fn main() {
    let model = arm7();
    let mut data = Data::new(&model);
    let b = biped();
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let [mode] = args.as_slice() {
        assert_eq!(mode, "pinocchio", "one argument: `pinocchio`");
        // The protocol of the Pinocchio figures it is compared with: wall time of 5 batches of
        // 100 000 calls each, the median batch's mean per call.
        for name in ["aba", "rnea", "crba"] {
            let mut per_call: Vec<f64> = (0..5)
                .map(|_| {
                    let t = Instant::now();
                    for _ in 0..100_000 {
                        call(name, &model, &mut data, &b);
                    }
                    t.elapsed().as_secs_f64() / 100_000.0
                })
                .collect();
            per_call.sort_by(f64::total_cmp);
            println!(
                "{name:>20}: {:10.3} µs per call (median of 5 batches of 100000, wall)",
                per_call[2] * 1e6
            );
        }
        return;
    }
    if let [name, n] = args.as_slice() {
        let n: usize = n.parse().expect("call count");
        for _ in 0..n {
            call(name, &model, &mut data, &b);
        }
        return;
    }
    let algos = [
        ("aba", 1000),
        ("rnea", 1000),
        ("crba", 1000),
        ("aba_derivatives", 200),
        ("linearize_analytic", 1),
        ("linearize_fd", 1),
    ];
    for (name, batch) in algos {
        let batches = if batch == 1 { 30 } else { 200 };
        let mut best = f64::INFINITY;
        let t0 = Instant::now();
        for _ in 0..batches {
            let t = now(&t0);
            for _ in 0..batch {
                call(name, &model, &mut data, &b);
            }
            best = best.min((now(&t0) - t) / batch as f64);
        }
        println!(
            "{name:>20}: {:10.3} µs per call (min of {batches} batches of {batch})",
            best * 1e6
        );
    }
}
