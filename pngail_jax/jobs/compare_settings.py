"""``compare_settings(config, out)``: what a run setting does to learning. TRPO on the true
reward, arms x the same seeds, each arm one ``train_rl`` run into ``out/<arm>/`` (kept when
that directory holds a finished run, so an interrupted comparison continues where it
stopped). Then every arm's final policies are evaluated by one protocol: the same reset keys,
on the task's own MJX solver and on the fast one (a policy trained on the fast physics is
also judged on the accurate one). Writes ``comparison.json`` (last: it marks a finished
comparison), ``comparison.md`` and ``comparison.png``.

An arm is "not worse" than the baseline when its mean final return is at least the
baseline's mean minus one standard error (docs/performance.md).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import jax
import numpy as np
import orbax.checkpoint as ocp

from pngail_jax import envs
from pngail_jax.analysis.report import json_safe, read_evaluations
from pngail_jax.config import validation
from pngail_jax.config.learner import LearnerConfig, TRPOConfig
from pngail_jax.config.saved import provenance
from pngail_jax.config.settings import REFERENCE_SETTINGS, parse_solver, settings_for
from pngail_jax.jobs.errors import refusals
from pngail_jax.jobs.train_rl import TrainRLConfig, flat_document, train_rl
from pngail_jax.networks import GaussianPolicy
from pngail_jax.rl.on_policy import ObservationNormalizer
from pngail_jax.rl.rollout import evaluate
from pngail_jax.storage.integrity import atomic_path, atomic_write_text, write_json
from pngail_jax.storage.outputs import claimed, prepare_output

PROGRAM = "compare_settings"
COMPARISON_FILE = "comparison.json"  # written last: its presence marks a finished comparison

# Each arm: the settings it starts from ("table": the task's row; "reference": the authors'),
# the settings it changes, its Fisher subsample and its value fit's epochs. The flags train_rl
# takes for the same run are in ``arm_flags``.
ARMS = {
    "reference": {"settings": "reference"},
    "reference-fast": {"settings": "reference", "solver": "fast"},
    # between the fast caps (1 / 4) and gymnasium's own (100 / 50): four times the fast ones
    "reference-solver-4-16": {"settings": "reference", "solver": "4/16"},
    "mid-fast": {"settings": "reference", "solver": "fast", "num_envs": 100, "unroll_length": 50},
    "wide-fast": {"settings": "reference", "solver": "fast", "num_envs": 250, "unroll_length": 20},
    "reference-fast-value10": {"settings": "reference", "solver": "fast", "value_epochs": 10},
    "reference-value10": {"settings": "reference", "value_epochs": 10},
    "wide-fast-value10": {
        "settings": "reference",
        "solver": "fast",
        "num_envs": 250,
        "unroll_length": 20,
        "value_epochs": 10,
    },
    "table": {},
    "table-own-solver": {"solver": "own"},
    "table-normalized": {"normalize_observations": True},
    "reference-fisher5": {"settings": "reference", "fisher_subsample": 5},
    "table-fisher5": {"fisher_subsample": 5},
}


def arm_flags(arm: str) -> list[str]:
    """The train_rl flags of ``arm`` (besides the common ones): what --help lists."""
    flags = []
    for name, value in ARMS[arm].items():
        flag = "--" + name.replace("_", "-")
        flags += [flag] if value is True else [flag, str(value)]
    return flags


@dataclasses.dataclass(frozen=True)
class CompareSettingsConfig:
    """Which arms (``ARMS``), judged against ``baseline`` (None: the first), with ``seeds``
    seeds x ``iterations`` TRPO iterations each, evaluated every ``eval_every`` and at the
    end on ``num_eval_episodes`` episodes."""

    env: str
    arms: tuple[str, ...] = ("reference-fast", "table")
    baseline: str | None = None
    seeds: int = 5
    iterations: int = 400
    eval_every: int = 50
    num_eval_episodes: int = 32
    seed: int = 0

    def __post_init__(self):
        object.__setattr__(self, "arms", tuple(self.arms))
        unknown = [arm for arm in self.arms if arm not in ARMS]
        if unknown or not self.arms:
            validation.fail("arms", f"unknown arm {unknown[0]!r}; known: {', '.join(ARMS)}"
                            if unknown else "give at least one arm")  # fmt: skip
        if len(set(self.arms)) != len(self.arms):
            validation.fail("arms", f"an arm is named twice: {', '.join(self.arms)}")
        if self.baseline is None:
            object.__setattr__(self, "baseline", self.arms[0])
        elif self.baseline not in self.arms:
            validation.fail("baseline", f"{self.baseline!r} is not among the arms")
        for name in ("seeds", "iterations", "eval_every", "num_eval_episodes"):
            validation.integer(name, getattr(self, name), 1)
        if self.env == "Pendulum-v1" and any("solver" in ARMS[arm] for arm in self.arms):
            validation.fail("arms", "Pendulum-v1 has no MJX solver: choose arms without one")

    def arm_config(self, arm: str) -> TrainRLConfig:
        """The train_rl run of ``arm``."""
        spec = dict(ARMS[arm])
        base = REFERENCE_SETTINGS if spec.pop("settings", "table") == "reference" else None
        base = base or settings_for(self.env)
        fisher_subsample = spec.pop("fisher_subsample", 1)
        value_epochs = spec.pop("value_epochs", 1)
        if "solver" in spec:
            spec.update(parse_solver(spec.pop("solver")))
        settings = dataclasses.replace(base, eval_every=self.eval_every, **spec)
        return TrainRLConfig(
            env=self.env,
            iterations=self.iterations,
            seeds=self.seeds,
            seed=self.seed,
            settings=settings,
            learner=LearnerConfig(
                trpo=TRPOConfig(fisher_subsample=fisher_subsample, num_value_epochs=value_epochs)
            ),
        )


def compare_settings(
    config: CompareSettingsConfig, out, *, overwrite: bool = False, command=None
) -> dict:
    """Runs (or keeps) every arm of ``config`` into ``out/<arm>/``, evaluates them alike and
    writes the comparison; returns its summary. ``out`` is new, empty, an unfinished
    comparison (continued), or with ``overwrite`` a finished one (rewritten, its arms kept).
    ``command``: the flags recorded in the summary's provenance (default: this process's).
    Raises ``RunError`` with one line."""
    out = Path(out)
    unfinished = not (out / COMPARISON_FILE).exists()
    with refusals(), claimed(out, PROGRAM, overwrite=overwrite or unfinished):
        prepare_output(out, PROGRAM)  # marked, never emptied: its finished arms are reused
        origin = {  # taken before training: the commit the arms train at
            **provenance(command, program="experiments.compare_settings"),
            # trained by an earlier process (its commit is not known)
            "arms_reused": [arm for arm in config.arms if arm_finished(out / arm)],
        }
        directories = {arm: run_arm(config, out, arm) for arm in config.arms}
        results, curves = evaluate_arms(config, directories)
        return write_comparison(config, out, results, curves, origin)


def arm_finished(directory: Path) -> bool:
    """Whether an arm's train_rl run in ``directory`` is finished (its policy written)."""
    return (directory / "policy.json").exists()


