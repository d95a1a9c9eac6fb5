"""Accuracy cost and speed-up of ``envs.FAST_SOLVER`` on the MuJoCo tasks.

For each task two solver settings run the same experiment: N parallel environments (vmap)
reset with the same keys and driven by the same uniform random actions for T steps. The
reference is the task's default setting and the candidate ``FAST_SOLVER`` (1 Newton iteration,
4 line-search iterations). Brax's Ant already uses ``FAST_SOLVER`` by default, so for Ant the
reference is an accurate ``solver_iterations=4, ls_iterations=50`` and the candidate is the
default.

Accuracy (candidate minus reference): max and mean absolute observation difference after 1, 10
and T steps; per-step reward mean absolute difference; the difference in mean undiscounted
return, with its standard error paired over envs. A third run of the reference with actions
perturbed by 1e-6 gives the chaos floor: how far trajectories drift from tiny differences
alone, stored as the reference row's accuracy metrics. Plain env, no auto-reset: a step counts
only up to and including the first ``done`` (for the reward difference, the first ``done`` of
either run), and the number of terminated episodes is reported per setting.

Speed: each setting has one compiled function, a ``lax.scan`` over ``jax.vmap(env.step)`` that
returns the whole trace; it gives the accuracy trace and is then timed warm (median of 3). The
timed call includes the batched reset, about 1/T of the work. Compile seconds are lower plus
compile.

    python benchmarks/solver_accuracy.py                         # all five tasks, 16 x 200
    python benchmarks/solver_accuracy.py --quick                 # HalfCheetah, Hopper, 8 x 100
    python benchmarks/solver_accuracy.py --envs Hopper --steps 500 --json out.json
"""

from __future__ import annotations

import argparse
import statistics
import time

import common
import jax
import numpy as np

from pngail_jax import envs

TASKS = ("Ant", "HalfCheetah", "Hopper", "Walker2d", "Swimmer")
ACCURATE_SOLVER = {"solver_iterations": 4, "ls_iterations": 50}
NUM_TIMINGS = 3
ACTION_NOISE = 1e-6  # perturbation of the reference's actions that sets the chaos floor


def settings_for(name: str) -> tuple[tuple[str, dict], tuple[str, dict]]:
    """``(reference, candidate)``, each as ``(setting name, envs.make options)``."""
    if name == "Ant":
        return ("accurate", ACCURATE_SOLVER), ("default", {})
    return ("default", {}), ("fast", envs.FAST_SOLVER)


def make_rollout(env: envs.Env):
    """``rollout(reset_keys key[N], actions float[T, N, A]) -> (obs, reward, done)``.

    Returns float[T, N, O] observations, float[T, N] rewards and bool[T, N] done flags.
    """

    def rollout(reset_keys, actions):
        def step(state, action):
            state = jax.vmap(env.step)(state, action)
            return state, (state.obs, state.reward, state.done)

        _, trace = jax.lax.scan(step, jax.vmap(env.reset)(reset_keys), actions)
        return trace

    return rollout


def run_setting(env: envs.Env, reset_keys, actions):
    """Compiles, runs and times one setting: ``(compiled rollout, NumPy trace, speed dict)``."""
    start = time.perf_counter()
    compiled = jax.jit(make_rollout(env)).lower(reset_keys, actions).compile()
    compile_s = time.perf_counter() - start
    trace = jax.block_until_ready(compiled(reset_keys, actions))  # also the warm-up call
    timings = []
    for _ in range(NUM_TIMINGS):
        start = time.perf_counter()
        jax.block_until_ready(compiled(reset_keys, actions))
        timings.append(time.perf_counter() - start)
    steps_per_s = actions.shape[0] * actions.shape[1] / statistics.median(timings)
    speed = {"compile_s": compile_s, "steps_per_s": steps_per_s}
    return compiled, tuple(np.asarray(x) for x in trace), speed


