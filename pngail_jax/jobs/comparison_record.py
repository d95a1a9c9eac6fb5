"""Records of ``experiments.compare_settings`` comparisons: the settings tables of
docs/performance.md as committed data, beside the sweep's run records (``run_records``).

A comparison record is a folder (``records/<name>/``) holding one ``record.json``: the name,
the command, the commit and the machine the comparison ran with (its ``provenance``), the arms
an earlier process trained (whose commit is not known), and the comparison itself: every
arm's settings, each seed's final return on each physics and each arm's evaluation curve
(every seed at every evaluated iteration). No policies, checkpoints or plots: a few kB.
``check`` recomputes every statistic of the table (means, standard errors, the average
during training and the "not worse" verdicts) from the per-seed numbers it keeps.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from pngail_jax.analysis import stats
from pngail_jax.analysis.run_records import MACHINE_KEYS, RECORD_FILE, RecordError, check_name
from pngail_jax.jobs.compare_settings import (
    COMPARISON_FILE,
    PROGRAM,
    arm_description,
    average_during_training,
    comparison_markdown,
    judged_physics,
    mean_and_standard_error,
    trained_on,
)
from pngail_jax.storage.integrity import IntegrityError, read_json, write_json
from pngail_jax.storage.outputs import output_owner

FORMAT = 2  # a comparison record's own (a run record's is run_records.FORMAT)

KIND = "comparison"


def is_comparison(run_dir: Path) -> bool:
    """Whether ``run_dir`` is a folder of ``experiments.compare_settings``."""
    return output_owner(Path(run_dir)) == PROGRAM


def write(run_dir: Path, name: str, records: Path = Path("records")) -> Path:
    """Records the finished comparison in ``run_dir`` as ``records/<name>/`` and checks it
    before writing. A record of that name already there is replaced only if it records the
    same comparison (same command, commit and machine). Returns the record's folder;
    RecordError naming the problem."""
    run_dir = Path(run_dir)
    check_name(name)
    try:
        summary = read_json(run_dir / COMPARISON_FILE, "comparison")
    except FileNotFoundError:
        missing = f"the comparison is not finished ({COMPARISON_FILE} is missing)"
        raise RecordError(f"{run_dir}: {missing}") from None
    except (OSError, IntegrityError) as error:
        raise RecordError(str(error)) from None
    origin = summary.get("provenance")
    if origin is None or "curves" not in summary:
        raise RecordError(
            f"{run_dir}/{COMPARISON_FILE} was written before comparisons kept their command "
            "and curves: run its compare_settings command again (its finished arms are reused)"
        )
    record = {
        "format": FORMAT,
        "kind": KIND,
        "name": name,
        "program": f"experiments.{PROGRAM}",
        "command": origin.get("command_line"),
        "commit": origin.get("git_commit"),
        "machine": {key: origin.get(key) for key in MACHINE_KEYS},
        "arms_reused": origin.get("arms_reused", []),
        "comparison": {key: value for key, value in summary.items() if key != "provenance"},
    }
    folder = Path(records) / name
    verify(json.loads(json.dumps(record)), f"{run_dir}/{COMPARISON_FILE}")  # before writing
    _check_replaceable(folder, record)
    folder.mkdir(parents=True, exist_ok=True)
    write_json(folder / RECORD_FILE, record)
    return folder


def _check_replaceable(folder: Path, record: dict) -> None:
    if not folder.exists() or (folder.is_dir() and not any(folder.iterdir())):
        return
    found = {path.name for path in folder.iterdir()} if folder.is_dir() else None
    if found != {RECORD_FILE}:
        raise RecordError(f"{folder} holds something other than a comparison record: not replaced")
    try:
        old = read_json(folder / RECORD_FILE, "run record")
    except (OSError, IntegrityError) as error:
        unreadable = f"not replaced, its {RECORD_FILE} is unreadable ({error})"
        raise RecordError(f"{folder}: {unreadable}") from None
    same = ("command", "commit", "machine")
    if [old.get(key) for key in same] != [record[key] for key in same]:
        raise RecordError(f"{folder} records another comparison: give another --name")


def _numbers(values) -> np.ndarray:
    """A float array of JSON numbers, nested or not (null: NaN)."""
    as_float = np.frompyfunc(lambda v: math.nan if v is None else v, 1, 1)
    return as_float(np.asarray(values, dtype=object)).astype(float)


def _same(stated, computed) -> bool:
    return np.allclose(_numbers(stated), _numbers(computed), rtol=1e-12, atol=0, equal_nan=True)


def check(folder: Path) -> dict:
    """Verifies the comparison record in ``folder`` (``verify``) and returns it."""
    path = Path(folder) / RECORD_FILE
    try:
        record = read_json(path, "run record")
    except FileNotFoundError:
        raise RecordError(f"{folder} holds no run record ({RECORD_FILE} is missing)") from None
    except (OSError, IntegrityError) as error:
        raise RecordError(f"{path}: unreadable ({error})") from None
    verify(record, path)
    return record


def verify(record: dict, where) -> None:
    """RecordError (naming ``where``) unless every figure the record's table shows follows
    from the per-seed numbers it keeps: which physics each arm trained on, its means and
    standard errors on each physics, its average during training, its verdict, and the
    title's seeds and iterations."""
    if record.get("format") != FORMAT or record.get("kind") != KIND:
        raise RecordError(f"{where}: not a comparison record of format {FORMAT}")
    try:
        comparison = record["comparison"]
        arms, curves = comparison["arms"], comparison["curves"]
        env, physics = comparison["env"], set(judged_physics(comparison["env"]))
        baseline = arms[comparison["baseline"]]
        base_mean, base_se = _numbers(
            baseline["final_return_mean_se"][trained_on(env, baseline["env_options"])]
        )
        for arm, result in arms.items():
            on = trained_on(env, result["env_options"])
            problem = _arm_problem(comparison, result, curves[arm], physics, on)
            mean = _numbers(result["final_return"][on]).mean()
            if problem is None and result["not_worse_than_baseline"] != bool(
                mean >= base_mean - base_se
            ):
                problem = "verdict"
            if problem is not None:
                raise RecordError(f"{where}: arm {arm}'s {problem} differs from its numbers")
    except (KeyError, TypeError, ValueError, IndexError) as error:
        raise RecordError(f"{where}: not a whole comparison record ({error!r})") from None


