"""Against imitation's GAIL: pngail-jax's GAIL and the ``imitation`` library's (1.0.1, on
stable-baselines3 and sb3-contrib's TRPO) on the authors' Pendulum file, side by side.

Each run is a fresh process pinned to one CPU (``taskset -c``, with ``OMP_NUM_THREADS``,
``MKL_NUM_THREADS``, ``OPENBLAS_NUM_THREADS`` at 1, ``XLA_FLAGS`` without XLA's multi-threaded
Eigen and ``torch.set_num_threads(1)``), so its interpreter's start, its imports and (ours)
its compiles count in its time:

- pngail-jax: the sweep program as a user runs it, ``python -m experiments.sweep --demos FILE
  --methods gail --seeds 1 --seed S --iterations N`` with an empty compilation cache of its
  own (its periodic evaluations, checkpoints and plots included);
- imitation: ``GAIL`` with ``sb3_contrib.TRPO`` in the interpreter ``--peer-python`` (a
  virtual environment of its own: imitation 1.0.1 needs gymnasium 0.29, which pngail-jax's
  gymnasium >= 1.1 excludes; ``benchmarks/peer-requirements.txt``), on gymnasium's
  Pendulum-v1, fed the rows pngail-jax's loader reads from the same file (actions at their
  known scale, clipped to the torque bound as our discriminator sees them).

Both at the settings they share (``PEER_SETTINGS`` and docs/performance.md, "Against
imitation's GAIL", list the ones that still differ). Per run it records the whole process's
seconds (launch to exit), the training loop's env steps per second (ours: the sweep's chunks,
evaluations included; the peer's: ``GAIL.train``) and the final evaluation's return (32
deterministic episodes), normalised by the file's random and optimal returns (the paper's
Table 3, as the sweep normalises). Over seeds: mean ± s.e. and the IQM with a 95% bootstrap
interval (``pngail_jax.analysis.stats.seed_summary``); per budget the peer's time over ours.

    python benchmarks/vs_imitation.py --json vs_imitation.json       # 500 k and 2.5 M, 3 seeds
    python benchmarks/vs_imitation.py --cpus 0,1                     # two runs at a time
    python benchmarks/vs_imitation.py --quick                        # a smoke test: 2 iterations

Row schema: ``{name, library, budget, seed, cpu, total_seconds, total_cpu_seconds,
train_seconds, train_env_steps_per_second, final_return, final_normalized_return,
load_before, load_after, versions, command, device, jax_version}`` (imitation's rows add
``train_cpu_seconds``).
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parents[1]
DEMOS = "data/released/Pendulum-v1_mixture.npy"
LIBRARIES = ("pngail-jax", "imitation")
# The goal: the peer's whole process over ours, at least this much, per budget.
GOALS = {500_000: 3.0, 2_500_000: 6.0}
THREAD_VARIABLES = {
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1",
}
# sb3-contrib's TRPO at our sweep's settings (pngail_jax.config.learner, rl.trpo): its value
# fit is one pass (n_critic_updates) in minibatches of 167 rows, 30 of a 5,000-row batch; its
# Adam at our 3e-4 and eps 1e-8 (sb3's own default eps is 1e-5); its line search halves the
# step, 10 times at most, as ours.
PEER_SETTINGS = {
    "gamma": 0.995,
    "gae_lambda": 0.97,
    "target_kl": 0.01,
    "cg_damping": 0.1,
    "cg_max_steps": 10,
    "n_critic_updates": 1,
    "learning_rate": 3e-4,
    "line_search_shrinking_factor": 0.5,
    "line_search_max_iter": 10,
    "normalize_advantage": True,
    "sub_sampling_factor": 1,
}
NUM_VALUE_MINIBATCHES = 30
HIDDEN_SIZES = (100, 100)
DISCRIMINATOR_LEARNING_RATE = 1e-3  # ours (AdversarialHyperparams) and torch's Adam default


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--budgets", default="500000,2500000", help="env steps per run")
    parser.add_argument("--seeds", type=int, default=3, help="runs per library and budget")
    parser.add_argument("--libraries", default=",".join(LIBRARIES), help="of the two")
    parser.add_argument("--cpus", default="0", help="CPU ids, one run on each at a time")
    parser.add_argument("--demos", default=DEMOS, help="the authors' Pendulum file")
    parser.add_argument("--num-envs", type=int, default=25, help="parallel envs (both)")
    parser.add_argument("--unroll-length", type=int, default=200, help="steps per env (both)")
    parser.add_argument("--num-eval-episodes", type=int, default=32, help="final evaluation")
    parser.add_argument(
        "--peer-python",
        default=str(ROOT / ".venv-peer" / "bin" / "python"),
        help="an interpreter with imitation and sb3-contrib (benchmarks/peer-requirements.txt)",
    )
    parser.add_argument(
        "--quick", action="store_true", help="a smoke test: 2 iterations, 1 seed, 2 episodes"
    )
    parser.add_argument("--json", help="write the rows here")
    parser.add_argument("--peer-child", help=argparse.SUPPRESS)  # JSON: the peer's run
    args = parser.parse_args(argv)
    if args.quick:
        args.seeds, args.num_eval_episodes = 1, 2
        args.budgets = str(2 * args.num_envs * args.unroll_length)
    return args


# -- the peer's child: imitation's GAIL in the peer's interpreter (no pngail_jax there) -------


class DrawnRows:
    """The demonstrations as imitation takes an iterable of batches: endless batches of
    ``size`` rows drawn with replacement, as our trainer draws its discriminator's
    demonstration rows (imitation's own loader shuffles and needs ``size`` rows or more: the
    Pendulum file has 1,000)."""

    def __init__(self, rows: dict, size: int, seed: int):
        import numpy as np

        self.rows, self.size = rows, size
        self.generator = np.random.default_rng(seed)

    def __iter__(self):
        num_rows = len(self.rows["obs"])
        while True:
            drawn = self.generator.integers(0, num_rows, self.size)
            yield {key: values[drawn] for key, values in self.rows.items()}


def peer_trainer(instructions: dict, rows: dict):
    """``(GAIL trainer, TRPO learner)`` of imitation at the shared settings."""
    import numpy as np
    import torch
    from imitation.algorithms.adversarial.gail import GAIL
    from imitation.rewards.reward_nets import BasicRewardNet
    from imitation.util import logger
    from imitation.util.util import make_vec_env
    from sb3_contrib import TRPO

    seed, num_envs = instructions["seed"], instructions["num_envs"]
    batch_size = num_envs * instructions["unroll_length"]
    venv = make_vec_env("Pendulum-v1", rng=np.random.default_rng(seed), n_envs=num_envs)
    network = {"net_arch": {"pi": list(HIDDEN_SIZES), "vf": list(HIDDEN_SIZES)},
               "activation_fn": torch.nn.Tanh, "optimizer_kwargs": {"eps": 1e-8}}  # fmt: skip
    learner = TRPO(
        "MlpPolicy",
        venv,
        n_steps=instructions["unroll_length"],
        batch_size=-(-batch_size // NUM_VALUE_MINIBATCHES),
        policy_kwargs=network,
        seed=seed,
        device="cpu",
        **PEER_SETTINGS,
    )
    discriminator = BasicRewardNet(
        venv.observation_space, venv.action_space, hid_sizes=HIDDEN_SIZES,
        activation=torch.nn.Tanh,
    )  # fmt: skip
    trainer = GAIL(
        demonstrations=DrawnRows(rows, batch_size, seed),
        demo_batch_size=batch_size,
        gen_replay_buffer_capacity=batch_size,
        n_disc_updates_per_round=1,
        disc_opt_kwargs={"lr": DISCRIMINATOR_LEARNING_RATE},
        venv=venv,
        gen_algo=learner,
        reward_net=discriminator,
        custom_logger=logger.configure(tempfile.mkdtemp(prefix="imitation-log-"), []),
    )
    return trainer, learner


def peer_child(instructions: dict) -> dict:
    """One imitation run in this process: the times since the parent's launch, the training
    loop's seconds and the final evaluation's returns."""
    import numpy as np
    import torch

    torch.set_num_threads(1)
    torch.set_num_interop_threads(1)
    import imitation
    import sb3_contrib
    from imitation.util.util import make_vec_env
    from stable_baselines3.common.evaluation import evaluate_policy

    with np.load(instructions["rows"]) as saved:
        rows = {key: saved[key] for key in ("obs", "acts", "next_obs", "dones")}
    trainer, learner = peer_trainer(instructions, rows)
    started, started_cpu = time.time(), time.process_time()
    trainer.train(instructions["budget"])
    train_seconds, train_cpu_seconds = time.time() - started, time.process_time() - started_cpu
    seed = instructions["seed"]
    evaluation = make_vec_env("Pendulum-v1", rng=np.random.default_rng(seed + 10_000), n_envs=8)
    returns, _ = evaluate_policy(
        learner.policy, evaluation, n_eval_episodes=instructions["num_eval_episodes"],
        deterministic=True, return_episode_rewards=True,
    )  # fmt: skip
    return {
        "train_seconds": train_seconds,
        "train_cpu_seconds": train_cpu_seconds,
        "final_return": float(np.mean(returns)),
        "versions": {
            "imitation": imitation.__version__,
            "sb3_contrib": sb3_contrib.__version__,
            "torch": torch.__version__,
            "numpy": np.__version__,
        },
    }


# -- the parent: demonstrations, processes, table ---------------------------------------------


def peer_rows(demos_path: str) -> tuple[dict, tuple[float, float]]:
    """The rows imitation is fed, from pngail-jax's loader (the file's known action scale
    applied, actions clipped to Pendulum's torque bound as our discriminator sees them), as
    imitation's transition fields (float32 ``obs[N, 3]``, ``acts[N, 1]``, ``next_obs[N, 3]``,
    bool ``dones[N]``: the next row of the same trajectory, the last row its own), and the
    file's ``(random, optimal)`` returns."""
    import numpy as np

    from pngail_jax import envs
    from pngail_jax.demos import load_released

    demos = load_released(demos_path)
    env = envs.make("Pendulum-v1")
    obs = demos.observations.astype(np.float32)
    # A file without trajectories (not the authors' layout) is one trajectory here: imitation
    # needs a next observation per row, which its discriminator (no next state) never reads.
    ids = demos.trajectory_ids if demos.trajectory_ids is not None else np.zeros(len(obs))
    last = np.append(ids[1:] != ids[:-1], True)
    rows_index = np.arange(len(obs))
    following = np.where(last, rows_index, np.minimum(rows_index + 1, len(obs) - 1))
    rows = {
        "obs": obs,
        "acts": np.clip(demos.actions, env.action_low, env.action_high).astype(np.float32),
        "next_obs": obs[following],
        "dones": last,
    }
    return rows, (demos.metadata["random_return"], demos.metadata["optimal_return"])