def first_episode_mask(done: np.ndarray) -> np.ndarray:
    """bool[T, N]: the step is in the first episode (up to and including its first done)."""
    done = done.astype(np.int64)
    return np.cumsum(done, axis=0) - done == 0


def first_episode_return(reward: np.ndarray, done: np.ndarray) -> np.ndarray:
    """float[N]: undiscounted return of each env's first episode within the trace."""
    return np.sum(reward * first_episode_mask(done), axis=0)


def episode_metrics(reward: np.ndarray, done: np.ndarray) -> dict:
    mask = first_episode_mask(done)
    return {
        "mean_return": float(first_episode_return(reward, done).mean()),
        "num_terminated": int(done.any(axis=0).sum()),
        "mean_episode_length": float(mask.sum(axis=0).mean()),
    }


def accuracy_metrics(reference: tuple, candidate: tuple) -> dict:
    """Candidate-minus-reference differences of two ``(obs, reward, done)`` traces."""
    (obs_ref, reward_ref, done_ref), (obs_cand, reward_cand, done_cand) = reference, candidate
    obs_diff = np.abs(obs_cand - obs_ref)
    metrics = {}
    for label, step in (("1", 1), ("10", 10), ("last", len(obs_diff))):
        metrics[f"obs_max_diff_{label}"] = float(obs_diff[step - 1].max())
        metrics[f"obs_mean_diff_{label}"] = float(obs_diff[step - 1].mean())
    both_alive = first_episode_mask(done_ref) & first_episode_mask(done_cand)
    metrics["reward_mean_abs_diff"] = float(np.abs(reward_cand - reward_ref)[both_alive].mean())
    return_ref = first_episode_return(reward_ref, done_ref)
    return_diff = first_episode_return(reward_cand, done_cand) - return_ref
    metrics["return_diff"] = float(return_diff.mean())
    # Paired over envs (same start, same actions): is the mean difference more than noise?
    metrics["return_diff_stderr"] = float(return_diff.std(ddof=1) / np.sqrt(len(return_diff)))
    return metrics


def compare_task(name: str, num_envs: int, num_steps: int, key, context: dict) -> list[dict]:
    """Both settings of one task: one JSON row each.

    The candidate's accuracy metrics compare it with the reference; the reference's compare it
    with itself under actions perturbed by ``ACTION_NOISE``, the floor that chaos alone sets.
    """
    (ref_name, ref_options), (cand_name, cand_options) = settings_for(name)
    reference_env, candidate_env = envs.make(name, **ref_options), envs.make(name, **cand_options)
    reset_key, action_key, noise_key = jax.random.split(key, 3)
    reset_keys = jax.random.split(reset_key, num_envs)
    shape = (num_steps, num_envs, reference_env.action_size)
    low, high = reference_env.action_low, reference_env.action_high
    actions = jax.random.uniform(action_key, shape, minval=low, maxval=high)
    noise = jax.random.uniform(noise_key, shape, minval=-ACTION_NOISE, maxval=ACTION_NOISE)
    rows, traces, rollouts = [], [], []
    for setting, env in ((ref_name, reference_env), (cand_name, candidate_env)):
        options = env.model_options
        print(
            f"[{name}] {setting} (iterations={options['iterations']}, "
            f"ls_iterations={options['ls_iterations']}): compiling...",
            flush=True,
        )
        rollout, trace, speed = run_setting(env, reset_keys, actions)
        print(
            f"[{name}] {setting}: compiled in {speed['compile_s']:.1f} s, "
            f"{speed['steps_per_s']:,.0f} steps/s",
            flush=True,
        )
        traces.append(trace)
        rollouts.append(rollout)
        row = {"env": name, "setting": setting, "solver_options": options, **context}
        row.update(num_envs=num_envs, num_steps=num_steps, **speed, **episode_metrics(*trace[1:]))
        rows.append(row)
    reference, candidate = rows
    floor_trace = tuple(np.asarray(x) for x in rollouts[0](reset_keys, actions + noise))
    reference.update(role="reference", compared_to=f"{ref_name}+noise", action_noise=ACTION_NOISE)
    reference.update(speedup=1.0, **accuracy_metrics(traces[0], floor_trace))
    candidate.update(role="candidate", compared_to=ref_name, **accuracy_metrics(*traces))
    candidate["speedup"] = candidate["steps_per_s"] / reference["steps_per_s"]
    if name == "Ant":
        note = "Brax's default Ant already uses FAST_SOLVER; compared against accurate 4/50"
        for row in rows:
            row["note"] = note
    return rows


