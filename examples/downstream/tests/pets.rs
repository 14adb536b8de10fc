//! PETS on a plant and task of our own learns the cart within two refits: its last episode
//! comes within 30 % of the same planner through the true cart, from the same start, and far
//! above the random episode.

use tandem_downstream::{pets, planned_through_the_cart};

#[test]
fn pets_learns_the_cart_from_three_episodes() {
    let seed = 7;
    let returns = pets(seed, 2).unwrap();
    let last = *returns.last().unwrap();
    let oracle = planned_through_the_cart(seed + 2).unwrap();
    eprintln!("returns {returns:?}, through the true cart {oracle}");
    assert!(last >= 1.3 * oracle, "{last} vs {oracle}");
    assert!(last > 0.5 * returns[0], "{last} vs random {}", returns[0]);
}