def _arm_problem(comparison, result, curve, physics, on) -> str | None:
    """What of one arm's figures does not follow from its per-seed numbers (None: all do)."""
    finals = result["final_return"]
    if set(finals) != physics or set(result["final_return_mean_se"]) != physics:
        return "set of physics"
    if result["trained_on"] != on:
        return "physics trained on"
    returns = _numbers(curve["eval_return"])  # seeds x evaluations
    rollout = result["rollout"]
    steps = comparison["iterations"] * rollout["num_envs"] * rollout["unroll_length"]
    seeds = comparison["seeds"]
    if any(len(values) != seeds for values in finals.values()) or returns.shape != (
        seeds, len(curve["env_steps"])
    ) or curve["env_steps"][-1] != steps:  # fmt: skip
        return "count of seeds or steps"
    for name, values in finals.items():
        if not _same(result["final_return_mean_se"][name], _mean_se(values)):
            return f"final return on the {name} solver"
    if not _same(result["average_eval_return_mean_se"], average_during_training(returns)):
        return "average during training"
    return None


def _mean_se(values):
    return mean_and_standard_error(_numbers(values))


def table(record: dict) -> str:
    """The comparison's markdown table, as ``experiments.compare_settings`` prints it."""
    return comparison_markdown(record["comparison"])


def contrast_table(records: list[dict], arms: list[str], baseline: str) -> str:
    """One table across comparisons (one per task): each task's ``baseline`` arm and each of
    ``arms`` it has, every arm's final return on the task's own physics (the real task,
    whatever it trained on; mean ± s.e. over seeds), the probability that a seed of the arm
    ends above a seed of the baseline there (with its 95% bootstrap interval), and the
    average during training. Arms a comparison lacks are left out."""
    lines = [
        "| task | arm | settings | final, own solver | P(arm > baseline) [95% CI] "
        "| average during training |",
        "|---|---|---|---:|---:|---:|",
    ]
    for record in records:
        comparison = record["comparison"]
        env, results = comparison["env"], comparison["arms"]
        if baseline not in results:
            missing = f"has no arm {baseline!r} to contrast with"
            raise RecordError(f"record {record.get('name')} {missing}")
        base = _numbers(results[baseline]["final_return"]["own"])
        for arm in [baseline, *[arm for arm in arms if arm in results and arm != baseline]]:
            result = results[arm]
            finals = _numbers(result["final_return"]["own"])
            if arm == baseline:
                improvement = "(baseline)"
            else:
                low, high = stats.probability_of_improvement_ci(finals, base)
                p = stats.probability_of_improvement(finals, base)
                improvement = f"{p:.2f} [{low:.2f}, {high:.2f}]"
            mean, se = mean_and_standard_error(finals)
            during, during_se = _numbers(result["average_eval_return_mean_se"])
            lines.append(
                f"| {env} | {arm} | {arm_description(env, result)} | "
                f"{mean:,.1f} ± {se:,.1f} | {improvement} | {during:,.1f} ± {during_se:,.1f} |"
            )
    return "\n".join(lines) + "\n"


def describe(record: dict) -> str:
    comparison = record["comparison"]
    arms = ", ".join(comparison["arms"])
    return (
        f"{record['name']}: compare_settings on {comparison['env']}, {comparison['seeds']} "
        f"seeds x {comparison['iterations']} iterations, arms {arms}; commit "
        f"{str(record['commit'])[:7]}"
    )