def our_command(args, budget: int, seed: int, out: Path) -> list[str]:
    """The sweep's command line for one run of ``budget`` env steps."""
    iterations = budget // (args.num_envs * args.unroll_length)
    command = [
        sys.executable, "-m", "experiments.sweep", "--demos", args.demos, "--methods", "gail",
        "--seeds", "1", "--seed", str(seed), "--iterations", str(iterations),
        "--num-envs", str(args.num_envs), "--unroll-length", str(args.unroll_length),
        "--num-eval-episodes", str(args.num_eval_episodes),
        "--out", str(out / "run"), "--compile-cache", str(out / "cache"),
    ]  # fmt: skip
    if iterations < 50:  # the sweep's chunks are 50 iterations, its evaluations every 10
        every = min(10, iterations)
        command += ["--chunk-iterations", str(every), "--eval-every", str(every)]
    return command


class Launched(NamedTuple):
    """A finished child: its exit status and output, the seconds from launch to exit and the
    CPU seconds it used (user + system: on a shared machine, the figure other processes do
    not stretch, as they stretch the wall clock)."""

    returncode: int
    stdout: str
    output_tail: str
    seconds: float
    cpu_seconds: float


def launch(command: list[str], cpu: int | None) -> Launched:
    """``command`` run from the repository root on ``cpu`` with one thread."""
    pin = ["taskset", "-c", str(cpu)] if cpu is not None else []
    environment = {**os.environ, **THREAD_VARIABLES}
    with tempfile.TemporaryFile("w+") as stdout, tempfile.TemporaryFile("w+") as stderr:
        start = time.time()
        child = subprocess.Popen([*pin, *command], stdout=stdout, stderr=stderr, text=True,
                                 cwd=ROOT, env=environment)  # fmt: skip
        # wait4: this child's own resource use (two children may run at once).
        _, status, usage = os.wait4(child.pid, 0)
        seconds = time.time() - start
        child.returncode = os.waitstatus_to_exitcode(status)
        stdout.seek(0), stderr.seek(0)
        printed, errors = stdout.read(), stderr.read()
    return Launched(child.returncode, printed, (printed + errors)[-3000:], seconds,
                    usage.ru_utime + usage.ru_stime)  # fmt: skip


