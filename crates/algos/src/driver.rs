//! The one resumable driver: an algorithm is a value holding its whole state (agent, model,
//! buffers, generators, counters, the episode in progress) that [`drive`] steps until it is done.
//! MBPO's loop ([`crate::mbpo::Mbpo`], also M-DeMoRL's and p1's), p2's
//! ([`crate::imagined_episodes::ImaginedEpisodes`], [`crate::imagined_pixels::PixelDqn`]), p0's
//! ([`crate::difference_models::DifferenceModels`]), p4's local controllers and MDGPS
//! ([`crate::gps::LocalGps`], [`crate::mdgps::Mdgps`]) and model-free training
//! ([`crate::model_free::ModelFree`], also under p4's DDPG baseline) run on it. The driver owns
//! the bookkeeping the algorithms share: restoring a saved run (refusing another run's
//! checkpoint), stop requests, checkpoints when the algorithm says one is due, and the wall time
//! (summed over every process that ran it, for the algorithms that ask).
//!
//! An algorithm's [`Algorithm::step`] is then its paper's loop body and nothing else. Equal
//! runs save equal bytes (unless they sum wall time), and a resumed run gives exactly the numbers
//! of an uninterrupted one: an algorithm saves everything its later steps read.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use tandem_nn::Checkpoint;

use crate::{AlgoError, Checkpoints, Result};

/// A run of an algorithm as one checkpointable value.
pub trait Algorithm {
    /// What it reports as it goes.
    type Event;
    /// What a finished run returns.
    type Record;
    /// Whether checkpoints carry the wall time, so that a resumed run's is summed over every
    /// process that ran it. Without it equal runs save equal bytes, and [`Algorithm::finish`]
    /// gets the last process's time.
    const SUMS_WALL_TIME: bool = false;
    /// Whether every step boundary is a resume point, so that a stop request saves a checkpoint
    /// before [`drive`] returns [`AlgoError::Stopped`] and loses nothing. Without it the last
    /// checkpoint the algorithm asked for resumes the run.
    const SAVES_ON_STOP: bool = false;

    /// The method's name (the checkpoint's key) and the run's seed.
    fn id(&self) -> (&str, u64);

    /// Work done before the first step of a fresh run (e.g. evaluating the initial policy);
    /// skipped when the run resumes from a checkpoint.
    fn start(&mut self, _on_event: &mut dyn FnMut(Self::Event)) -> Result<()> {
        Ok(())
    }

    /// Whether the run is done.
    fn done(&self) -> bool;

    /// One unit of work (a real step, an episode, an iteration); `Ok(true)` when a checkpoint
    /// is due after it. A step long enough to need it may poll `stop` itself and return
    /// [`AlgoError::Stopped`] (losing the work since the last checkpoint).
    fn step(
        &mut self,
        on_event: &mut dyn FnMut(Self::Event),
        stop: &dyn Checkpoints,
    ) -> Result<bool>;

    /// Writes the whole state into `ckpt`.
    fn save(&self, ckpt: &mut Checkpoint) -> Result<()>;

    /// Restores what [`Algorithm::save`] wrote.
    fn load(&mut self, ckpt: &Checkpoint) -> Result<()>;

    /// The record of the finished run after `wall_seconds` (see [`Algorithm::SUMS_WALL_TIME`]).
    fn finish(self, wall_seconds: f64) -> Result<Self::Record>;
}

/// The run's identity and time, saved beside the algorithm's state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Header {
    method: String,
    seed: u64,
    /// Wall seconds up to this checkpoint, where the algorithm sums them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    wall_seconds: Option<f64>,
}

const HEADER: &str = "run";

