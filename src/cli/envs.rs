//! `tandem envs`: the registered environments.

use tandem::registered_envs as registered;

/// Prints one block per registered environment: id, description, episode limit, spaces.
pub fn run() -> super::Result<()> {
    for spec in registered() {
        super::emit(&format!(
            "{}\n  {}\n  max episode steps: {}\n  observation space: {}\n  action space:      {}",
            spec.id,
            spec.description,
            spec.max_episode_steps,
            spec.observation_space.describe(),
            spec.action_space.describe()
        ))?;
    }
    Ok(())
}
