// The algorithms' build script is the MuJoCo crate's: with the `mujoco` feature it puts the folder
// of libmujoco on the run path of this crate's tests, which run p4's MuJoCo problems.
include!("../mujoco/build.rs");