/// Runs `algo` to its end: from the checkpoint `store` holds under its name, if any, saving
/// whenever a step says a checkpoint is due, and returning [`AlgoError::Stopped`] at the first
/// step boundary after `store` asks to stop (the last checkpoint resumes the run).
pub fn drive<A: Algorithm>(
    mut algo: A,
    store: &mut dyn Checkpoints,
    on_event: &mut dyn FnMut(A::Event),
) -> Result<A::Record> {
    let t0 = Instant::now();
    let (name, seed) = {
        let (name, seed) = algo.id();
        (name.to_string(), seed)
    };
    let before = match store.load(&name)? {
        Some(ckpt) => {
            let h: Header = ckpt.get_json(HEADER)?;
            crate::ensure_same_run((&h.method, h.seed), (&name, seed))?;
            algo.load(&ckpt)?;
            h.wall_seconds.unwrap_or(0.0)
        }
        None => {
            algo.start(on_event)?;
            0.0
        }
    };
    let save = |algo: &A, store: &mut dyn Checkpoints| -> Result<()> {
        let mut ckpt = Checkpoint::new();
        algo.save(&mut ckpt)?;
        let header = Header {
            method: name.clone(),
            seed,
            wall_seconds: A::SUMS_WALL_TIME.then(|| before + t0.elapsed().as_secs_f64()),
        };
        ckpt.put_json(HEADER, &header)?;
        store.save(&name, &ckpt)
    };
    while !algo.done() {
        if store.stop_requested() {
            if A::SAVES_ON_STOP {
                save(&algo, store)?;
            }
            return Err(AlgoError::Stopped);
        }
        if algo.step(on_event, &*store)? {
            save(&algo, store)?;
        }
    }
    algo.finish(before + t0.elapsed().as_secs_f64())
}

/// Adds the seconds `f` takes to `total`.
pub fn timed<R>(total: &mut f64, f: impl FnOnce() -> R) -> R {
    let t0 = Instant::now();
    let r = f();
    *total += t0.elapsed().as_secs_f64();
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Ephemeral, InMemory};

    /// Sums 1 + 2 + … + `n`, one term a step, checkpointing every `every` steps.
    struct Sum {
        seed: u64,
        n: u64,
        every: u64,
        k: u64,
        total: u64,
    }

    impl Sum {
        fn new(seed: u64) -> Self {
            Self {
                seed,
                n: 10,
                every: 3,
                k: 0,
                total: 0,
            }
        }
    }

    impl Algorithm for Sum {
        type Event = u64;
        type Record = (u64, u64);

        fn id(&self) -> (&str, u64) {
            ("sum", self.seed)
        }

        fn done(&self) -> bool {
            self.k >= self.n
        }

        fn step(&mut self, on_event: &mut dyn FnMut(u64), _: &dyn Checkpoints) -> Result<bool> {
            self.k += 1;
            self.total += self.k;
            on_event(self.k);
            Ok(self.k.is_multiple_of(self.every))
        }

        fn save(&self, ckpt: &mut Checkpoint) -> Result<()> {
            Ok(ckpt.put_json("sum.state", &(self.k, self.total))?)
        }

        fn load(&mut self, ckpt: &Checkpoint) -> Result<()> {
            (self.k, self.total) = ckpt.get_json("sum.state")?;
            Ok(())
        }

        fn finish(self, _wall_seconds: f64) -> Result<(u64, u64)> {
            Ok((self.k, self.total))
        }
    }

    #[test]
    fn a_run_stopped_at_any_step_resumes_from_its_last_checkpoint_to_the_same_record() {
        let whole = drive(Sum::new(0), &mut Ephemeral, &mut |_| {}).unwrap();
        assert_eq!(whole, (10, 55));
        for stop_after in 1..10 {
            let mut store = InMemory::default();
            let stop = store.stop_flag();
            let mut seen = Vec::new();
            let e = drive(Sum::new(0), &mut store, &mut |k| {
                seen.push(k);
                stop.set(k == stop_after);
            })
            .unwrap_err();
            assert!(matches!(e, AlgoError::Stopped), "{e}");
            stop.set(false);
            let resumed = drive(Sum::new(0), &mut store, &mut |k| seen.push(k)).unwrap();
            assert_eq!(resumed, whole, "stopped after step {stop_after}");
            // The steps after the last checkpoint (every 3rd) are done again.
            let redone = stop_after - stop_after / 3 * 3;
            assert_eq!(seen.len() as u64, 10 + redone, "stopped after {stop_after}");
        }
    }

    #[test]
    fn another_runs_checkpoint_is_refused_and_equal_runs_save_equal_bytes() {
        let (mut a, mut b) = (InMemory::default(), InMemory::default());
        drive(Sum::new(1), &mut a, &mut |_| {}).unwrap();
        drive(Sum::new(1), &mut b, &mut |_| {}).unwrap();
        assert_eq!(a.saves(), 3);
        let bytes = |s: &mut InMemory| s.load("sum").unwrap().unwrap().to_bytes().unwrap();
        assert_eq!(bytes(&mut a), bytes(&mut b));
        let e = drive(Sum::new(2), &mut a, &mut |_| {}).unwrap_err();
        assert!(matches!(e, AlgoError::Checkpoint(_)), "{e}");
        assert!(e.to_string().contains("seed 1"), "{e}");
    }
}
