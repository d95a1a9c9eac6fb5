"""Run records: what a results table in the docs rests on, small enough to commit.

A record is a folder (``records/<name>/``) made from a sweep run's folder:

- ``record.json``: the name, the command, the commit, the machine (CPU model, devices,
  library versions, ``XLA_FLAGS``), the run's config (``config.json`` without its
  provenance), how far it got, its training and compile seconds, the digest of the metrics
  file, and each method's normalised returns per seed under both statistics: the headline
  (the mean over the last ``late_share`` of training) and the final evaluation;
- ``metrics.csv.gz``: the run's ``metrics.csv``, every cell and iteration (the evaluations
  and the diagnostics columns), gzipped.

No checkpoints, policies or plots: a 12-cell run of 5,000 iterations is about 2 MB.
``check_record`` reads a record back and verifies it: the metrics file against its digest,
whole against the config (every cell, every iteration the record says the run reached),
and both statistics recomputed from it against those the record states.
"""

from __future__ import annotations

import gzip
import math
import re
import shutil
from pathlib import Path

import numpy as np

from pngail_jax.integrity import IntegrityError, atomic_path, file_digest, read_json, write_json
from pngail_jax.report import LATE_SHARE
from pngail_jax.runs import (
    STATISTICS,
    RunReadError,
    run_progress_numbers,
    run_settings,
    scores_of_metrics,
)

FORMAT = 2  # 2: both statistics per seed (1 held the final evaluation only)
RECORD_FILE = "record.json"
METRICS_FILE = "metrics.csv.gz"
MACHINE_KEYS = (
    "cpu_model", "platform", "device_kind", "device_count", "process_count", "python",
    "libraries", "xla_flags",
)  # fmt: skip


class RecordError(Exception):
    """A run that cannot be recorded, or a record that does not check (the message names the
    file and the problem)."""


def _per_seed(scores: dict[str, np.ndarray]) -> dict[str, list[float | None]]:
    """Per method label, its seeds' scores (None for a diverged seed)."""
    return {
        label: [float(v) if np.isfinite(v) else None for v in values]
        for label, values in scores.items()
    }


def _confidence_errors(summary: dict) -> dict[str, list[float | None]]:
    """Per method label, each seed's confidence MAE on D_u as ``summary.json`` states it
    (None where it has none). The classifier is trained before the grid, so its error is
    not in metrics.csv: a record keeps it as the run stated it."""
    return {
        label: [
            seed.get("confidence_mae") for seed in sorted(row["per_seed"], key=lambda s: s["seed"])
        ]
        for label, row in summary.get("methods", {}).items()
        if row.get("per_seed")
    }


def _training_seconds(metrics_path: Path) -> float | None:
    """The run's training seconds so far: the largest ``wall_seconds`` of its metrics file."""
    from pngail_jax.report import metrics_rows

    rows = metrics_rows(metrics_path)
    seconds = [float(row["wall_seconds"]) for row in rows if row.get("wall_seconds")]
    return max(seconds) if seconds else None