def judged_physics(env: str) -> dict[str, dict]:
    """The physics every arm's final policies are evaluated on, by name: the task's own,
    and MJX's fast solver beside it on the MuJoCo tasks."""
    return {"own": {}} if env == "Pendulum-v1" else {"own": {}, "fast": dict(envs.FAST_SOLVER)}


def trained_on(env: str, env_options: dict) -> str:
    """Which of ``judged_physics`` an arm trained on (its verdict is read there). An arm on
    caps between the fast ones and the task's own (e.g. 4 / 16) is judged on the task's own
    physics, the one its caps approximate."""
    fast = env_options and dict(env_options) == dict(envs.FAST_SOLVER)
    return "fast" if fast or env == "Ant" else "own"


def solver_label(env: str, env_options: dict) -> str:
    """The solver an arm trained on, in words: "own solver", "fast solver" or "solver I / L"."""
    if trained_on(env, env_options) == "fast":
        return "fast solver"
    if not env_options:
        return "own solver"
    return f"solver {env_options['solver_iterations']} / {env_options['ls_iterations']}"


def average_during_training(returns: np.ndarray) -> tuple[float, float]:
    """Mean ± s.e. over seeds of each seed's mean evaluation (``returns``: seeds x
    evaluations)."""
    return mean_and_standard_error(np.asarray(returns).mean(axis=1))


