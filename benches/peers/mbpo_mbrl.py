"""The mbrl-lib half of benches/peers/mbpo_pair.sh (docs/performance.md): mbrl-lib 0.2.0's own
MBPO, `mbrl.algorithms.mbpo.train`, on HalfCheetah-v4, with the time of its parts recorded.

Not part of the build or the tests. Run it from a virtual environment of your own (the install is
in docs/performance.md); the project never installs it.

The work is the one of benches/peers/mbpo_tandem.toml: mbrl-lib's `algorithm=mbpo` with its
`overrides=mbpo_halfcheetah` and its default `dynamics_model=gaussian_mlp_ensemble`, changed to
  - 2000 random steps (`algorithm.initial_exploration_steps`, `random_initial_explore`), then
    3 epochs of 1000 steps (`overrides.num_steps=3000`), the replay buffer holding all 5000;
  - SAC of 256 x 256 (`overrides.sac_hidden_size`; the config says 512), batch 256, `--updates`
    updates per real step (the config says 10; 4 by default here);
  - a refit every 250 steps of `--model-epochs` epochs (20) with early stopping off
    (`overrides.patience=0`), 7 members / 5 elites of 4 x 200, 400 one-step rollouts per real step
    (as the config).
Extra `key=value` arguments are set on the composed configuration last (OmegaConf dot-list).

The configuration is composed from the installed package's own `mbrl/examples/conf` with OmegaConf
rather than hydra's compose: the wheel lacks the `action_optimizer` group that `main.yaml`'s
defaults name (MBPO does not use it), and hydra 1.3 refuses a defaults list with a missing entry.
The agent's and the model's configurations get `_recursive_: false`, as hydra 1.0 (mbrl-lib's pin)
instantiated them.

Timing wraps, without changing what they do, the functions `mbpo.train` calls:
  - SAC updates:     `SAC.update_parameters` (mbrl's pytorch_sac_pranz24);
  - model training:  `mbrl.util.common.train_model_and_save_model_and_data`, less the saving of the
                     model and the replay buffer it does after each fit (timed apart as `save`);
  - model rollouts:  `mbrl.algorithms.mbpo.rollout_model_and_populate_sac_buffer`;
  - evaluation:      `mbrl.algorithms.mbpo.evaluate` (its returns are the run's sanity check).
Everything else in `mbpo.train` (real steps, the agent acting, the saves, logging) is "rest".

Usage: python mbpo_mbrl.py --out DIR [--updates 4] [--model-epochs 20] [--threads 2] [--seed 0]
                           [--check] [key=value ...]
Writes DIR/timing.json and prints it. `--check` imports everything, composes the configuration,
makes the environment, and exits without training.
"""
import argparse
import json
import os
import sys
import time

T_START = time.perf_counter()

ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
ap.add_argument("--out", required=True, help="directory for timing.json and mbrl-lib's files")
ap.add_argument("--updates", type=int, default=4, help="SAC updates per real step")
ap.add_argument("--model-epochs", type=int, default=20, help="epochs per model refit")
ap.add_argument("--threads", type=int, default=2, help="torch's threads")
ap.add_argument("--seed", type=int, default=0)
ap.add_argument("--check", action="store_true", help="compose and make the env, then exit")
ap.add_argument("dotlist", nargs="*", help="more key=value settings")
args = ap.parse_args()

try:
    import numpy as np
    import omegaconf
    import torch

    import mbrl
    import mbrl.algorithms.mbpo as mbpo
    import mbrl.models
    import mbrl.util
    import mbrl.util.common
    import mbrl.util.mujoco
    from mbrl.third_party.pytorch_sac_pranz24.sac import SAC
except ImportError as e:
    sys.exit(f"mbpo_mbrl.py: cannot import {e.name!r}: run it from a venv with mbrl==0.2.0, torch, "
             "hydra-core 1.3, numpy<2 and mujoco 2.3.7 (docs/performance.md says how)")
if mbrl.__version__ != "0.2.0":
    sys.exit(f"mbpo_mbrl.py: this pairs with mbrl-lib 0.2.0, found {mbrl.__version__}")

torch.set_num_threads(args.threads)


def compose():
    """main.yaml's top-level keys and the three groups MBPO reads, then the pair's settings."""
    conf = os.path.join(os.path.dirname(mbrl.__file__), "examples", "conf")
    main = omegaconf.OmegaConf.load(os.path.join(conf, "main.yaml"))
    cfg = omegaconf.OmegaConf.create(
        {k: v for k, v in omegaconf.OmegaConf.to_container(main).items()
         if k not in ("defaults", "hydra")})
    for group, name in [("algorithm", "mbpo"), ("dynamics_model", "gaussian_mlp_ensemble"),
                        ("overrides", "mbpo_halfcheetah")]:
        cfg[group] = omegaconf.OmegaConf.load(os.path.join(conf, group, f"{name}.yaml"))
    settings = [
        "device=cpu",
        f"seed={args.seed}",
        # gymnasium 0.26's HalfCheetah on the mujoco bindings (v2 needs mujoco-py)
        "overrides.env=gym___HalfCheetah-v4",
        "overrides.num_steps=3000",
        "algorithm.initial_exploration_steps=2000",
        "algorithm.random_initial_explore=true",
        # mbrl-lib sizes the real buffer by num_steps unless told: it holds the random steps too
        "algorithm.dataset_size=5000",
        "overrides.sac_hidden_size=256",
        f"overrides.num_sac_updates_per_step={args.updates}",
        f"overrides.num_epochs_train_model={args.model_epochs}",
        "overrides.patience=0",
        "algorithm.agent._recursive_=false",
        "dynamics_model._recursive_=false",
    ]
    return omegaconf.OmegaConf.merge(cfg, omegaconf.OmegaConf.from_dotlist(settings + args.dotlist))