def write_record(
    run_dir: Path, name: str, records: Path = Path("records"), *, allow_unsealed: bool = False
) -> Path:
    """Records the sweep or offline run in ``run_dir`` as ``records/<name>/`` and checks it,
    once ``runs.verify_run`` trusts the run (its seal, unless ``allow_unsealed``; metrics.csv
    whole and agreeing with summary.json; its input files are not looked at). A record of
    that name already there is replaced only if it records the same run (same config and
    commit); anything else in the way is refused. Returns the record's folder."""
    from pngail_jax.outputs import output_owner
    from pngail_jax.runs import run_scores, verify_run

    run_dir = Path(run_dir)
    check_name(name)
    try:  # verify_run refuses a folder of neither program
        for note in verify_run(run_dir, str(run_dir), allow_unsealed=allow_unsealed,
                               check_inputs=False):  # fmt: skip
            print(f"note: {note}")
        config = read_json(run_dir / "config.json", "run config")
        summary = read_json(run_dir / "summary.json", "run summary")
        scores = {name: run_scores(run_dir, name)[1] for name in STATISTICS}
    except FileNotFoundError as error:
        raise RecordError(f"{run_dir}: {Path(error.filename).name} is missing") from None
    except (OSError, IntegrityError, RunReadError) as error:
        raise RecordError(str(error)) from None
    provenance = config.get("provenance", {})
    progress = run_progress_numbers(run_dir)
    record = {
        "format": FORMAT,
        "name": name,
        "program": f"experiments.{output_owner(run_dir)}",
        "command": provenance.get("command_line"),
        "commit": provenance.get("git_commit"),
        "machine": {key: provenance.get(key) for key in MACHINE_KEYS},
        "config": {key: value for key, value in config.items() if key != "provenance"},
        "complete": summary.get("complete") is not False,
        "iterations_done": progress[0] if progress else None,
        "iterations": progress[1] if progress else run_settings(config).get("iterations"),
        "training_seconds": _training_seconds(run_dir / "metrics.csv"),
        "compile_seconds": summary.get("compile_seconds"),
        "late_share": LATE_SHARE,
        **{_key(name): _per_seed(values) for name, values in scores.items()},
        "confidence_mae": _confidence_errors(summary),
    }
    folder = Path(records) / name
    _check_replaceable(folder, record)
    folder.mkdir(parents=True, exist_ok=True)
    metrics = folder / METRICS_FILE
    # No file name and no time in the gzip header: the same run gives the same bytes.
    with atomic_path(metrics) as temporary, temporary.open("wb") as raw:
        with (run_dir / "metrics.csv").open("rb") as source:
            with gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as target:
                shutil.copyfileobj(source, target)
    record["metrics"] = {"file": METRICS_FILE, "bytes": metrics.stat().st_size,
                         "sha256": file_digest(metrics)}  # fmt: skip
    write_json(folder / RECORD_FILE, record)
    check_record(folder)
    return folder


def check_name(name: str) -> None:
    """RecordError unless ``name`` is a plain folder name a docs marker can name."""
    if not name or not re.fullmatch(r"[\w.-]+", name) or name.startswith("."):
        raise RecordError(f"record name {name!r}: give a plain folder name, e.g. hopper-cpu")


def _check_replaceable(folder: Path, record: dict) -> None:
    """RecordError unless ``folder`` is new, empty, or a record of the same run."""
    if not folder.exists():
        return
    if not folder.is_dir():
        raise RecordError(f"{folder} is a file: give another --name")
    found = {path.name for path in folder.iterdir()}
    if not found:
        return
    if not found <= {RECORD_FILE, METRICS_FILE}:
        strangers = ", ".join(sorted(found - {RECORD_FILE, METRICS_FILE}))
        raise RecordError(f"{folder} holds files a record does not ({strangers}): not replaced")
    try:
        old = read_json(folder / RECORD_FILE, "run record")
    except (OSError, IntegrityError) as error:
        raise RecordError(
            f"{folder}: not replaced, its record.json is unreadable ({error})"
        ) from None
    if old.get("config") != record["config"] or old.get("commit") != record["commit"]:
        raise RecordError(
            f"{folder} records another run (its config or commit differs): give another --name"
        )


def check_record(folder: Path) -> dict:
    """Verifies the record in ``folder`` and returns its ``record.json``: the metrics file is
    the one recorded (size and SHA-256), whole (every cell of the config, to the iteration the
    record says), and gives both statistics the record states. RecordError otherwise."""
    folder = Path(folder)
    try:
        record = read_json(folder / RECORD_FILE, "run record")
    except FileNotFoundError:
        raise RecordError(f"{folder} holds no run record ({RECORD_FILE} is missing)") from None
    except (OSError, IntegrityError) as error:
        raise RecordError(f"{folder / RECORD_FILE}: unreadable ({error})") from None
    if not isinstance(record, dict) or record.get("format") != FORMAT:
        raise RecordError(f"{folder / RECORD_FILE}: not a run record of format {FORMAT}")
    metrics = folder / METRICS_FILE
    expected = record.get("metrics", {})
    if not metrics.is_file():
        raise RecordError(f"{metrics} is missing")
    if metrics.stat().st_size != expected.get("bytes") or file_digest(metrics) != expected.get(
        "sha256"
    ):
        raise RecordError(f"{metrics} differs from what the record wrote (size or SHA-256)")
    done, planned = record.get("iterations_done"), record.get("iterations")
    progress = (done, planned) if isinstance(done, int) and isinstance(planned, int) else None
    if record.get("late_share") != LATE_SHARE:
        raise RecordError(
            f"{folder / RECORD_FILE}: its late average is over the last "
            f"{record.get('late_share')} of training, this version's over {LATE_SHARE}: "
            "record the run again"
        )
    for name in STATISTICS:
        try:
            scores = scores_of_metrics(metrics, run_settings(record["config"]), progress, name)
        except RunReadError as error:
            raise RecordError(str(error)) from None
        if _per_seed(scores) != record.get(_key(name)):
            raise RecordError(
                f"{folder / RECORD_FILE}: its {_key(name)} differs from that of {METRICS_FILE}"
            )
    _check_confidence_errors(folder, record)
    return record


