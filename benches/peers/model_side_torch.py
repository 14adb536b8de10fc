"""The PyTorch and mbrl-lib side of tandem's benches/model_side.rs (docs/performance.md).

Not part of the build or the tests: run it from a virtual environment of your own, e.g.
    python3 -m venv venv && venv/bin/pip install pip==24.0 && venv/bin/pip install mbrl==0.2.0 torch
    venv/bin/pip install --no-deps hydra-core==1.3.2 omegaconf==2.3.0 antlr4-python3-runtime==4.9.3
(mbrl 0.2.0 pins a hydra that does not import on Python 3.11; the later one works.)

cem_mbrl / cem_ens_mbrl: mbrl-lib's CEM (CEMOptimizer: population 500, horizon 30, 5 iterations,
elite ratio 0.1, smoothing 0.1) planning one action of Pendulum-v1 (3 observations, 1 action in
[-2, 2]) through ModelEnv.evaluate_action_sequences, as its TrajectoryOptimizerAgent does, over a
GaussianMLP of 2x200 (deterministic) or of 5 members of 3x200 (probabilistic, fixed_model
propagation: each row keeps its member), predicting the state change with input normalization.

pets_mbrl: PETS's planning step at mbrl-lib 0.2.0's settings: its TrajectoryOptimizerAgent
(replan every step, warm-started from the last plan) with the same CEM, scoring each sequence by
ModelEnv.evaluate_action_sequences with num_particles=20 (algorithm/pets.yaml) over the same
5 x 3x200 GaussianMLP with its PETS propagation, random_model (dynamics_model/
gaussian_mlp_ensemble.yaml; PETS's TS-1: each step a fresh permutation deals the 10 000 rows to
the members), and the double-precision normalizer pets.yaml asks for; one action per call.

ensemble_fit: 7 members of 4x200 SiLU, 23 inputs -> 18 Gaussian outputs (mean, log-variance with
PETS's learned soft bounds and 0.01 bound penalty), Adam 1e-3, one epoch of 20 minibatches of 256
per member (each member its own bootstrap rows, all members in one batched matmul as mbrl-lib and
MBPO do), then the held-out evaluation (569 rows) and the elite sort.
Both a hand-written batched ensemble (raw PyTorch) and mbrl-lib 0.2.0's GaussianMLP.update.

mbpo_rollouts: 100 000 one-step rollouts: SAC actor 17-256-256-12 (tanh-Gaussian sample), then
5 elites of the ensemble, a random elite per row (mbrl-lib's random_model: a permutation split into
E equal chunks through a batched matmul), a sample of its Gaussian, de-standardized delta and
reward.

Usage: python model_side_torch.py --threads 2 [--only cem_mbrl,cem_ens_mbrl,pets_mbrl,fit_raw,fit_mbrl,rollouts_raw]
"""
import argparse
import json
import os
import statistics
import time

ap = argparse.ArgumentParser()
ap.add_argument("--threads", type=int, default=2)
ap.add_argument("--reps", type=int, default=10)
ap.add_argument("--only", default="")
ap.add_argument("--out", default="")
args = ap.parse_args()
for v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[v] = str(args.threads)

import torch  # noqa: E402
import torch.nn.functional as F  # noqa: E402

torch.set_num_threads(args.threads)
try:
    torch.set_num_interop_threads(1)
except RuntimeError:
    pass

E, ELITES, H, DIN, DOUT, B = 7, 5, 200, 23, 18, 256
S, A = 17, 6


class Ens(torch.nn.Module):
    def __init__(self, e=E, din=DIN, dout=DOUT, hid=H, layers=4):
        super().__init__()
        dims = [din] + [hid] * layers + [2 * dout]
        self.w = torch.nn.ParameterList()
        self.b = torch.nn.ParameterList()
        for i, o in zip(dims[:-1], dims[1:]):
            w = torch.empty(e, i, o)
            for k in range(e):
                torch.nn.init.trunc_normal_(w[k], std=1 / (2 * i ** 0.5))
            self.w.append(torch.nn.Parameter(w))
            self.b.append(torch.nn.Parameter(torch.zeros(e, 1, o)))
        self.max_lv = torch.nn.Parameter(0.5 * torch.ones(1, dout))
        self.min_lv = torch.nn.Parameter(-10 * torch.ones(1, dout))
        self.dout = dout

    def forward(self, x):  # x: [E, B, din]
        n = len(self.w)
        for i in range(n):
            x = torch.baddbmm(self.b[i], x, self.w[i])
            if i < n - 1:
                x = F.silu(x)
        mean, lv = x[..., : self.dout], x[..., self.dout:]
        lv = self.max_lv - F.softplus(self.max_lv - lv)
        lv = self.min_lv + F.softplus(lv - self.min_lv)
        return mean, lv


def nll(mean, lv, y):
    return (((mean - y) ** 2) * torch.exp(-lv) + lv).mean(-1).mean(-1).sum()


def timed(fn, reps):
    fn()
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        ts.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(ts), min(ts), ts


