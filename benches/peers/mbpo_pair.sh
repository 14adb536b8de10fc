#!/usr/bin/env bash
# MBPO's whole run, tandem against mbrl-lib 0.2.0, on HalfCheetah: the same short run on both
# sides (benches/peers/mbpo_tandem.toml and benches/peers/mbpo_mbrl.py), alternately, tandem
# first (A B A B ...), N pairs. Prints each run's wall time, its split (SAC updates, model
# training, model rollouts, the rest) and its evaluation returns, then the ratios tandem/mbrl-lib,
# the median over the pairs (docs/performance.md).
#
# Pair only on a quiet machine (nothing else running) with libgomp's default wait policy:
# under load, PyTorch's spinning OpenMP threads slow it several times over, and
# OMP_WAIT_POLICY=PASSIVE, which avoids that, slows it on a quiet machine. This script unsets
# OMP_WAIT_POLICY and says when the load average was not near zero.
#
# usage: benches/peers/mbpo_pair.sh --python VENV/bin/python [options]
#   --python PATH      the Python of a venv with mbrl-lib 0.2.0 (or MBRL_PYTHON); the measurer's,
#                      never installed by the project (docs/performance.md)
#   --pairs N          pairs to run (default 3)
#   --updates G        SAC updates per real step on both sides (default 4; mbrl-lib's
#                      HalfCheetah configuration: 10)
#   --threads T        threads on both sides: tandem's RAYON_NUM_THREADS, torch's (default 2)
#   --tandem PATH      the tandem program, built with `--features mujoco` (default
#                      target/release/tandem)
#   --out DIR          where the runs go (default runs/mbpo-pair__<time>)
#   --check            check both sides' settings and installs, run nothing
#   --smoke            a tiny run on both sides (700 real steps, refits of 2 epochs every 50),
#                      to try the command lines; its figures mean nothing
#   --tandem-only      run tandem's side alone (no Python needed but python3 for the report)
set -euo pipefail

die() {
    echo "mbpo_pair.sh: $*" >&2
    exit 2
}

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$here/../.." && pwd)
python=${MBRL_PYTHON:-}
pairs=3
updates=4
threads=2
tandem=$root/target/release/tandem
out=
check=0
smoke=0
tandem_only=0
while [ $# -gt 0 ]; do
    case $1 in
    --python) python=${2:?--python needs a path}; shift 2 ;;
    --pairs) pairs=${2:?--pairs needs a count}; shift 2 ;;
    --updates) updates=${2:?--updates needs a count}; shift 2 ;;
    --threads) threads=${2:?--threads needs a count}; shift 2 ;;
    --tandem) tandem=${2:?--tandem needs a path}; shift 2 ;;
    --out) out=${2:?--out needs a directory}; shift 2 ;;
    --check) check=1; shift ;;
    --smoke) smoke=1; shift ;;
    --tandem-only) tandem_only=1; shift ;;
    -h | --help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) die "unknown argument '$1' (--help lists them)" ;;
    esac
done
for n in "$pairs" "$updates" "$threads"; do
    [[ $n =~ ^[1-9][0-9]*$ ]] || die "'$n' is not a positive count"
done

# ---- what each side needs, refused loudly when missing ----
[ -x "$tandem" ] || die "no tandem program at $tandem: build it with
    cargo build --release --features mujoco   (after scripts/setup-mujoco.sh)
or name it with --tandem PATH"
if [ "$tandem_only" = 0 ]; then
    [ -n "$python" ] || die "no Python for mbrl-lib's side: make a venv of your own with mbrl-lib 0.2.0
