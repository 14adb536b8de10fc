//! [`SharedWorkspace`]: an [`MlpWorkspace`] (and an input buffer) behind a mutex, for inference
//! through `&self` (a model's `predict`, an agent's batched acting and critic values).

use std::sync::Mutex;

use crate::mlp::MlpWorkspace;

/// Reusable buffers of `&self` inference: a `Vec<f32>` for the network input and an
/// [`MlpWorkspace`], so that repeated calls of one batch size (a planner's rollouts) allocate only
/// their result. Behind a mutex so the owner stays `Sync`; a contended lock falls back to fresh
/// buffers, so callers on several threads never wait and get the same numbers. Cloning gives
/// fresh, empty buffers (a workspace holds no state that outlives a call).
#[derive(Debug, Default)]
pub struct SharedWorkspace(Mutex<(Vec<f32>, MlpWorkspace)>);

impl Clone for SharedWorkspace {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl SharedWorkspace {
    /// Runs `f` on the buffers (or on fresh ones when another thread holds them).
    pub fn with<R>(&self, f: impl FnOnce(&mut Vec<f32>, &mut MlpWorkspace) -> R) -> R {
        match self.0.try_lock() {
            Ok(mut g) => {
                let (x, ws) = &mut *g;
                f(x, ws)
            }
            Err(_) => f(&mut Vec::new(), &mut MlpWorkspace::default()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mlp::{Mlp, MlpConfig};
    use tandem_core::seeding::rng_from_seed;

    #[test]
    fn shared_and_nested_calls_give_the_numbers_of_a_private_workspace() {
        let net = Mlp::new(MlpConfig::new(&[3, 8, 2]), &mut rng_from_seed(1)).unwrap();
        let x = [0.1f32, -0.4, 0.9, 1.0, 0.0, -2.0];
        let want = net.forward(&x, 2, &mut net.workspace()).unwrap().to_vec();
        let shared = SharedWorkspace::default();
        let got = shared.with(|_, ws| net.forward(&x, 2, ws).unwrap().to_vec());
        assert_eq!(got, want);
        // A nested call finds the lock taken and runs on fresh buffers.
        let nested =
            shared.with(|_, _| shared.with(|_, ws| net.forward(&x, 2, ws).unwrap().to_vec()));
        assert_eq!(nested, want);
    }
}