def run_arm(config: CompareSettingsConfig, out: Path, arm: str) -> Path:
    """``arm``'s train_rl run in ``out/<arm>/``, or the finished one there."""
    directory = out / arm
    if arm_finished(directory):
        print(f"{arm}: finished run in {directory}, reused", flush=True)
        return directory
    print(f"{arm}: train_rl {' '.join(arm_flags(arm)) or '(the table)'}", flush=True)
    # An arm cut short is the comparison's own, started again.
    train_rl(config.arm_config(arm), directory, overwrite=directory.exists())
    return directory


def write_comparison(
    config: CompareSettingsConfig, out: Path, results: dict, curves, origin=None
) -> dict:
    """The verdicts, then comparison.md, .png and (last) .json, which also keeps each arm's
    evaluation curve and ``origin`` (the command, commit and machine: ``provenance``)."""
    baseline = results[config.baseline]
    baseline_mean, baseline_se = baseline["final_return_mean_se"][
        trained_on(config.env, baseline["env_options"])
    ]
    for result in results.values():
        result["trained_on"] = trained_on(config.env, result["env_options"])
        mean, _ = result["final_return_mean_se"][result["trained_on"]]
        result["not_worse_than_baseline"] = bool(mean >= baseline_mean - baseline_se)
    summary = {
        "env": config.env,
        "seeds": config.seeds,
        "iterations": config.iterations,
        "baseline": config.baseline,
        "eval_episodes": config.num_eval_episodes,
        "arms": results,
        "curves": {
            arm: {"env_steps": np.asarray(steps).tolist(), "eval_return": returns.tolist()}
            for arm, (steps, returns) in curves.items()
        },
        **({} if origin is None else {"provenance": origin}),
    }
    markdown = comparison_markdown(summary)
    atomic_write_text(out / "comparison.md", markdown + "\n")
    plot(out / "comparison.png", curves, f"TRPO on {config.env}, true reward")
    write_json(out / COMPARISON_FILE, json_safe(summary))  # null, never a bare NaN
    print(f"\n{markdown}\n\nwrote {out}/comparison.{{json,md,png}}")
    return summary


def read_arm_curves(directory: Path) -> tuple[np.ndarray, np.ndarray]:
    """(env_steps int[I], eval returns float[seeds, I]) at the evaluated iterations."""
    ((steps, returns),) = read_evaluations(directory / "metrics.csv", "eval/return").values()
    return steps, returns


def make_evaluator(env_name: str, solver: dict, metadata: dict, num_episodes: int, key):
    """A compiled ``(policy_params, normalizer) -> float[seeds]``: the final deterministic
    return of every seed's policy on ``env_name`` with ``solver``, from the same
    ``num_episodes`` reset keys for every arm (built once per physics, shared by the arms)."""
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
    metadata = json.loads((directory / "policy.json").read_text())
    # orbax takes absolute paths only: a comparison's --out may be relative
    return metadata, ocp.StandardCheckpointer().restore((directory / "policy_params").absolute())


def mean_and_standard_error(values) -> tuple[float, float]:
    values = np.asarray(values, float)
    if len(values) < 2:
        return float(values.mean()), float("nan")
    return float(values.mean()), float(values.std(ddof=1) / math.sqrt(len(values)))