def print_tables(rows: list[dict]) -> None:
    print("\nThroughput (env steps/s, warm, median of 3) and first-episode returns")
    header = "env          setting   iters/ls  compile_s     steps/s  speedup  mean_return  term"
    print(header + "\n" + "-" * len(header))
    for row in rows:
        solver = row["solver_options"]
        iterations = f"{solver['iterations']:>3}/{solver['ls_iterations']:<4}"
        print(
            f"{row['env']:<12} {row['setting']:<9} {iterations}"
            f" {row['compile_s']:>9.1f} {row['steps_per_s']:>11,.0f} {row['speedup']:>7.2f}x"
            f" {row['mean_return']:>12.2f} {row['num_terminated']:>3}/{row['num_envs']}"
        )
    print(
        "\nAccuracy: |obs diff| max/mean after step 1, 10, T; mean |reward diff| per step; mean"
        " return diff ± paired s.e.\nReference rows are the chaos floor: the reference vs itself"
        f" with actions perturbed by +-{ACTION_NOISE:g}"
    )
    header = (
        f"{'env':<12} {'comparison':<26} {'obs @1':>17} {'obs @10':>17} {'obs @T':>17}"
        f" {'|r diff|':>9} {'return diff':>14}"
    )
    print(header + "\n" + "-" * len(header))
    for row in rows:
        obs = [
            f"{row[f'obs_max_diff_{label}']:.1e}/{row[f'obs_mean_diff_{label}']:.1e}"
            for label in ("1", "10", "last")
        ]
        return_diff = f"{row['return_diff']:+.2f}±{row['return_diff_stderr']:.2f}"
        compared = f"{row['setting']} vs {row['compared_to']}"
        print(
            f"{row['env']:<12} {compared:<26} {obs[0]:>17} {obs[1]:>17} {obs[2]:>17}"
            f" {row['reward_mean_abs_diff']:>9.1e} {return_diff:>14}"
        )
    for note in sorted({row["note"] for row in rows if "note" in row}):
        print(f"Note: {note}.")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", help=f"comma-separated, default {','.join(TASKS)}")
    parser.add_argument("--num-envs", type=int, help="parallel envs (default 16)")
    parser.add_argument("--steps", type=int, help="steps per rollout, at least 10 (default 200)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", metavar="PATH", help="write the rows as a JSON list")
    parser.add_argument("--quick", action="store_true", help="HalfCheetah, Hopper, 8 x 100")
    args = parser.parse_args(argv)
    defaults = ("HalfCheetah,Hopper", 8, 100) if args.quick else (",".join(TASKS), 16, 200)
    names = (args.envs or defaults[0]).split(",")
    num_envs = args.num_envs or defaults[1]
    num_steps = args.steps or defaults[2]
    if unknown := sorted(set(names) - set(TASKS)):
        parser.error(f"unknown env(s) {unknown}; choose from {', '.join(TASKS)}")
    if num_steps < 10 or num_envs < 2:
        parser.error("need --steps >= 10 and --num-envs >= 2")

    context = common.context()
    print(f"{num_envs} envs x {num_steps} steps on {context['device']}, jax {jax.__version__}")
    key = jax.random.key(args.seed)
    rows = []
    for name in names:
        task_key = jax.random.fold_in(key, TASKS.index(name))  # independent of --envs order
        rows += compare_task(name, num_envs, num_steps, task_key, context)
    print_tables(rows)
    common.write_rows(args.json, rows)


if __name__ == "__main__":
    main()