def run_ours(args, budget: int, seed: int, cpu: int | None) -> dict:
    """One pngail-jax run: the sweep's process, its summary's rate and final return."""
    with tempfile.TemporaryDirectory(prefix="vs-imitation-") as scratch:
        command = our_command(args, budget, seed, Path(scratch))
        done = launch(command, cpu)
        summary_path = Path(scratch) / "run" / "summary.json"
        if done.returncode != 0 or not summary_path.exists():
            raise SystemExit(f"pngail-jax failed:\n{done.output_tail}")
        summary = json.loads(summary_path.read_text())
    from pngail_jax import __version__

    (run,) = summary["methods"]["gail"]["per_seed"]
    rate = summary["train_env_steps_per_second"]
    return {"total_seconds": done.seconds, "total_cpu_seconds": done.cpu_seconds,
            "train_seconds": budget / rate,
            "train_env_steps_per_second": rate, "final_return": run["final_return"],
            "versions": {"pngail_jax": __version__},
            "command": " ".join(command[1:]).split(" --out ")[0]}  # fmt: skip


def run_peer(args, budget: int, seed: int, cpu: int | None, rows_path: Path) -> dict:
    """One imitation run in the peer's interpreter."""
    instructions = {"budget": budget, "seed": seed, "rows": str(rows_path),
                    "num_envs": args.num_envs, "unroll_length": args.unroll_length,
                    "num_eval_episodes": args.num_eval_episodes}  # fmt: skip
    command = [args.peer_python, str(Path(__file__).resolve()), "--peer-child",
               json.dumps(instructions)]  # fmt: skip
    done = launch(command, cpu)
    results = [line for line in done.stdout.splitlines() if line.startswith("RESULT ")]
    if done.returncode != 0 or not results:
        raise SystemExit(f"imitation failed:\n{done.output_tail}")
    result = json.loads(results[-1].removeprefix("RESULT "))
    return {
        **result,
        "total_seconds": done.seconds,
        "total_cpu_seconds": done.cpu_seconds,
        "train_env_steps_per_second": budget / result["train_seconds"],
        "command": f"benchmarks/vs_imitation.py --peer-child '{json.dumps(instructions)}'",
    }


