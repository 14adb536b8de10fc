// The MuJoCo crate's build script: with the `mujoco` feature it puts the folder of libmujoco on
// the run path of this crate's tests, which load p4's scenes.
include!("../mujoco/build.rs");