def _check_confidence_errors(folder: Path, record: dict) -> None:
    """RecordError unless the record's ``confidence_mae`` (where it has one) holds, for
    methods of the record, one number (or None) per seed."""
    errors = record.get("confidence_mae")
    if errors is None:
        return
    seeds = record[_key("final")]
    if not isinstance(errors, dict) or any(
        label not in seeds
        or not isinstance(values, list)
        or len(values) != len(seeds[label])
        or not all(v is None or isinstance(v, (int, float)) for v in values)
        for label, values in errors.items()
    ):
        raise RecordError(
            f"{folder / RECORD_FILE}: its confidence_mae is not one number per seed of its methods"
        )


def _key(statistic: str) -> str:
    """record.json's key of a statistic's per-seed scores."""
    return f"{statistic}_normalized_return"


def describe(record: dict) -> str:
    """One paragraph for the terminal: what the record holds."""
    finals = record[_key("final")]
    cells = sum(len(values) for values in finals.values())
    how_far = (
        "complete"
        if record["complete"]
        else f"{record['iterations_done']:,} of {record['iterations']:,} iterations"
    )
    return (
        f"{record['name']}: {run_settings(record['config']).get('env')}, {len(finals)} methods, "
        f"{cells} runs, {how_far}; commit {str(record['commit'])[:10]}, "
        f"{record['machine'].get('cpu_model') or 'CPU not recorded'}; "
        f"metrics {record['metrics']['bytes']:,} bytes"
    )


# Keys of a run config that do not change its numbers (or say where its files were).
_NOT_NUMBERS = ("demos", "conf", "resolved", "log", "chunk_iterations", "cpu_devices",
                "preset_name", "provenance")  # fmt: skip


def config_differences(config: dict, record: dict) -> list[str]:
    """The config fields (``config.json``'s top level) in which a run differs from the
    record's run, leaving out those that do not change the numbers."""
    from pngail_jax.run_config import RunConfig

    reference = record["config"]
    keys = sorted((set(config) | set(reference)) - set(_NOT_NUMBERS))
    # A field one side lacks (a record from before the field existed) has its default.
    defaults = RunConfig().to_dict()

    def value(document: dict, key: str):
        return document[key] if key in document else defaults.get(key)

    return [key for key in keys if value(config, key) != value(reference, key)]