def run_all(args, jobs: list[tuple[str, int, int]], rows_path: Path, return_range) -> list[dict]:
    """Every ``(library, budget, seed)`` job, one per CPU of ``--cpus`` at a time (the rows
    so far written to ``--json`` after each, so a long run cut short keeps what it measured)."""
    from common import context, write_rows

    cpus = [int(cpu) for cpu in args.cpus.split(",")] if args.cpus else [None]
    free: queue.Queue = queue.Queue()
    for cpu in cpus:
        free.put(cpu)
    random_return, optimal_return = return_range
    finished: list[dict] = []
    lock = threading.Lock()

    def work(job):
        library, budget, seed = job
        cpu = free.get()
        try:
            load_before = os.getloadavg()[0]
            if library == "pngail-jax":
                row = run_ours(args, budget, seed, cpu)
            else:
                row = run_peer(args, budget, seed, cpu, rows_path)
        finally:
            free.put(cpu)
        normalised = (row["final_return"] - random_return) / (optimal_return - random_return)
        print(f"{library} {budget:,} seed {seed} on cpu {cpu}: {row['total_seconds']:.1f} s "
              f"({row['total_cpu_seconds']:.1f} s CPU), {row['train_env_steps_per_second']:,.0f} "
              f"steps/s, return {normalised:.2f}", flush=True)  # fmt: skip
        row = {
            "name": f"{library}/{budget}/{seed}", "library": library, "budget": budget,
            "seed": seed, "cpu": cpu, **row, "final_normalized_return": normalised,
            "load_before": load_before, "load_after": os.getloadavg()[0], **context(),
        }  # fmt: skip
        with lock:
            finished.append(row)
            write_rows(args.json, finished)
        return row

    with ThreadPoolExecutor(len(cpus)) as pool:
        return list(pool.map(work, jobs))


# -- the tables -------------------------------------------------------------------------------


def summaries(rows: list[dict]) -> dict[tuple[str, int], dict]:
    """Per (library, budget): ``seed_summary`` of each measured quantity over its seeds."""
    from pngail_jax.analysis.stats import seed_summary

    quantities = ("total_seconds", "total_cpu_seconds", "train_env_steps_per_second",
                  "final_normalized_return")  # fmt: skip
    groups: dict[tuple[str, int], list[dict]] = {}
    for row in rows:
        groups.setdefault((row["library"], row["budget"]), []).append(row)
    return {
        key: {name: seed_summary([row[name] for row in group]) for name in quantities}
        for key, group in groups.items()
    }


