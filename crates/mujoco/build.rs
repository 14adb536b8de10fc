// With the `mujoco` feature: adds the folder of the linked libmujoco (`MUJOCO_DYNAMIC_LINK_DIR`,
// set by the workspace's `.cargo/config.toml`) to the run path of this crate's tests, examples
// and benches, so they start with no `LD_LIBRARY_PATH`. Without the feature it does nothing.
// `pub` so that a build script with more to do can call it from a module (tandem-studies').
pub fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if std::env::var_os("CARGO_FEATURE_MUJOCO").is_some() {
        if let Some(dir) = std::env::var_os("MUJOCO_DYNAMIC_LINK_DIR") {
            println!("cargo::rustc-link-arg=-Wl,-rpath,{}", dir.to_string_lossy());
        }
    }
}