torch.manual_seed(0)
N_TRAIN, N_HOLD, STEPS = 20 * B, 569, 20
x_all = torch.randn(N_TRAIN + N_HOLD, DIN)
y_all = torch.randn(N_TRAIN + N_HOLD, DOUT)
x_tr, y_tr = x_all[:N_TRAIN], y_all[:N_TRAIN]
x_ho, y_ho = x_all[N_TRAIN:], y_all[N_TRAIN:]


def fit_epoch_raw(model, opt):
    idx = torch.randint(N_TRAIN, (E, N_TRAIN))  # bootstrap rows per member
    for s in range(STEPS):
        bi = idx[:, s * B:(s + 1) * B]
        xb, yb = x_tr[bi], y_tr[bi]
        opt.zero_grad(set_to_none=True)
        mean, lv = model(xb)
        loss = nll(mean, lv, yb) + 0.01 * (model.max_lv.sum() - model.min_lv.sum())
        loss.backward()
        opt.step()
    with torch.no_grad():
        mean, _ = model(x_ho.expand(E, -1, -1))
        mse = ((mean - y_ho) ** 2).mean((1, 2))
        return torch.argsort(mse)[:ELITES]


results = {}
only = set(filter(None, args.only.split(",")))

if not only or "fit_raw" in only:
    model = Ens()
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    med, mn, ts = timed(lambda: fit_epoch_raw(model, opt), args.reps)
    results["ensemble_fit_raw_torch"] = dict(ms_median=med, ms_min=mn, ms_all=ts)
    print(f"ensemble fit (raw torch)    t={args.threads} median {med:8.2f} ms  min {mn:8.2f}", flush=True)

if not only or "fit_mbrl" in only:
    import mbrl.models  # noqa: E402

    net = mbrl.models.GaussianMLP(in_size=DIN, out_size=DOUT, device="cpu", num_layers=4,
                                  ensemble_size=E, hid_size=H, deterministic=False,
                                  learn_logvar_bounds=True,
                                  activation_fn_cfg={"_target_": "torch.nn.SiLU"})
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)

    def fit_epoch_mbrl():
        idx = torch.randint(N_TRAIN, (E, N_TRAIN))
        for s in range(STEPS):
            bi = idx[:, s * B:(s + 1) * B]
            net.update(x_tr[bi], opt, target=y_tr[bi])
        with torch.no_grad():
            score, _ = net.eval_score(x_ho, target=y_ho)
            return torch.argsort(score.mean((1, 2)))[:ELITES]

    med, mn, ts = timed(fit_epoch_mbrl, args.reps)
    results["ensemble_fit_mbrl"] = dict(ms_median=med, ms_min=mn, ms_all=ts)
    print(f"ensemble fit (mbrl-lib)     t={args.threads} median {med:8.2f} ms  min {mn:8.2f}", flush=True)

