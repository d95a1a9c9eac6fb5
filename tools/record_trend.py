"""Is a recorded run still learning at its end? Each method's normalised return over the last
three windows of its training, from a committed record, and the change over the last window
with its standard error over seeds.

    python tools/record_trend.py records/offline-ant records/offline-halfcheetah
    python tools/record_trend.py records/offline-ant --windows 5

A window is a share of the run's evaluated iterations (the last ``1 / windows`` of them, the
one before, ...); a seed's value in a window is the mean of its evaluations there. A change
within two standard errors of 0 says the curve is flat at the end: more training of the
same kind is unlikely to move the result much. The record is checked first
(``run_records.check_record``: its metrics against their digest).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pngail_jax.adversarial.methods import display_name  # noqa: E402
from pngail_jax.analysis import run_records  # noqa: E402
from pngail_jax.analysis.report import metrics_rows  # noqa: E402


def evaluations(folder: Path) -> dict[str, dict[int, list[tuple[int, float]]]]:
    """method -> seed -> [(iteration, normalised return)] of a checked record."""
    run_records.check_record(folder)
    found: dict[str, dict[int, list]] = {}
    for row in metrics_rows(folder / run_records.METRICS_FILE):
        if row.get("normalized_return"):
            seeds = found.setdefault(row["method"], {})
            seeds.setdefault(int(row["seed"]), []).append(
                (int(row["iteration"]), float(row["normalized_return"]))
            )
    return found


def trend_rows(folder: Path, windows: int = 5) -> list[dict]:
    """Per method: the mean over seeds of the last three windows and the last window's
    change (mean and standard error over seeds)."""
    rows = []
    for method, seeds in evaluations(folder).items():
        last = max(iteration for points in seeds.values() for iteration, _ in points)
        edges = [last * k / windows for k in range(windows - 3, windows + 1)]

        means = [
            np.array(
                [np.mean([v for i, v in points if low < i <= high]) for points in seeds.values()]
            )  # fmt: skip
            for low, high in zip(edges, edges[1:], strict=False)
        ]
        change = means[-1] - means[-2]
        se = change.std(ddof=1) / np.sqrt(len(change)) if len(change) > 1 else float("nan")
        rows.append({"method": method, "windows": [float(m.mean()) for m in means],
                     "change": float(change.mean()), "change_se": float(se)})  # fmt: skip
    return rows


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("records", nargs="+", type=Path)
    parser.add_argument("--windows", type=int, default=5, help="windows per run (default 5)")
    args = parser.parse_args(argv)
    if args.windows < 3:
        parser.error(f"--windows must be at least 3, got {args.windows}")
    print("| record | method | third-last window | second-last | last | last change ± s.e. |")
    print("|---|---|---:|---:|---:|---:|")
    found = []
    for folder in args.records:
        try:
            rows = trend_rows(folder, args.windows)
        except run_records.RecordError as error:
            raise SystemExit(str(error)) from None
        for row in rows:
            values = " | ".join(f"{v:.2f}" for v in row["windows"])
            print(f"| {folder.name} | {display_name(row['method'])} | {values} | "
                  f"{row['change']:+.3f} ± {row['change_se']:.3f} |")  # fmt: skip
        found += [{"record": folder.name, **row} for row in rows]
    return found


if __name__ == "__main__":
    main()