cfg = compose()
out = os.path.abspath(args.out)
os.makedirs(out, exist_ok=True)
with open(os.path.join(out, "config.yaml"), "w") as f:
    f.write(omegaconf.OmegaConf.to_yaml(cfg, resolve=True))
env, term_fn, _ = mbrl.util.mujoco.MujocoEnvHandler.make_env(cfg)
test_env, *_ = mbrl.util.mujoco.MujocoEnvHandler.make_env(cfg)
if args.check:
    print(f"mbpo_mbrl.py: ready (mbrl {mbrl.__version__}, torch {torch.__version__}, "
          f"{args.threads} threads, {cfg.overrides.env}); config in {out}/config.yaml")
    sys.exit(0)

seconds = {"sac_updates": 0.0, "model_training": 0.0, "save": 0.0, "model_rollouts": 0.0,
           "evaluation": 0.0}
counts = {"sac_updates": 0, "model_fits": 0, "model_minibatches": 0, "rollout_calls": 0}
model_epochs = []
eval_returns = []


def timed(key, fn):
    """`fn`, adding its time to `seconds[key]`."""
    def wrapper(*a, **k):
        t = time.perf_counter()
        try:
            return fn(*a, **k)
        finally:
            seconds[key] += time.perf_counter() - t
    return wrapper


def counted(fn, key):
    def wrapper(*a, **k):
        counts[key] += 1
        return fn(*a, **k)
    return wrapper


SAC.update_parameters = counted(timed("sac_updates", SAC.update_parameters), "sac_updates")
mbrl.models.OneDTransitionRewardModel.update = counted(
    mbrl.models.OneDTransitionRewardModel.update, "model_minibatches")
mbrl.models.OneDTransitionRewardModel.save = timed("save", mbrl.models.OneDTransitionRewardModel.save)
mbrl.util.ReplayBuffer.save = timed("save", mbrl.util.ReplayBuffer.save)

_trainer_train = mbrl.models.ModelTrainer.train


def trainer_train(self, *a, **k):
    losses, val_scores = _trainer_train(self, *a, **k)
    model_epochs.append(len(losses))
    return losses, val_scores


mbrl.models.ModelTrainer.train = trainer_train
mbrl.util.common.train_model_and_save_model_and_data = counted(
    timed("model_training", mbrl.util.common.train_model_and_save_model_and_data), "model_fits")
mbpo.rollout_model_and_populate_sac_buffer = counted(
    timed("model_rollouts", mbpo.rollout_model_and_populate_sac_buffer), "rollout_calls")
_evaluate = timed("evaluation", mbpo.evaluate)


def evaluate(*a, **k):
    r = _evaluate(*a, **k)
    eval_returns.append(float(r))
    return r


mbpo.evaluate = evaluate

# As mbrl-lib's examples/main.py does before mbpo.train.
np.random.seed(cfg.seed)
torch.manual_seed(cfg.seed)
t0 = time.perf_counter()
best = mbpo.train(env, test_env, term_fn, cfg, silent=False, work_dir=out)
wall = time.perf_counter() - t0

# The saves run inside model training: count them once, in the rest.
seconds["model_training"] -= seconds["save"]
parts = seconds["sac_updates"] + seconds["model_training"] + seconds["model_rollouts"]
record = {
    "side": "mbrl-lib",
    "mbrl": mbrl.__version__,
    "torch": torch.__version__,
    "threads": torch.get_num_threads(),
    "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY", "default"),
    "updates_per_step": args.updates,
    "model_epochs_per_fit": args.model_epochs,
    "wall_seconds": wall,
    "process_seconds": time.perf_counter() - T_START,
    "sac_update_seconds": seconds["sac_updates"],
    "fit_seconds": seconds["model_training"],
    "rollout_seconds": seconds["model_rollouts"],
    "rest_seconds": wall - parts,
    "of_which_eval_seconds": seconds["evaluation"],
    "of_which_save_seconds": seconds["save"],
    "sac_updates": counts["sac_updates"],
    "model_fits": counts["model_fits"],
    "model_epochs": model_epochs,
    "model_minibatches": counts["model_minibatches"],
    "rollout_calls": counts["rollout_calls"],
    "eval_returns": eval_returns,
    # evaluate() runs after each epoch of the loop, which follows the random steps
    "eval_steps": [cfg.algorithm.initial_exploration_steps + (k + 1) * cfg.overrides.epoch_length
                   for k in range(len(eval_returns))],
    "best_return": float(best),
}
with open(os.path.join(out, "timing.json"), "w") as f:
    json.dump(record, f, indent=1)
print(json.dumps(record, indent=1))