(docs/performance.md, 'MBPO's whole run') and pass --python VENV/bin/python or set MBRL_PYTHON;
--tandem-only runs tandem's side alone"
    [ -x "$python" ] || die "--python $python is not an executable"
    report_python=$python
else
    report_python=$(command -v python3 || true)
    [ -n "$report_python" ] || die "--tandem-only needs python3 for the report"
fi

if [ -n "${OMP_WAIT_POLICY:-}" ]; then
    echo "mbpo_pair.sh: unsetting OMP_WAIT_POLICY=$OMP_WAIT_POLICY: the pair runs with libgomp's default"
    unset OMP_WAIT_POLICY
fi
export RAYON_NUM_THREADS=$threads

out=${out:-$root/runs/mbpo-pair__$(date -u +%Y-%m-%dT%H-%M-%S)}
mkdir -p "$out/logs"
out=$(cd "$out" && pwd)

# tandem's settings: the committed file, with the pair's updates per step (and the smoke sizes).
config=$out/tandem.toml
sed "s/^updates_per_step = .*/updates_per_step = $updates/" "$here/mbpo_tandem.toml" >"$config"
mbrl_args=(--updates "$updates" --threads "$threads")
if [ "$smoke" = 1 ]; then
    # mbrl-lib: 400 random steps, 300 in its loop (3 epochs of 100), refits every 50 of 2
    # epochs; tandem: 449 random steps and 700 in all, the same refits and updates.
    sed -i -e 's/^real_steps = .*/real_steps = 700/' -e 's/^epoch_length = .*/epoch_length = 100/' \
        -e 's/^model_train_freq = .*/model_train_freq = 50/' -e 's/^eval_every = .*/eval_every = 100/' \
        -e 's/^learning_starts = .*/learning_starts = 449/' -e 's/^epochs = .*/epochs = 2/' "$config"
    mbrl_args+=(--model-epochs 2 overrides.num_steps=300 algorithm.initial_exploration_steps=400
        algorithm.dataset_size=700 overrides.epoch_length=100 overrides.freq_train_model=50)
fi
tandem_cmd=("$tandem" reproduce p3-mujoco --env HalfCheetah-v5 --methods mbpo --seeds 1 --jobs 1
    --config "$config" --quiet)

echo "== checking: $("$tandem" --version 2>/dev/null || echo tandem)"
"${tandem_cmd[@]}" --check >"$out/logs/tandem_check.out" 2>&1 || {
    cat "$out/logs/tandem_check.out" >&2
    die "tandem refused the settings (above): is it built with --features mujoco?"
}
grep -v WARNING "$out/logs/tandem_check.out" | sed '/^$/d'
if [ "$tandem_only" = 0 ]; then
    "$python" "$here/mbpo_mbrl.py" --out "$out/mbrl_check" --check "${mbrl_args[@]}" \
        >"$out/logs/mbrl_check.out" 2>&1 || {
        grep -v -i warning "$out/logs/mbrl_check.out" >&2
        die "mbrl-lib's side cannot run from $python (above); docs/performance.md says how to install it"
    }
    grep -v -i warning "$out/logs/mbrl_check.out"
fi
if [ "$check" = 1 ]; then
    echo "== would run $pairs pair(s) into $out:"
    echo "   RAYON_NUM_THREADS=$threads ${tandem_cmd[*]} --out $out/tandem_<i>"
    [ "$tandem_only" = 1 ] || echo "   $python $here/mbpo_mbrl.py --out $out/mbrl_<i> ${mbrl_args[*]}"
    exit 0
fi

quiet_note() {
    local load
    load=$(cut -d' ' -f1 /proc/loadavg)
    echo "   load average before: $load$(awk -v l="$load" 'BEGIN { if (l > 0.5) print "  (not quiet: this pair compares little)" }')"
}

run_tandem() {
    local dir=$out/tandem_$1
    echo "== tandem, pair $1"
    quiet_note
    "${tandem_cmd[@]}" --out "$dir" >"$out/logs/tandem_$1.out" 2>&1 || {
        tail -n 20 "$out/logs/tandem_$1.out" >&2
        die "tandem's run $1 failed (log: $out/logs/tandem_$1.out)"
    }
    "$report_python" "$here/mbpo_pair_report.py" run tandem "$dir"
}

run_mbrl() {
    local dir=$out/mbrl_$1
    echo "== mbrl-lib, pair $1"
    quiet_note
    "$python" "$here/mbpo_mbrl.py" --out "$dir" "${mbrl_args[@]}" >"$out/logs/mbrl_$1.out" 2>&1 || {
        grep -v -i warning "$out/logs/mbrl_$1.out" | tail -n 20 >&2
        die "mbrl-lib's run $1 failed (log: $out/logs/mbrl_$1.out)"
    }
    "$report_python" "$here/mbpo_pair_report.py" run mbrl "$dir"
}

for i in $(seq 1 "$pairs"); do
    run_tandem "$i"
    [ "$tandem_only" = 1 ] || run_mbrl "$i"
done
"$report_python" "$here/mbpo_pair_report.py" pairs "$out"
