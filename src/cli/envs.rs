//! `tandem envs`: the registered environments.

use tandem_envs::registered;

/// Prints one block per registered environment: id, description, episode limit, spaces.
pub fn run() -> super::Result<()> {
    for spec in registered() {
        println!("{}", spec.id);
        println!("  {}", spec.description);
        println!("  max episode steps: {}", spec.max_episode_steps);
        println!("  observation space: {}", spec.observation_space.describe());
        println!("  action space:      {}", spec.action_space.describe());
    }
    Ok(())
}
