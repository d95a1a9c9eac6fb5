"""One figure across recorded ``compare_settings`` comparisons: a panel per comparison (task),
the chosen arms' evaluation returns during training (mean ± s.e. over seeds), from the
committed records (each checked first). The figure beside a ``record-contrast`` table.

    python tools/contrast_figure.py records/settings-hopper-v4-solver \\
        records/settings-swimmer-v4-solver --arms reference,reference-fast --out fig.png
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pngail_jax.analysis.run_records import RecordError  # noqa: E402
from pngail_jax.jobs import comparison_record  # noqa: E402
from pngail_jax.jobs.compare_settings import arm_description, draw_curve  # noqa: E402


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("records", nargs="+", type=Path, help="comparison records' folders")
    parser.add_argument("--arms", required=True, help="comma-separated arms, in legend order")
    parser.add_argument("--out", required=True, type=Path, help="the figure (.png)")
    return parser.parse_args(argv)


def draw(records: list[dict], arms: list[str], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = min(len(records), 3)
    rows = math.ceil(len(records) / columns)
    figure, axes = plt.subplots(rows, columns, figsize=(4.6 * columns, 3.6 * rows), squeeze=False)
    colors = dict(zip(arms, plt.rcParams["axes.prop_cycle"].by_key()["color"], strict=False))
    for axis, record in zip(axes.flat, records, strict=False):
        comparison = record["comparison"]
        for arm in [arm for arm in arms if arm in comparison["arms"]]:
            curve = comparison["curves"][arm]
            steps = np.asarray(curve["env_steps"]) / 1e6
            label = f"{arm} ({arm_description(comparison['env'], comparison['arms'][arm])})"
            # one colour per arm in every panel
            draw_curve(axis, steps, curve["eval_return"], label, colors.get(arm), alpha=0.2)
        axis.set(title=comparison["env"], xlabel="environment steps per run (M)",
                 ylabel="evaluation return")  # fmt: skip
        axis.grid(alpha=0.3)
        axis.legend(fontsize=6.5)
    for axis in list(axes.flat)[len(records) :]:
        axis.set_visible(False)
    figure.suptitle(f"TRPO on the true reward, {records[0]['comparison']['seeds']} seeds each")
    figure.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=110)
    plt.close(figure)


def main(argv=None) -> Path:
    args = parse_args(argv)
    try:
        records = [comparison_record.check(folder) for folder in args.records]
    except RecordError as error:
        raise SystemExit(str(error)) from None
    draw(records, args.arms.split(","), args.out)
    print(f"wrote {args.out}")
    return args.out


if __name__ == "__main__":
    main()
