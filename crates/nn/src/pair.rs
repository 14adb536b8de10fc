//! [`join`]: two closures side by side, the second on a helper thread that stays awake between
//! calls.
//!
//! On the two-core virtual machines this project runs on, a `rayon::join` whose idle worker has
//! gone to sleep costs 50–100 µs before the second half starts (waking a halted virtual CPU);
//! rayon's workers sleep after a few microseconds without work. A planner joins once per
//! prediction, 150 times a plan, with tens of microseconds of serial work between; SAC joins its
//! twin critics a few times per update. The helper here spins for [`SPIN`] after each job before
//! it parks, so a join that follows within that time hands its second half over at once
//! (measured: 2–34 µs of overhead per join against rayon's 48–100 µs, for halves of
//! 100–2000 µs). OpenMP runtimes (PyTorch's threads) spin the same way.
//!
//! Which threads run what never changes a result: callers split work into parts whose numbers do
//! not depend on the thread that computes them.

use std::cell::{Cell, UnsafeCell};
use std::panic::{self, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::OnceLock;
use std::thread::{self, Thread};
use std::time::{Duration, Instant};

/// How long the helper waits for the next job, spinning, before it parks.
pub const SPIN: Duration = Duration::from_micros(300);

const IDLE: u8 = 0;
const POSTED: u8 = 1;
const RUNNING: u8 = 2;
const DONE: u8 = 3;

/// Spins of a caller waiting for the helper's result before it parks.
const WAIT_SPINS: u32 = 1 << 12;

/// A type-erased job: `run(data)` runs it and stores its result behind `data`.
#[derive(Clone, Copy)]
struct Job {
    run: unsafe fn(*mut ()),
    data: *mut (),
}

/// The helper's mailbox: one caller at a time (`claimed`) writes `job` and `waiter`, then `state`
/// goes `IDLE → POSTED` (caller) `→ RUNNING → DONE` (helper) `→ IDLE` (caller), or back
/// `POSTED → IDLE` when the caller takes its job back before the helper started it (a helper
/// that the operating system has not scheduled, on a machine with more busy threads than cores).
struct Mailbox {
    claimed: AtomicBool,
    state: AtomicU8,
    job: UnsafeCell<Job>,
    waiter: UnsafeCell<Option<Thread>>,
}

// SAFETY: `job` and `waiter` are written only by the caller holding `claimed`, before it publishes
// the job with a release store of `POSTED`, and read only by the helper after it won the
// `POSTED → RUNNING` exchange (acquire), until its release store of `DONE`.
unsafe impl Sync for Mailbox {}

unsafe fn no_job(_: *mut ()) {}

static MAILBOX: Mailbox = Mailbox {
    claimed: AtomicBool::new(false),
    state: AtomicU8::new(IDLE),
    job: UnsafeCell::new(Job {
        run: no_job,
        data: std::ptr::null_mut(),
    }),
    waiter: UnsafeCell::new(None),
};

thread_local! {
    /// Set on the helper, and on a caller from posting its second closure until that is done: a
    /// join nested in either runs its closures one after the other (both cores are busy already).
    static IN_PAIR: Cell<bool> = const { Cell::new(false) };
}

/// The helper thread, started on first use (`None` if it could not be spawned).
fn helper() -> Option<&'static Thread> {
    static HELPER: OnceLock<Option<Thread>> = OnceLock::new();
    HELPER
        .get_or_init(|| {
            thread::Builder::new()
                .name("tandem-join".into())
                .spawn(helper_loop)
                .ok()
                .map(|h| h.thread().clone())
        })
        .as_ref()
}