def _mean_se(summary: dict, digits: int) -> str:
    if summary["num_seeds"] < 2:
        return f"{summary['mean']:,.{digits}f}"
    return f"{summary['mean']:,.{digits}f} ± {summary['se']:,.{digits}f}"


def runs_table(rows: list[dict]) -> str:
    """A line per library and budget: rate, whole process (wall clock and CPU), normalised
    final return."""
    from common import markdown_table

    header = ["library", "env steps", "seeds", "training env steps/s", "whole process s",
              "whole process CPU s", "final normalised return", "IQM [95% CI]"]  # fmt: skip
    lines = []
    for (library, budget), summary in sorted(summaries(rows).items(), key=lambda i: i[0][::-1]):
        returns = summary["final_normalized_return"]
        low, high = returns["ci95"]
        lines.append([
            library, f"{budget:,}", returns["num_seeds"],
            _mean_se(summary["train_env_steps_per_second"], 0),
            _mean_se(summary["total_seconds"], 1), _mean_se(summary["total_cpu_seconds"], 1),
            _mean_se(returns, 2),
            f"{returns['iqm']:.2f} [{low:.2f}, {high:.2f}]",
        ])  # fmt: skip
    return markdown_table(header, lines, "lrrrrrrr")


def ratio_table(rows: list[dict]) -> str:
    """Per budget with both libraries: imitation's mean over ours (rate: ours over theirs),
    and whether the whole process (wall clock, CPU seconds) meets the issue's goal where it
    sets one."""
    from common import markdown_table

    found = summaries(rows)
    lines = []
    for budget in sorted({budget for _, budget in found}):
        if ("pngail-jax", budget) not in found or ("imitation", budget) not in found:
            continue
        ours, peer = found["pngail-jax", budget], found["imitation", budget]
        rate = (
            ours["train_env_steps_per_second"]["mean"] / peer["train_env_steps_per_second"]["mean"]
        )
        whole, cpu = (
            peer[name]["mean"] / ours[name]["mean"]
            for name in ("total_seconds", "total_cpu_seconds")
        )
        goal = GOALS.get(budget)
        verdict = "-" if goal is None else (
            f"{goal:g}x: wall {'met' if whole >= goal else 'not met'}, "
            f"CPU {'met' if cpu >= goal else 'not met'}"
        )  # fmt: skip
        lines.append([f"{budget:,}", f"{rate:.1f}x", f"{whole:.1f}x", f"{cpu:.1f}x", verdict])
    header = ["env steps", "training rate, ours / imitation", "whole process, imitation / ours",
              "whole process CPU, imitation / ours", "goal"]  # fmt: skip
    return markdown_table(header, lines, "lrrrl")


def main(argv=None) -> list[dict]:
    args = parse_args(argv)
    if args.peer_child is not None:
        print("RESULT " + json.dumps(peer_child(json.loads(args.peer_child))), flush=True)
        return []
    import numpy as np
    from common import write_rows

    libraries = args.libraries.split(",")
    if not set(libraries) <= set(LIBRARIES) or not libraries:
        raise SystemExit(f"--libraries: of {', '.join(LIBRARIES)}, got {args.libraries!r}")
    if "imitation" in libraries and not Path(args.peer_python).exists():
        raise SystemExit(f"--peer-python: no interpreter at {args.peer_python} "
                         "(benchmarks/peer-requirements.txt says how to make one)")  # fmt: skip
    budgets = [int(budget) for budget in args.budgets.split(",")]
    steps = args.num_envs * args.unroll_length
    if any(budget < steps or budget % steps for budget in budgets):
        raise SystemExit(f"--budgets: each a positive multiple of {steps:,} env steps")
    rows_for_peer, return_range = peer_rows(args.demos)
    jobs = [(library, budget, seed) for budget in budgets for seed in range(args.seeds)
            for library in libraries]  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="vs-imitation-rows-") as scratch:
        rows_path = Path(scratch) / "rows.npz"
        np.savez(rows_path, **rows_for_peer)
        rows = run_all(args, jobs, rows_path, return_range)
    print(runs_table(rows))
    print()
    print(ratio_table(rows))
    write_rows(args.json, rows)
    return rows


if __name__ == "__main__":
    main()