if not only or "rollouts_raw" in only:
    NR = 100_000
    actor = torch.nn.Sequential(torch.nn.Linear(S, 256), torch.nn.ReLU(), torch.nn.Linear(256, 256),
                                torch.nn.ReLU(), torch.nn.Linear(256, 2 * A))
    ens = Ens()
    elites = torch.arange(ELITES)
    mu_in, sd_in = torch.zeros(DIN), torch.ones(DIN)
    mu_out, sd_out = torch.zeros(DOUT), torch.ones(DOUT)
    starts = torch.rand(NR, S) * 2 - 1

    def rollouts():
        with torch.no_grad():
            h = actor(starts)
            mean, log_std = h[:, :A], h[:, A:].clamp(-20, 2)
            act = torch.tanh(mean + log_std.exp() * torch.randn_like(mean))
            x = (torch.cat([starts, act], 1) - mu_in) / sd_in
            perm = torch.randperm(NR)
            xe = x[perm].view(ELITES, NR // ELITES, DIN)
            n = len(ens.w)
            for i in range(n):
                xe = torch.baddbmm(ens.b[i][elites], xe, ens.w[i][elites])
                if i < n - 1:
                    xe = F.silu(xe)
            m, lv = xe[..., :DOUT], xe[..., DOUT:]
            lv = ens.max_lv - F.softplus(ens.max_lv - lv)
            lv = ens.min_lv + F.softplus(lv - ens.min_lv)
            out = m + torch.randn_like(m) * (0.5 * lv).exp()
            out = out.view(NR, DOUT)
            res = torch.empty_like(out)
            res[perm] = out
            res = res * sd_out + mu_out
            nxt = starts + res[:, :S]
            return nxt, res[:, S], act

    med, mn, ts = timed(rollouts, args.reps)
    results["mbpo_rollouts_raw_torch"] = dict(ms_median=med, ms_min=mn, ms_all=ts)
    print(f"100k rollouts (raw torch)   t={args.threads} median {med:8.2f} ms  min {mn:8.2f}", flush=True)

    def policy_only():
        with torch.no_grad():
            h = actor(starts)
            mean, log_std = h[:, :A], h[:, A:].clamp(-20, 2)
            return torch.tanh(mean + log_std.exp() * torch.randn_like(mean))

    med, mn, ts = timed(policy_only, args.reps)
    results["policy_100k_raw_torch"] = dict(ms_median=med, ms_min=mn, ms_all=ts)
    print(f"100k policy only (torch)    t={args.threads} median {med:8.2f} ms  min {mn:8.2f}", flush=True)

def pendulum_model_env(ensemble, propagation="fixed_model", double_normalizer=False):
    """A ModelEnv of Pendulum-v1 over a 2x200 MLP or a 5 x 3x200 ensemble, normalized on 1000
    random transitions, with the cost of tandem's bench as its (negated) reward."""
    import gymnasium as gym
    import mbrl.env.termination_fns as term_fns
    import mbrl.models
    import mbrl.types
    import numpy as np

    def reward(act, next_obs):
        th = torch.atan2(next_obs[:, 1], next_obs[:, 0])
        return -(th ** 2 + 0.1 * next_obs[:, 2] ** 2 + 0.001 * act[:, 0] ** 2).view(-1, 1)

    torch.manual_seed(0)
    if ensemble:
        net = mbrl.models.GaussianMLP(in_size=4, out_size=3, device="cpu", num_layers=3,
                                      ensemble_size=5, hid_size=200, deterministic=False,
                                      propagation_method=propagation)
    else:
        net = mbrl.models.GaussianMLP(in_size=4, out_size=3, device="cpu", num_layers=2,
                                      ensemble_size=1, hid_size=200, deterministic=True)
    model = mbrl.models.OneDTransitionRewardModel(net, target_is_delta=True, normalize=True,
                                                  normalize_double_precision=double_normalizer,
                                                  learned_rewards=False)
    rng = np.random.default_rng(0)
    th = rng.uniform(-np.pi, np.pi, 1000)
    obs = np.stack([np.cos(th), np.sin(th), rng.uniform(-8, 8, 1000)], 1).astype(np.float32)
    act = rng.uniform(-2, 2, (1000, 1)).astype(np.float32)
    model.update_normalizer(mbrl.types.TransitionBatch(
        obs, act, obs, np.zeros(1000, np.float32), np.zeros(1000, bool), np.zeros(1000, bool)))
    gen = torch.Generator()
    gen.manual_seed(0)
    return mbrl.models.ModelEnv(gym.make("Pendulum-v1"), model, term_fns.no_termination,
                                reward_fn=reward, generator=gen)


PENDULUM_X0 = [-1.0, 0.0, 0.0]
HORIZON = 30


def cem_mbrl(ensemble):
    import mbrl.planning
    import numpy as np

    env = pendulum_model_env(ensemble)
    opt = mbrl.planning.CEMOptimizer(num_iterations=5, elite_ratio=0.1, population_size=500,
                                     lower_bound=[[-2.0]] * HORIZON,
                                     upper_bound=[[2.0]] * HORIZON, alpha=0.1, device="cpu",
                                     return_mean_elites=True)
    x0 = np.array(PENDULUM_X0, np.float32)

    def plan():
        with torch.no_grad():
            def objective(seqs):
                return env.evaluate_action_sequences(seqs, initial_state=x0, num_particles=1)
            return opt.optimize(objective, torch.zeros(HORIZON, 1))

    return timed(plan, 20)


def pets_mbrl(particles=20):
    import mbrl.planning
    import numpy as np
    import omegaconf

    env = pendulum_model_env(True, propagation="random_model", double_normalizer=True)
    cem = omegaconf.OmegaConf.create({
        "_target_": "mbrl.planning.CEMOptimizer", "num_iterations": 5, "elite_ratio": 0.1,
        "population_size": 500, "alpha": 0.1, "lower_bound": "???", "upper_bound": "???",
        "return_mean_elites": True, "device": "cpu"})
    # What create_trajectory_optim_agent_for_model builds, without hydra instantiating the
    # agent (hydra 1.3 would also instantiate its nested optimizer config).
    agent = mbrl.planning.TrajectoryOptimizerAgent(cem, action_lb=[-2.0], action_ub=[2.0],
                                                   planning_horizon=HORIZON, replan_freq=1)
    agent.set_trajectory_eval_fn(lambda x, seqs: env.evaluate_action_sequences(
        seqs, initial_state=x, num_particles=particles))
    x0 = np.array(PENDULUM_X0, np.float32)

    def act():
        with torch.no_grad():
            return agent.act(x0)

    return timed(act, 10)


for name, run in [("cem_mbrl", lambda: cem_mbrl(False)), ("cem_ens_mbrl", lambda: cem_mbrl(True)),
                  ("pets_mbrl", pets_mbrl)]:
    if not only or name in only:
        med, mn, ts = run()
        results[name] = dict(ms_median=med, ms_min=mn, ms_all=ts)
        print(f"{name:27s} t={args.threads} median {med:8.2f} ms  min {mn:8.2f}", flush=True)

results["meta"] = dict(torch=torch.__version__, threads=args.threads)
if args.out:
    with open(args.out, "w") as f:
        json.dump(results, f, indent=1)