fn helper_loop() {
    IN_PAIR.with(|p| p.set(true));
    loop {
        let idle_since = Instant::now();
        let mut spins = 0u32;
        loop {
            if MAILBOX.state.load(Ordering::Relaxed) == POSTED
                && MAILBOX
                    .state
                    .compare_exchange(POSTED, RUNNING, Ordering::Acquire, Ordering::Relaxed)
                    .is_ok()
            {
                break;
            }
            spins = spins.wrapping_add(1);
            if spins.is_multiple_of(64) {
                if idle_since.elapsed() > SPIN {
                    // `unpark` after the job is posted wakes this, or makes it return at once.
                    thread::park();
                } else {
                    // Let another runnable thread of this core go first.
                    thread::yield_now();
                }
            } else {
                std::hint::spin_loop();
            }
        }
        // SAFETY: see `Mailbox`: this thread won the job.
        let (job, waiter) = unsafe { (*MAILBOX.job.get(), (*MAILBOX.waiter.get()).clone()) };
        // SAFETY: the caller keeps `job.data` alive until it sees `DONE`; `run` catches panics.
        unsafe { (job.run)(job.data) };
        MAILBOX.state.store(DONE, Ordering::Release);
        if let Some(w) = waiter {
            w.unpark();
        }
    }
}

/// A posted closure and, once run, its result.
struct Slot<B, RB> {
    f: Option<B>,
    out: Option<thread::Result<RB>>,
}

/// Runs the closure of a [`Slot`] behind `data`, keeping its result or panic.
unsafe fn run_slot<B: FnOnce() -> RB, RB>(data: *mut ()) {
    // SAFETY: `data` is the caller's `Slot<B, RB>`, alive until the caller sees `DONE`.
    let slot = unsafe { &mut *data.cast::<Slot<B, RB>>() };
    if let Some(f) = slot.f.take() {
        slot.out = Some(panic::catch_unwind(AssertUnwindSafe(f)));
    }
}

/// Runs `a` and `b`, potentially in parallel, returning both results (as `rayon::join`).
///
/// With exactly two threads in rayon's pool (the project's two-core machines), a call from a
/// thread outside the pool runs `b` on a helper thread that keeps spinning briefly between jobs
/// (see the module docs); a call from inside the pool, one made while the helper is taken by
/// another thread, or one with more threads goes to `rayon::join`; a call nested in a pair
/// (inside `a` or `b`), or with one thread, runs `a` then `b` here. If the helper has not started
/// `b` when `a` is done (on a machine with more busy threads than cores the operating system may
/// not have scheduled it), `b` runs here too, and a caller waiting for a started `b` parks after a
/// short spin: a busy machine costs no more than running the two in turn. A panic in either
/// closure is raised here once both have finished.
///
/// ```
/// let data = vec![1.0f32; 1000];
/// let (lo, hi) = tandem_nn::join(|| data[..500].iter().sum::<f32>(), || data[500..].iter().sum::<f32>());
/// assert_eq!(lo + hi, 1000.0);
/// ```
pub fn join<A, B, RA, RB>(a: A, b: B) -> (RA, RB)
where
    A: FnOnce() -> RA + Send,
    B: FnOnce() -> RB + Send,
    RA: Send,
    RB: Send,
{
    join_with(rayon::current_num_threads(), a, b)
}