def expected_rows(scores, record: dict) -> list[dict]:
    """Per method of the record: is the IQM of your seeds' scores (``scores``, a
    ``compare.Scores``, under its statistic) inside the record's 95% bootstrap interval of its
    IQM over seeds under the same statistic, and by how much is it outside. RecordError when
    your runs hold no run of the record's task."""
    from pngail_jax import stats

    task = run_settings(record["config"]).get("env")
    if task not in scores.tasks:
        raise RecordError(
            f"the record {record['name']} is of {task}; your runs are of {', '.join(scores.tasks)}"
        )
    rows = []
    for method, seeds in record[_key(scores.statistic)].items():
        reference = stats.seed_summary([math.nan if v is None else v for v in seeds])
        row = {
            "method": method,
            "reference_iqm": reference["iqm"],
            "reference_ci95": reference["ci95"],
            "reference_seeds": reference["num_seeds"],
        }
        yours = scores.values.get(method, {}).get(task)
        if yours is None:
            rows.append({**row, "verdict": "not in your runs"})
            continue
        mine = stats.seed_summary(yours)
        low, high = reference["ci95"]
        estimate = mine["iqm"]
        spread = rerun_spread(seeds, mine["num_seeds"])
        row["rerun_spread"] = spread
        row["within_rerun_spread"] = bool(abs(estimate - reference["iqm"]) <= spread)
        if not math.isfinite(estimate):
            verdict, distance = "no finite return", math.nan
        elif low <= estimate <= high:
            verdict, distance = "within", 0.0
        elif estimate < low:
            verdict, distance = "below", low - estimate
        else:
            verdict, distance = "above", estimate - high
        rows.append({**row, "your_iqm": estimate, "your_seeds": mine["num_seeds"],
                     "verdict": verdict, "outside_by": distance})  # fmt: skip
    return rows


def rerun_spread(seeds, num_seeds: int, num_draws: int = 2000) -> float:
    """How far the IQM of a re-run of ``num_seeds`` seeds lands from the record's IQM, as a
    re-run shows it: the 95th percentile of |IQM(a draw of ``num_seeds`` of the record's seeds,
    without replacement) - IQM(all of them)| over ``num_draws`` draws (a fixed seed). NaN when
    the record has no more seeds than the re-run (then no draw differs from it)."""
    from pngail_jax import stats

    values = np.asarray([v for v in seeds if v is not None and math.isfinite(v)], float)
    if num_seeds < 1 or values.size <= num_seeds:
        return math.nan
    rng = np.random.default_rng(0)
    whole = stats.iqm(values)
    shifts = [
        abs(stats.iqm(rng.choice(values, num_seeds, replace=False)) - whole)
        for _ in range(num_draws)
    ]
    return float(np.percentile(shifts, 95))


def expected_markdown(
    rows: list[dict], record: dict, differences: list[str], statistic: str
) -> str:
    """The ``--expected`` table: your IQM against the record's interval, per method, both
    under ``statistic`` (a key of ``compare.STATISTICS``)."""

    lines = [
        f"## Against the record {record['name']} "
        f"({run_settings(record['config']).get('env')}, commit {str(record['commit'])[:10]})",
        "",
        f"Score: {STATISTICS[statistic]}. The IQM of your seeds against the record's IQM and "
        "its 95% bootstrap interval over its seeds. Outside it is a difference to look at, not "
        "proof of one: a run on another machine is another draw (docs/sweep.md, what is "
        "reproducible).",
        "",
    ]
    if differences:
        lines += [f"Your config differs from the record's in: {', '.join(differences)}.", ""]
    lines += ["| method | yours (IQM, seeds) | record: IQM [95% CI] (seeds) | verdict |",
              "|---|---:|---:|---|"]  # fmt: skip
    for row in rows:
        low, high = row["reference_ci95"]
        reference = f"{row['reference_iqm']:.2f} [{low:.2f}, {high:.2f}] ({row['reference_seeds']})"
        if "your_iqm" not in row:
            lines.append(f"| {row['method']} | - | {reference} | {row['verdict']} |")
            continue
        verdict = row["verdict"] + (
            f" by {row['outside_by']:.2f}" if row["verdict"] in ("below", "above") else ""
        )
        if math.isfinite(row["rerun_spread"]):
            side = "within" if row["within_rerun_spread"] else "beyond"
            verdict += (
                f"; {side} the spread a re-run of {row['your_seeds']} seeds shows "
                f"(+-{row['rerun_spread']:.2f}, from the record's seeds)"
            )
        lines.append(
            f"| {row['method']} | {row['your_iqm']:.2f} ({row['your_seeds']}) | {reference} | "
            f"{verdict} |"
        )
    return "\n".join(lines) + "\n"


def _seed_values(seeds: list[float | None]) -> np.ndarray:
    """A record's per-seed list as float[seeds], NaN for a seed without a score."""
    return np.asarray([math.nan if v is None else v for v in seeds], float)