def draw_curve(axis, steps, returns, label: str, color=None, alpha: float = 0.25) -> None:
    """One arm's evaluation returns (float[seeds, evaluations]) on ``axis``: the mean over
    seeds, and a band of one standard error around it."""
    returns = np.asarray(returns, float)
    mean = returns.mean(axis=0)
    error = returns.std(axis=0, ddof=1) / math.sqrt(len(returns))
    axis.plot(steps, mean, lw=2, marker="o", ms=3, label=label, color=color)
    axis.fill_between(steps, mean - error, mean + error, alpha=alpha, color=color)


def plot(path: Path, curves: dict, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(7, 4.5))
    for arm, (steps, returns) in curves.items():
        draw_curve(axis, steps, returns, f"{arm} ({len(returns)} seeds)")
    axis.set(xlabel="environment steps per run", ylabel="evaluation return", title=title)
    axis.grid(alpha=0.3)
    axis.legend()
    figure.tight_layout()
    with atomic_path(path) as temporary:  # keeps the .png suffix savefig takes the format from
        figure.savefig(temporary, dpi=120)
    plt.close(figure)


def evaluate_arms(config: CompareSettingsConfig, directories: dict) -> tuple[dict, dict]:
    """Each arm's saved policies evaluated on the task's own physics (and MJX's fast solver
    beside it on the MuJoCo tasks), with its TRPO settings and learning curves."""
    key = jax.random.key(config.seed + 10_000)  # evaluation keys unused by any training run
    physics = judged_physics(config.env)
    evaluators = {}
    results, curves = {}, {}
    for arm, directory in directories.items():
        curves[arm] = read_arm_curves(directory)
        saved = flat_document(json.loads((directory / "config.json").read_text()))
        metadata, arrays = saved_policies(directory)
        final = {}
        for name, solver in physics.items():
            if name not in evaluators:
                evaluators[name] = make_evaluator(
                    config.env, solver, metadata, config.num_eval_episodes, key
                )
            returns = evaluators[name](arrays["policy_params"], arrays["normalizer"])
            final[name] = np.asarray(returns)
        results[arm] = {
            "rollout": {
                name: saved["rollout"][name]
                for name in ("num_envs", "unroll_length", "normalize_observations")
            },
            "env_options": saved["env_options"],
            "fisher_subsample": saved["trpo"]["fisher_subsample"],
            "value_epochs": saved["trpo"]["num_value_epochs"],
            "final_return": {name: values.tolist() for name, values in final.items()},
            "final_return_mean_se": {
                name: mean_and_standard_error(values) for name, values in final.items()
            },
            "average_eval_return_mean_se": average_during_training(curves[arm][1]),
        }
    return results, curves


def arm_description(env: str, result: dict) -> str:
    """An evaluated arm's settings in words: "25 x 200, own solver, 10 value epochs"."""
    settings = result["rollout"]
    words = [f"{settings['num_envs']} x {settings['unroll_length']}"]
    words.append(solver_label(env, result["env_options"]))
    if settings["normalize_observations"]:
        words.append("norm. obs")
    if result["fisher_subsample"] > 1:
        words.append(f"Fisher on every {result['fisher_subsample']}th step")
    if result.get("value_epochs", 1) > 1:
        words.append(f"{result['value_epochs']} value epochs")
    return ", ".join(words)


def comparison_markdown(summary: dict) -> str:
    def cell(pair):
        mean, se = (math.nan if value is None else value for value in pair)  # JSON's null
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
        lines.append(
            f"| {arm} | {arm_description(summary['env'], result)} | "
            f"{cell(result['final_return_mean_se']['own'])} | "
            f"{cell(result['final_return_mean_se'].get('fast', (math.nan, math.nan)))} | "
            f"{cell(result['average_eval_return_mean_se'])} | "
            f"{'yes' if result['not_worse_than_baseline'] else 'NO'} |"
        )
    return "\n".join(lines)