/// [`join`] as if rayon's pool had `threads` threads.
fn join_with<A, B, RA, RB>(threads: usize, a: A, b: B) -> (RA, RB)
where
    A: FnOnce() -> RA + Send,
    B: FnOnce() -> RB + Send,
    RA: Send,
    RB: Send,
{
    if IN_PAIR.with(Cell::get) || threads < 2 {
        return (a(), b());
    }
    if threads != 2 || rayon::current_thread_index().is_some() {
        return rayon::join(a, b);
    }
    let Some(helper) = helper() else {
        return rayon::join(a, b);
    };
    if MAILBOX
        .claimed
        .compare_exchange(false, true, Ordering::Acquire, Ordering::Relaxed)
        .is_err()
    {
        return rayon::join(a, b);
    }
    let mut slot = Slot::<B, RB> {
        f: Some(b),
        out: None,
    };
    // SAFETY: this thread holds `claimed`; the helper reads the job only after `POSTED`.
    unsafe {
        *MAILBOX.job.get() = Job {
            run: run_slot::<B, RB>,
            data: (&mut slot as *mut Slot<B, RB>).cast(),
        };
        *MAILBOX.waiter.get() = Some(thread::current());
    }
    MAILBOX.state.store(POSTED, Ordering::Release);
    helper.unpark();
    IN_PAIR.with(|p| p.set(true));
    let ra = panic::catch_unwind(AssertUnwindSafe(a));
    if MAILBOX
        .state
        .compare_exchange(POSTED, IDLE, Ordering::Acquire, Ordering::Relaxed)
        .is_ok()
    {
        // The helper had not started `b`: run it here.
        // SAFETY: the job is no longer posted, so the helper will not touch `slot`.
        unsafe { run_slot::<B, RB>((&mut slot as *mut Slot<B, RB>).cast()) };
    } else {
        // `slot` is borrowed by the helper until `DONE`: wait for it even if `a` panicked.
        let mut spins = 0u32;
        while MAILBOX.state.load(Ordering::Acquire) != DONE {
            spins = spins.wrapping_add(1);
            if spins < WAIT_SPINS {
                std::hint::spin_loop();
            } else {
                // The helper unparks this thread after `DONE`.
                thread::park();
            }
        }
    }
    IN_PAIR.with(|p| p.set(false));
    MAILBOX.state.store(IDLE, Ordering::Relaxed);
    MAILBOX.claimed.store(false, Ordering::Release);
    let rb = slot.out.take().expect("the helper ran the posted closure");
    match (ra, rb) {
        (Ok(ra), Ok(rb)) => (ra, rb),
        (Err(p), _) | (_, Err(p)) => panic::resume_unwind(p),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::on_threads;

    /// From outside a two-thread pool, `b` runs on the helper; nested joins run in place; both
    /// results come back; borrowed data is shared safely.
    #[test]
    fn second_closure_runs_on_the_helper_and_nested_joins_in_place() {
        use std::sync::atomic::AtomicBool;
        let here = thread::current().id();
        let data: Vec<u64> = (0..10_000).collect();
        // `a` waits until `b` has started, so `b` cannot be taken back; another test may hold
        // the helper for a moment (then rayon runs `b`): try again.
        let on_helper = (0..200).any(|_| {
            let started = AtomicBool::new(false);
            let (ta, (tb, nested)) = join_with(
                2,
                || {
                    let t0 = Instant::now();
                    while !started.load(Ordering::Acquire) && t0.elapsed() < Duration::from_secs(5)
                    {
                        std::hint::spin_loop();
                    }
                    (thread::current().id(), data[..5000].iter().sum::<u64>())
                },
                || {
                    started.store(true, Ordering::Release);
                    let inner = join_with(2, || thread::current().id(), || thread::current().id());
                    (
                        (
                            thread::current().id(),
                            data[5000..].iter().sum::<u64>(),
                            thread::current().name() == Some("tandem-join"),
                        ),
                        inner,
                    )
                },
            );
            assert_eq!(ta.1 + tb.1, data.iter().sum::<u64>());
            // On the helper: `a` here, and a join nested in `b` wholly on the helper.
            tb.2 && ta.0 == here && nested == (tb.0, tb.0)
        });
        assert!(on_helper);
        // Many joins from several threads at once (the helper taken: rayon), all correct.
        thread::scope(|s| {
            for t in 0..4u64 {
                let data = &data;
                s.spawn(move || {
                    for k in 0..500u64 {
                        let (x, y) =
                            join_with(2, || data[k as usize] + t, || data[(k + 1) as usize] * t);
                        assert_eq!((x, y), (k + t, (k + 1) * t));
                    }
                });
            }
        });
        // Inside a pool: rayon's join.
        let in_pool = on_threads(2, || join_with(2, || 1, || 2));
        assert_eq!(in_pool, (1, 2));
    }

    /// A panic in either closure comes out of `join` after both finished, and the helper serves
    /// the next call.
    #[test]
    fn panics_propagate_and_the_helper_survives() {
        for which in [0, 1] {
            let r = panic::catch_unwind(|| {
                join_with(
                    2,
                    || {
                        if which == 0 {
                            panic!("a");
                        }
                        1
                    },
                    || {
                        if which == 1 {
                            panic!("b");
                        }
                        2
                    },
                )
            });
            assert!(r.is_err());
            assert_eq!(join_with(2, || 3, || 4), (3, 4));
        }
    }
}