def record_table(record: dict, baseline: str | None = None) -> str:
    """A results table made from a checked record (``check_record``'s dictionary): per
    method, the headline (the normalised return over the last ``late_share`` of training)
    and the final evaluation, each as mean ± s.e. and IQM [95% bootstrap CI] over seeds, and
    under both the probability of improvement (an interval holding 0.5 says so): PN-GAIL's
    over each method when the record has PN-GAIL, or with ``baseline`` each method's over it.
    The docs' tables between ``<!-- record-table NAME [baseline=METHOD] -->`` markers are
    this text, and a test keeps them so (``experiments.record --docs`` rewrites them)."""
    from pngail_jax import stats
    from pngail_jax.methods import display_name

    late, final = record[_key("late_average")], record[_key("final")]
    share = f"last {record['late_share']:.0%} of training"
    anchor = baseline or "pngail"
    if baseline is not None and baseline not in late:
        raise RecordError(f"record {record['name']} has no method {baseline!r}: {list(late)}")

    def summary(seeds) -> tuple[str, str]:
        row = stats.seed_summary(_seed_values(seeds))
        low, high = row["ci95"]
        return f"{row['mean']:.2f} ± {row['se']:.2f}", f"{row['iqm']:.2f} [{low:.2f}, {high:.2f}]"

    def improvement(statistic, method) -> str:
        ours, theirs = _seed_values(statistic[anchor]), _seed_values(statistic[method])
        if baseline is not None:
            ours, theirs = theirs, ours
        low, high = stats.probability_of_improvement_ci(ours, theirs)
        holds = ", holds 0.5" if low <= 0.5 <= high else ""
        return (
            f"{stats.probability_of_improvement(ours, theirs):.2f} [{low:.2f}, {high:.2f}]{holds}"
        )

    compared = anchor in late
    pair = f"method > {display_name(baseline)}" if baseline else f"{display_name(anchor)} > method"
    lines = [
        f"| method | seeds | {share}: mean ± s.e. | {share}: IQM [95% CI] | final: mean ± s.e. "
        "| final: IQM [95% CI] |" + (f" P({pair}), {share} | P, final |" if compared else ""),
        "|---|---:|---:|---:|---:|---:|" + ("---:|---:|" if compared else ""),
    ]
    for method in late:
        seeds = int(np.isfinite(_seed_values(late[method])).sum())
        cells = [display_name(method), str(seeds), *summary(late[method]), *summary(final[method])]
        if compared:
            cells += (
                ["-", "-"]
                if method == anchor
                else [improvement(late, method), improvement(final, method)]
            )
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def glance_table(records: list[dict], statistic: str = "late_average") -> str:
    """Several checked records in one table: a row per task (the records of one task
    joined, each method from one record only), a column per method in the order met, each
    cell the mean ± s.e. over seeds of ``statistic``'s normalised return ("-": not run).
    The docs' tables between ``<!-- record-glance NAME NAME ... -->`` markers are this text
    (``experiments.record --docs``)."""
    from pngail_jax import stats
    from pngail_jax.methods import display_name

    rows: dict[str, dict[str, np.ndarray]] = {}
    for record in records:
        env = str(run_settings(record["config"]).get("env"))
        task = rows.setdefault(env, {})
        for method, seeds in record[_key(statistic)].items():
            if method in task:
                raise RecordError(
                    f"record {record['name']}: {method!r} on {env} is in another record of "
                    "the table too"
                )
            task[method] = _seed_values(seeds)
    methods = list(dict.fromkeys(method for task in rows.values() for method in task))
    lines = [
        "| task (seeds) | " + " | ".join(display_name(method) for method in methods) + " |",
        "|---|" + "---:|" * len(methods),
    ]
    for env, task in rows.items():
        counts = sorted({int(np.isfinite(seeds).sum()) for seeds in task.values()})
        cells = []
        for method in methods:
            row = stats.seed_summary(task[method]) if method in task else None
            cells.append("-" if row is None else f"{row['mean']:.2f} ± {row['se']:.2f}")
        seeds = "/".join(map(str, counts))
        lines.append(f"| {env} ({seeds}) | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _mean_se(values: np.ndarray) -> str:
    """ "mean ± s.e." of ``values`` (s.e. with ddof 1; "-" for none)."""
    if values.size == 0:
        return "-"
    se = values.std(ddof=1) / math.sqrt(values.size) if values.size > 1 else math.nan
    return f"{values.mean():.2f} ± {se:.2f}"


def _block_label(block: int, block_steps: int, last_step: int) -> str:
    """A block's span in M steps, its end at most the run's last step."""
    low, high = block * block_steps, min((block + 1) * block_steps, last_step)
    return f"{low / 1e6:g}-{high / 1e6:g}"


def _blocks_of(record: dict, steps, block_steps: int) -> np.ndarray:
    """The block of each environment step count (step s in block ceil(s / block_steps) - 1);
    RecordError for a block of no steps or a run without environment steps (offline)."""
    steps = np.asarray(steps)
    if block_steps < 1:
        raise RecordError(f"record {record['name']}: a block of {block_steps} steps")
    if steps.size == 0 or steps.max() < 1:
        raise RecordError(f"record {record['name']}: no environment steps to cut into blocks")
    return (steps - 1) // block_steps


def block_table(record: dict, folder: Path, block_steps: int) -> str:
    """How a recorded run learned, per block of ``block_steps`` environment steps per run:
    per method, each seed's mean normalised evaluation in the block (an evaluation at step s
    is in block ceil(s / block_steps)), then mean ± s.e. over seeds; the last column the final
    evaluation. A seed without a final evaluation (diverged) is left out of every column, as
    from the record's headline. ``folder`` holds the checked ``record``. The docs' tables
    between ``<!-- record-blocks NAME block=STEPS -->`` markers are this text."""
    from pngail_jax.methods import display_name
    from pngail_jax.report import read_evaluations

    groups = read_evaluations(
        Path(folder) / METRICS_FILE, "normalized_return", evaluated_by="eval_return",
        group_by=("method", "setting"),
    )  # fmt: skip
    if not groups:
        raise RecordError(f"record {record['name']}: no evaluated iteration")
    settings = {setting for _, setting in groups}
    last = max(int(steps[-1]) for steps, _ in groups.values())
    order = sorted(
        {int(b) for steps, _ in groups.values() for b in _blocks_of(record, steps, block_steps)}
    )
    lines = [
        "| M steps | "
        + " | ".join(_block_label(b, block_steps, last) for b in order)
        + f" | final ({last / 1e6:g} M) |",
        "|---|" + "---:|" * (len(order) + 1),
    ]
    for (method, setting), (steps, values) in groups.items():
        name = display_name(method) + ("" if len(settings) == 1 else f" [{setting}]")
        values = values[np.isfinite(values[:, -1])] if int(steps[-1]) == last else values[:0]
        blocks = _blocks_of(record, steps, block_steps)
        with np.errstate(all="ignore"):
            cells = [_mean_se(np.nanmean(values[:, blocks == b], axis=1)) if (blocks == b).any()
                     else "-" for b in order]  # fmt: skip
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {_mean_se(values[:, -1])} |")
    return "\n".join(lines) + "\n"


def _check_methods(record: dict, known, methods: list[str] | None) -> None:
    """RecordError naming the first of ``methods`` that is not among ``known``."""
    known = list(dict.fromkeys(known))
    unknown = sorted(set(methods or ()) - set(known))
    if unknown:
        raise RecordError(f"record {record['name']} has no method {unknown[0]!r}: {known}")


# A recorded run's diagnostics columns as ``diagnostics_table`` names them.
DIAGNOSTICS = {
    "disc_acc_agent": ("D accuracy on agent rows", "{:.3f}"),
    "disc_acc_demo": ("D accuracy on demonstration rows", "{:.2f}"),
    "mean_reward": ("mean reward", "{:.3f}"),
    "train_return": ("training return", "{:,.0f}"),
    "beyond_bounds": ("action entries beyond the bounds", "{:.2f}"),
}


def diagnostics_table(
    record: dict, folder: Path, block_steps: int, methods: list[str] | None = None
) -> str:
    """The discriminator and policy diagnostics of a recorded run per block of
    ``block_steps`` environment steps per run: a row per method (``methods``, default all;
    per setting where the run has several) and column of ``DIAGNOSTICS``, each cell the mean
    over every (iteration, seed) row of the block, all seeds pooled. The docs' tables between
    ``<!-- record-diagnostics NAME block=STEPS [methods=A,B] -->`` markers are this text."""
    from pngail_jax.methods import display_name
    from pngail_jax.report import metrics_rows

    rows = list(metrics_rows(Path(folder) / METRICS_FILE))
    _check_methods(record, [row["method"] for row in rows], methods)
    rows = [row for row in rows if methods is None or row["method"] in methods]
    steps = [int(row["env_steps"]) for row in rows]
    blocks = _blocks_of(record, steps, block_steps)
    settings = {row.get("setting") for row in rows}
    sums: dict[tuple[str, str, str], dict[int, list[float]]] = {}
    for row, block in zip(rows, blocks, strict=True):
        for column in DIAGNOSTICS:
            if row.get(column) not in (None, "", "nan"):
                key = (row["method"], row.get("setting"), column)
                sums.setdefault(key, {}).setdefault(int(block), []).append(float(row[column]))
    order = sorted({int(b) for b in blocks})
    lines = [
        "| M steps | " + " | ".join(_block_label(b, block_steps, max(steps)) for b in order) + " |",
        "|---|" + "---:|" * len(order),
    ]
    for (method, setting, column), values in sums.items():
        title, form = DIAGNOSTICS[column]
        name = display_name(method) + ("" if len(settings) == 1 else f" [{setting}]")
        cells = [form.format(np.mean(values[b])) if b in values else "-" for b in order]
        lines.append(f"| {name}: {title} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _turn(steps: np.ndarray, values: np.ndarray, level: float) -> str:
    """The M steps of the first of three evaluations in a row above ``level``, or "never"."""
    above = values > level
    for first in range(len(values) - 2):
        if above[first : first + 3].all():
            return f"{steps[first] / 1e6:g}"
    return "never"


def seed_table(record: dict, folder: Path, turn: float, methods: list[str] | None = None) -> str:
    """Each seed of a recorded run, a row per (method, seed) (``methods``, default all):
    its final and late-average normalised return (the record's), its lowest evaluation and
    where, where it turned (the first of three evaluations in a row above ``turn``), and its
    confidence classifier's MAE on D_u (the record's ``confidence_mae``, for methods whose
    loss reads confidences). ``folder`` holds the checked ``record``. The docs' tables between
    ``<!-- record-seeds NAME turn=LEVEL [methods=A,B] -->`` markers are this text."""
    from pngail_jax.methods import reads_confidences
    from pngail_jax.report import LATE_LABEL, display_label, read_evaluations

    groups = read_evaluations(
        Path(folder) / METRICS_FILE, "normalized_return", evaluated_by="eval_return",
        group_by=("method", "setting"),
    )  # fmt: skip
    _check_methods(record, [method for method, _ in groups], methods)
    settings = {setting for _, setting in groups}
    lines = [
        f"| method | seed | final | {LATE_LABEL} | lowest evaluation (at M steps) | "
        f"turned above {turn:g} (M steps) | confidence MAE on D_u |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for (method, setting), (steps, values) in groups.items():
        if methods is not None and method not in methods:
            continue
        label = method if len(settings) == 1 else f"{method} [{setting}]"
        errors = (record.get("confidence_mae") or {}).get(label)
        for seed, row in enumerate(values):
            final, late = (record[_key(name)][label][seed] for name in ("final", "late_average"))
            low = int(np.nanargmin(row)) if np.isfinite(row).any() else None
            lowest = "-" if low is None else f"{row[low]:.2f} ({steps[low] / 1e6:g})"
            if not reads_confidences(method):
                error = "reads none"
            elif errors is None or errors[seed] is None:
                error = "not recorded"
            else:
                error = f"{errors[seed]:.3f}"
            cells = [display_label(label), str(seed),
                     "diverged" if final is None else f"{final:.2f}",
                     "diverged" if late is None else f"{late:.2f}", lowest,
                     _turn(steps, row, turn), error]  # fmt: skip
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
