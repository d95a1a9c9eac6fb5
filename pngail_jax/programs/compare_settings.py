"""What a run setting does to learning: TRPO on the true reward, arms x the same seeds.

    python -m experiments.compare_settings --env Hopper --arms reference-fast,table \\
        --seeds 5 --iterations 400 --out runs/settings/Hopper

Each arm is one ``experiments.train_rl`` run into ``OUT/<arm>/`` (skipped when that directory
already holds a finished run, so an interrupted comparison continues where it stopped), all
with the same seeds, Fisher form and iteration count. Then every arm's final policies are
evaluated by one protocol: ``--num-eval-episodes`` deterministic episodes from the same reset keys
on the task's own MJX solver and on the fast one, so a policy trained on the fast physics is
also judged on the accurate one. Writes ``comparison.json``, ``comparison.md`` and
``comparison.png`` (evaluation return vs environment steps, mean and standard error band).

``comparison.json`` is written last (each output atomically), so it marks a finished
comparison: running into the same ``--out`` again refuses unless ``--overwrite`` is given
(which rewrites the comparison; finished arms are still reused).

The verdict follows docs/performance.md: an arm is "not worse" than ``--baseline`` when its
mean final return is at least the baseline's mean minus one standard error.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from pngail_jax.integrity import atomic_path, atomic_write_text, write_json
from pngail_jax.programs.cli import (
    ENV_HELP,
    ArgumentParser,
    HelpFormatter,
    check_env,
    check_positive,
    claim_output,
    known_names,
    note_deprecated,
    path_argument,
    prepare_output,
)
from pngail_jax.report import json_safe

COMPARISON_FILE = "comparison.json"  # written last: its presence marks a finished comparison

# train_rl flags of each arm (the common flags are added by run_arm).
ARMS = {
    "reference": ["--settings", "reference"],
    "reference-fast": ["--settings", "reference", "--solver", "fast"],
    "mid-fast": [
        *("--settings", "reference", "--solver", "fast"),
        *("--num-envs", "100", "--unroll-length", "50"),
    ],
    "wide-fast": [
        *("--settings", "reference", "--solver", "fast"),
        *("--num-envs", "250", "--unroll-length", "20"),
    ],
    "table": [],
    "table-own-solver": ["--solver", "own"],
    "table-normalized": ["--normalize-observations"],
    "reference-fisher5": ["--settings", "reference", "--fisher-subsample", "5"],
    "table-fisher5": ["--fisher-subsample", "5"],
}


def parse_args(argv=None) -> argparse.Namespace:
    parser = ArgumentParser(
        "compare_settings",
        description=__doc__.split("\n\n")[0],
        epilog="arms:\n"
        + "\n".join(f"  {name:18s} train_rl {' '.join(flags)}" for name, flags in ARMS.items()),
        formatter_class=HelpFormatter,
    )
    parser.add_argument("--env", required=True, help=ENV_HELP)
    parser.add_argument("--arms", default="reference-fast,table", help="comma-separated")
    parser.add_argument("--baseline", help="the arm others are judged against (default: first)")
    parser.add_argument("--seeds", type=int, default=5, help="seeds per arm (the same in each)")
    parser.add_argument("--iterations", type=int, default=400, help="TRPO iterations per arm")
    parser.add_argument("--eval-every", type=int, default=50, help="iterations between evaluations")
    parser.add_argument(
        "--num-eval-episodes",
        "--eval-episodes",
        dest="num_eval_episodes",
        type=int,
        default=32,
        help="of the final evaluation",
    )
    parser.add_argument("--seed", type=int, default=0, help="base PRNG seed")
    parser.add_argument(
        "--out", type=path_argument, required=True, help="output directory (required)"
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="rewrite a finished comparison in --out (its finished arms are reused; "
        "default: refuse)",
    )
    args = parser.parse_args(argv)
    note_deprecated(argv, {"--eval-episodes": "--num-eval-episodes"})
    # Running into an unfinished comparison again is its resume (finished arms are reused).
    unfinished = not (args.out / COMPARISON_FILE).exists()
    claim_output(parser, args.out, "compare_settings", args.overwrite or unfinished)
    check_env(parser, args.env)
    args.arms = known_names(parser, args.arms, list(ARMS), "arm", flag="--arms")
    if args.env == "Pendulum-v1" and any("--solver" in ARMS[arm] for arm in args.arms):
        parser.error("Pendulum-v1 has no MJX solver: choose arms without --solver")
    args.baseline = args.baseline or args.arms[0]
    if args.baseline not in args.arms:
        parser.error(f"--baseline {args.baseline!r} is not among --arms")
    check_positive(parser, args, ("seeds", "iterations", "eval_every", "num_eval_episodes"))
    return args


def run_arm(args, arm: str) -> Path:
    from pngail_jax.programs import train_rl

    directory = args.out / arm
    if (directory / "policy.json").exists():
        print(f"{arm}: finished run in {directory}, reused", flush=True)
        return directory
    flags = [
        *("--env", args.env, "--seeds", str(args.seeds), "--seed", str(args.seed)),
        *("--iterations", str(args.iterations), "--eval-every", str(args.eval_every)),
        *("--fisher", "gauss_newton", "--out", str(directory)),
        *ARMS[arm],
    ]
    if directory.exists():  # an arm cut short: the comparison's own, started again
        flags.append("--overwrite")
    print(f"{arm}: python -m experiments.train_rl {' '.join(flags)}", flush=True)
    train_rl.main(flags)
    return directory


def read_curves(directory: Path) -> tuple[np.ndarray, np.ndarray]:
    """(env_steps int[I], eval returns float[seeds, I]) at the evaluated iterations."""
    from pngail_jax.report import read_evaluations

    ((steps, returns),) = read_evaluations(directory / "metrics.csv", "eval/return").values()
    return steps, returns


def make_evaluator(env_name: str, solver: dict, metadata: dict, num_episodes: int, key):
    """A compiled ``(policy_params, normalizer) -> float[seeds]``: the final deterministic
    return of every seed's policy on ``env_name`` with ``solver``, from the same
    ``num_episodes`` reset keys for every arm (built once per physics, shared by the arms)."""
    import jax

    from pngail_jax import envs
    from pngail_jax.networks import GaussianPolicy
    from pngail_jax.rl.rollout import evaluate
    from pngail_jax.rl.train import ObservationNormalizer

    env = envs.make(env_name, **solver)
    policy = GaussianPolicy(metadata["action_size"], tuple(metadata["hidden_sizes"]))
    keys = jax.random.split(key, num_episodes)

    def one_seed(params, normalizer_fields):
        # A run without observation normalisation saved a never-updated normaliser
        # (count 0), which is the identity.
        normalizer = ObservationNormalizer(**normalizer_fields)
        return evaluate(env, policy, params, normalizer, keys)

    return jax.jit(jax.vmap(one_seed))


def saved_policies(directory: Path):
    """(policy.json metadata, {"policy_params", "normalizer"} stacked over seeds)."""
    import orbax.checkpoint as ocp

    metadata = json.loads((directory / "policy.json").read_text())
    return metadata, ocp.StandardCheckpointer().restore(directory / "policy_params")


def mean_and_standard_error(values) -> tuple[float, float]:
    values = np.asarray(values, float)
    if len(values) < 2:
        return float(values.mean()), float("nan")
    return float(values.mean()), float(values.std(ddof=1) / math.sqrt(len(values)))


def plot(path: Path, curves: dict, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(7, 4.5))
    for arm, (steps, returns) in curves.items():
        mean = returns.mean(axis=0)
        error = returns.std(axis=0, ddof=1) / math.sqrt(len(returns))
        axis.plot(steps, mean, lw=2, marker="o", ms=3, label=f"{arm} ({len(returns)} seeds)")
        axis.fill_between(steps, mean - error, mean + error, alpha=0.25)
    axis.set(xlabel="environment steps per run", ylabel="evaluation return", title=title)
    axis.grid(alpha=0.3)
    axis.legend()
    figure.tight_layout()
    with atomic_path(path) as temporary:  # keeps the .png suffix savefig takes the format from
        figure.savefig(temporary, dpi=120)
    plt.close(figure)


def main(argv=None) -> dict:
    args = parse_args(argv)
    prepare_output(args.out, "compare_settings")  # never emptied: its arms are reused
    directories = {arm: run_arm(args, arm) for arm in args.arms}
    results, curves = evaluate_arms(args, directories)
    trained_on = {
        arm: "fast" if result["env_options"] or args.env == "Ant" else "own"
        for arm, result in results.items()
    }
    baseline_mean, baseline_se = results[args.baseline]["final_return_mean_se"][
        trained_on[args.baseline]
    ]
    for arm, result in results.items():
        mean, _ = result["final_return_mean_se"][trained_on[arm]]
        result["trained_on"] = trained_on[arm]
        result["not_worse_than_baseline"] = bool(mean >= baseline_mean - baseline_se)
    summary = {
        "env": args.env,
        "seeds": args.seeds,
        "iterations": args.iterations,
        "baseline": args.baseline,
        "eval_episodes": args.num_eval_episodes,
        "arms": results,
    }
    markdown = comparison_markdown(summary)
    atomic_write_text(args.out / "comparison.md", markdown + "\n")
    plot(args.out / "comparison.png", curves, f"TRPO on {args.env}, true reward")
    write_json(args.out / COMPARISON_FILE, json_safe(summary))  # null, never a bare NaN
    print(f"\n{markdown}\n\nwrote {args.out}/comparison.{{json,md,png}}")
    return summary


def evaluate_arms(args, directories: dict) -> tuple[dict, dict]:
    """Each arm's saved policies evaluated on the task's own physics (and MJX's fast solver
    beside it on the MuJoCo tasks), with its TRPO settings and learning curves."""
    import jax

    from pngail_jax import envs

    key = jax.random.key(args.seed + 10_000)  # evaluation keys unused by any training run
    physics = {"own": {}}
    if args.env != "Pendulum-v1":
        physics["fast"] = dict(envs.FAST_SOLVER)
    evaluators = {}
    results, curves = {}, {}
    for arm, directory in directories.items():
        curves[arm] = read_curves(directory)
        config = json.loads((directory / "config.json").read_text())
        metadata, arrays = saved_policies(directory)
        final = {}
        for name, solver in physics.items():
            if name not in evaluators:
                evaluators[name] = make_evaluator(
                    args.env, solver, metadata, args.num_eval_episodes, key
                )
            returns = evaluators[name](arrays["policy_params"], arrays["normalizer"])
            final[name] = np.asarray(returns)
        results[arm] = {
            "trpo": {
                name: config["trpo"][name]
                for name in ("num_envs", "unroll_length", "normalize_observations")
            },
            "env_options": config["env_options"],
            "fisher_subsample": config["trpo"]["fisher_subsample"],
            "final_return": {name: values.tolist() for name, values in final.items()},
            "final_return_mean_se": {
                name: mean_and_standard_error(values) for name, values in final.items()
            },
            "average_eval_return_mean_se": mean_and_standard_error(curves[arm][1].mean(axis=1)),
        }
    return results, curves


def comparison_markdown(summary: dict) -> str:
    def cell(pair):
        mean, se = pair
        return f"{mean:.1f} ± {se:.1f}"

    lines = [
        f"{summary['env']}: TRPO on the true reward, {summary['seeds']} seeds x "
        f"{summary['iterations']} iterations; final = deterministic return of the last policy "
        f"on {summary['eval_episodes']} episodes (mean ± s.e. over seeds); baseline "
        f"`{summary['baseline']}` (not worse = mean >= baseline mean - 1 s.e., on the physics "
        "each arm trained on).",
        "",
        "| arm | settings | final, own solver | final, fast solver | average during training "
        "| not worse |",
        "|---|---|---:|---:|---:|---|",
    ]
    for arm, result in summary["arms"].items():
        settings = result["trpo"]
        shape = f"{settings['num_envs']} x {settings['unroll_length']}"
        solver = "fast" if result["trained_on"] == "fast" else "own"
        normalized = ", norm. obs" if settings["normalize_observations"] else ""
        if result["fisher_subsample"] > 1:
            normalized += f", Fisher on every {result['fisher_subsample']}th step"
        lines.append(
            f"| {arm} | {shape}, {solver} solver{normalized} | "
            f"{cell(result['final_return_mean_se']['own'])} | "
            f"{cell(result['final_return_mean_se'].get('fast', (math.nan, math.nan)))} | "
            f"{cell(result['average_eval_return_mean_se'])} | "
            f"{'yes' if result['not_worse_than_baseline'] else 'NO'} |"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    main()
