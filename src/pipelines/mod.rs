//! The papers' loops, generic over the traits: each composes a plant or environment, a model, a
//! planner and an agent. Filled by the reproduction issues.
