#!/usr/bin/env bash
# Installs what `--features mujoco` needs, all under the git-ignored `.mujoco/` of the repository:
#   .mujoco/venv/    a Python venv with mujoco==3.17.0 (the shared library) and gymnasium[mujoco]==1.4.0
#                    (the MJCF assets of the v5 tasks, and the reference for benches and parity checks)
#   .mujoco/lib/     libmujoco.so and libmujoco.so.3.17.0, symlinks into the installed mujoco wheel
#   .mujoco/assets   a symlink to gymnasium's installed MJCF assets (MIT; linked, never copied)
# After it, `cargo build/test/run --features mujoco` work with no environment variables
# (`.cargo/config.toml` points mujoco-rs at .mujoco/lib; build scripts add it as the run path).
#
# Exit status: 0 when the setup is complete, 3 when PyPI cannot be reached (said loudly on stderr;
# `.ci/run` then skips the feature's checks), 1 on any other failure.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT="$PWD"
DIR="$ROOT/.mujoco"
VENV="$DIR/venv"
PYTHON="${PYTHON:-python3}"
MUJOCO_VERSION="3.17.0"          # must match mujoco-rs =7.0.0 (7.0.0+mj-3.17.0), which checks it at start
GYMNASIUM_VERSION="1.4.0"

mkdir -p "$DIR"
if [ ! -x "$VENV/bin/python" ]; then
    "$PYTHON" -m venv "$VENV"
fi

have() {
    "$VENV/bin/python" - "$MUJOCO_VERSION" "$GYMNASIUM_VERSION" <<'PY' 2>/dev/null
import sys, importlib.metadata as md
ok = md.version("mujoco") == sys.argv[1] and md.version("gymnasium") == sys.argv[2]
md.version("imageio")  # gymnasium's [mujoco] extra; gymnasium.make of a MuJoCo task needs it
sys.exit(0 if ok else 1)
PY
}

if ! have; then
    log="$DIR/pip.log"
    if ! "$VENV/bin/pip" install --disable-pip-version-check --quiet \
        "mujoco==$MUJOCO_VERSION" "gymnasium[mujoco]==$GYMNASIUM_VERSION" >"$log" 2>&1; then
        if grep -qiE "connection|network|resolve|timed out|temporary failure|no matching distribution|could not find a version" "$log"; then
            {
                echo "================================================================"
                echo "setup-mujoco: CANNOT REACH PyPI to install mujoco==$MUJOCO_VERSION and"
                echo "gymnasium[mujoco]==$GYMNASIUM_VERSION; the mujoco feature is NOT set up."
                echo "pip said (last lines of $log):"
                tail -n 5 "$log"
                echo "================================================================"
            } >&2
            exit 3
        fi
        cat "$log" >&2
        echo "setup-mujoco: pip failed (see above)" >&2
        exit 1
    fi
fi

site_path() {
    "$VENV/bin/python" -c "import importlib.util, os; print(os.path.dirname(importlib.util.find_spec('$1').origin))"
}
MJ="$(site_path mujoco)"
GYM="$(site_path gymnasium)"
LIB="$MJ/libmujoco.so.$MUJOCO_VERSION"
[ -f "$LIB" ] || { echo "setup-mujoco: $LIB not found in the wheel" >&2; exit 1; }
ASSETS="$GYM/envs/mujoco/assets"
[ -f "$ASSETS/half_cheetah.xml" ] || { echo "setup-mujoco: gymnasium's assets not found at $ASSETS" >&2; exit 1; }

mkdir -p "$DIR/lib"
ln -sfn "$LIB" "$DIR/lib/libmujoco.so"                      # the name mujoco-rs's build script looks for
ln -sfn "$LIB" "$DIR/lib/libmujoco.so.$MUJOCO_VERSION"      # the SONAME the loader looks for
ln -sfn "$ASSETS" "$DIR/assets"
echo "setup-mujoco: ready (mujoco $MUJOCO_VERSION, gymnasium $GYMNASIUM_VERSION) under $DIR"
