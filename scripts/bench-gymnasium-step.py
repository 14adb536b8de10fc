"""gymnasium's own HalfCheetah-v5 `env.step`, timed the way criterion reports it: the median of
samples, each the mean over a batch of steps (random actions, reset every 1000 steps as the time
limit does). Run with the venv of scripts/setup-mujoco.sh:

    .mujoco/venv/bin/python scripts/bench-gymnasium-step.py
"""
import statistics
import time

import gymnasium as gym
import numpy as np

env = gym.make("HalfCheetah-v5")
env.reset(seed=0)
rng = np.random.default_rng(0)
actions = rng.uniform(-1, 1, size=(1000, 6)).astype(np.float32)
t = 0


def run(n):
    global t
    for _ in range(n):
        if t == len(actions):
            env.reset()
            t = 0
        env.step(actions[t])
        t += 1


run(2000)  # warm up
samples = []
for _ in range(100):
    start = time.perf_counter()
    run(500)
    samples.append((time.perf_counter() - start) / 500 * 1e6)
unwrapped = env.unwrapped
samples_raw = []
for _ in range(100):
    start = time.perf_counter()
    for i in range(500):
        unwrapped.step(actions[i])
    samples_raw.append((time.perf_counter() - start) / 500 * 1e6)
print(f"gym.make('HalfCheetah-v5').step: median {statistics.median(samples):.2f} us "
      f"(min {min(samples):.2f}, 100 samples of 500 steps)")
print(f"unwrapped HalfCheetahEnv.step:    median {statistics.median(samples_raw):.2f} us "
      f"(min {min(samples_raw):.2f})")
