"""How far each engine of gymnasium's MuJoCo tasks drifts from gymnasium along one trajectory.

For each task: gymnasium's environment from ``reset(seed)``, stepped with uniform random
actions inside the bounds for ``--steps`` steps (past any termination: the physics goes on);
our task from the same initial positions and velocities with the same actions, on MuJoCo's C
engine and on MJX. Prints the largest |observation difference| up to steps 1, 10, 50, 200 and
the end, and the difference of the summed reward; writes the rows as JSON with ``--json``.

JAX's float width is the process's: run once as is (float32) and once with
``JAX_ENABLE_X64=1`` to separate MJX's float32 rounding from its different solver and
collision code. MJX compiles each task for 20-40 s on a CPU.

    python benchmarks/physics_agreement.py --json agreement32.json
    JAX_ENABLE_X64=1 python benchmarks/physics_agreement.py --json agreement64.json
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import jax
import numpy as np
from common import context, write_rows

from pngail_jax import envs

CHECKPOINTS = (1, 10, 50, 200)


def gymnasium_trajectory(name: str, seed: int, num_steps: int):
    reference = gym.make(name).unwrapped
    reference.reset(seed=seed)
    # Our tasks start from the state in JAX's float width: so does gymnasium here (a no-op
    # under x64), or a 1e-8 rounding of the start would grow chaotically and hide the engines.
    width = np.float64 if jax.config.jax_enable_x64 else np.float32
    qpos = reference.data.qpos.astype(width).astype(np.float64)
    qvel = reference.data.qvel.astype(width).astype(np.float64)
    reference.set_state(qpos, qvel)
    rng = np.random.default_rng(seed)
    low, high = reference.action_space.low, reference.action_space.high
    actions = rng.uniform(low, high, (num_steps, len(low))).astype(np.float32)
    observations, rewards = [], []
    for action in actions:
        obs, reward, *_ = reference.step(action)
        observations.append(obs)
        rewards.append(reward)
    return qpos, qvel, actions, np.array(observations), np.array(rewards)


def our_trajectory(env, qpos, qvel, actions):
    step = jax.jit(env.step)
    obs, internal = jax.jit(env.state_at)(qpos, qvel)
    state = jax.jit(env.reset)(jax.random.key(0)).replace(obs=obs, internal=internal)
    observations, rewards = [], []
    for action in actions:
        state = step(state, action)
        observations.append(np.asarray(state.obs, np.float64))
        rewards.append(float(state.reward))
    return np.array(observations), np.array(rewards)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", default=",".join(envs.GYM_TASKS), help="comma-separated")
    parser.add_argument("--physics", default="c,mjx", help="engines to compare (default c,mjx)")
    parser.add_argument("--steps", type=int, default=1000, help="trajectory length (1000)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    width = "float64" if jax.config.jax_enable_x64 else "float32"
    checkpoints = [c for c in CHECKPOINTS if c < args.steps] + [args.steps]
    rows = []
    print(f"JAX {jax.__version__}, {width}; {args.steps} steps of uniform random actions")
    header = " | ".join(f"obs, step {c}" for c in checkpoints)
    print(f"| task | physics | {header} | return difference |")
    print("|---|---|" + "---:|" * (len(checkpoints) + 1))
    for name in args.tasks.split(","):
        qpos, qvel, actions, expected_obs, expected_rewards = gymnasium_trajectory(
            name, args.seed, args.steps
        )
        for physics in args.physics.split(","):
            env = envs.make(name, physics=physics)
            obs, rewards = our_trajectory(env, qpos, qvel, actions)
            error = np.abs(obs - expected_obs).max(axis=1)
            worst = {c: float(error[:c].max()) for c in checkpoints}
            row = {
                "task": name,
                "physics": physics,
                "float": width,
                "steps": args.steps,
                "max_obs_error_up_to_step": worst,
                "return_difference": float(rewards.sum() - expected_rewards.sum()),
                "gymnasium_return": float(expected_rewards.sum()),
                **context(),
            }
            rows.append(row)
            cells = " | ".join(f"{worst[c]:.1e}" for c in checkpoints)
            print(f"| {name} | {physics} | {cells} | {row['return_difference']:+.3g} |", flush=True)
    write_rows(args.json, rows)


if __name__ == "__main__":
    main()
