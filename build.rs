// The facade's build script is the MuJoCo crate's: with the `mujoco` feature it puts the folder of
// libmujoco on the run path of the `tandem` binary and the facade's tests, examples and benches.
include!("crates/mujoco/build.rs");
