"""Experiment tracking: the TensorBoard event file read back, group means worked by hand.

The grid is 2 methods x 2 seeds, two chunks of 4 iterations (evaluations every 2nd). All
values are small dyadic numbers, so the float32 scalars in the event file are exact.
"""

import struct
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from tensorboardX.proto.event_pb2 import Event

from pngail_jax.analysis.tracking import chunk_scalars, open_logger
from pngail_jax.grid import make_cells

NAN = np.nan
CELLS = make_cells(["gail", "pngail"], num_seeds=2)  # gail s0, gail s1, pngail s0, pngail s1


def chunk_metrics(offset: float) -> dict[str, np.ndarray]:
    """float[4 cells, 4 iterations]; ``offset`` is added to the evaluation returns."""
    eval_return = np.array(
        [[NAN, 10, NAN, 20], [NAN, 14, NAN, 30], [NAN, -1, NAN, 2], [NAN, -3, NAN, 4]]
    )
    disc_loss = np.array(
        [[1, 2, NAN, 4], [3, NAN, NAN, 8], [0.5, 0.5, 0.5, 0.5], [1.5, 1.5, 1.5, 1.5]]
    )
    return {
        "eval/return": eval_return + offset,
        "disc/loss": disc_loss,
        "train/episode_return": np.full((4, 4), NAN),  # never finite: never logged
    }


def expected_scalars(first_iteration: int, offset: float) -> dict[str, dict[int, float]]:
    """Tag -> {step: value} of one chunk, by hand."""

    def at(values: dict[int, float]) -> dict[int, float]:
        return {first_iteration + column: value for column, value in values.items()}

    return {
        # gail at column 1: (10 + 14) / 2 = 12; column 3: (20 + 30) / 2 = 25.
        "eval/return/gail": at({1: 12 + offset, 3: 25 + offset}),
        # pngail: (-1 - 3) / 2 = -2; (2 + 4) / 2 = 3.
        "eval/return/pngail": at({1: -2 + offset, 3: 3 + offset}),
        "eval/return/gail/seed0": at({1: 10 + offset, 3: 20 + offset}),
        "eval/return/gail/seed1": at({1: 14 + offset, 3: 30 + offset}),
        "eval/return/pngail/seed0": at({1: -1 + offset, 3: 2 + offset}),
        "eval/return/pngail/seed1": at({1: -3 + offset, 3: 4 + offset}),
        # gail: (1 + 3) / 2 = 2; seed 1 is NaN at column 1 so 2 alone; column 2 all NaN
        # (absent); (4 + 8) / 2 = 6.
        "disc/loss/gail": at({0: 2, 1: 2, 3: 6}),
        # pngail: (0.5 + 1.5) / 2 = 1 at every column.
        "disc/loss/pngail": at({0: 1, 1: 1, 2: 1, 3: 1}),
    }


def read_events(directory: Path) -> list[Event]:
    """The events of TFRecord-framed event files: per record an 8-byte little-endian length,
    its 4-byte CRC, the payload, the payload's 4-byte CRC."""
    events = []
    for path in sorted(directory.glob("events.out.tfevents.*")):
        data = path.read_bytes()
        offset = 0
        while offset < len(data):
            (length,) = struct.unpack_from("<Q", data, offset)
            events.append(Event.FromString(data[offset + 12 : offset + 12 + length]))
            offset += 12 + length + 4
    return events


def read_scalars(directory: Path) -> dict[str, list[tuple[int, float]]]:
    """Tag -> [(step, value), ...] of every scalar in the directory's event files."""
    scalars: dict[str, list[tuple[int, float]]] = {}
    for event in read_events(directory):
        for value in event.summary.value:
            if value.HasField("simple_value"):
                scalars.setdefault(value.tag, []).append((event.step, value.simple_value))
    return scalars


def merged(*chunks: dict[str, dict[int, float]]) -> dict[str, list[tuple[int, float]]]:
    tags = dict.fromkeys(tag for chunk in chunks for tag in chunk)
    return {tag: sorted(p for c in chunks for p in c.get(tag, {}).items()) for tag in tags}


def test_tensorboard_event_file_holds_group_means(tmp_path):
    config = {"env": "Pendulum-v1", "methods": ["gail", "pngail"]}
    with open_logger(tmp_path, ["tensorboard"], config, "test-run") as logger:
        logger.log_chunk(CELLS, chunk_metrics(0.0), first_iteration=1)
        # Flushed after each chunk: readable before close.
        first = expected_scalars(1, 0.0)
        assert read_scalars(tmp_path / "tensorboard") == merged(first)
        logger.log_chunk(CELLS, chunk_metrics(100.0), first_iteration=5)
    scalars = read_scalars(tmp_path / "tensorboard")
    assert scalars == merged(first, expected_scalars(5, 100.0))
    assert sorted(scalars["eval/return/gail"]) == [(2, 12), (4, 25), (6, 112), (8, 125)]
    assert not any(tag.startswith("train/episode_return") for tag in scalars)
    texts = [
        value.tensor.string_val[0].decode()
        for event in read_events(tmp_path / "tensorboard")
        for value in event.summary.value
        if value.tag == "config/text_summary"
    ]
    assert len(texts) == 1 and '"env": "Pendulum-v1"' in texts[0]
    logger.close()  # closing twice is harmless


class FakeWandb(types.ModuleType):
    """Records ``wandb.init`` keywords and each ``run.log(values, step=...)``."""

    def __init__(self):
        super().__init__("wandb")
        self.init_kwargs, self.logged, self.finished = None, [], False

    def init(self, **kwargs):
        self.init_kwargs = kwargs
        return self

    def log(self, values, step):
        self.logged.append((step, dict(values)))

    def finish(self):
        self.finished = True


def test_wandb_logs_each_step_once_in_order(tmp_path, monkeypatch):
    wandb = FakeWandb()
    monkeypatch.setitem(sys.modules, "wandb", wandb)
    with open_logger(tmp_path, ["wandb"], {"seeds": 2}, "run-1") as logger:
        logger.log_chunk(CELLS, chunk_metrics(0.0), first_iteration=1)
    assert wandb.init_kwargs == {
        "project": "pngail-jax",
        "name": "run-1",
        "config": {"seeds": 2},
        "dir": str(tmp_path),
    }
    assert [step for step, _ in wandb.logged] == [1, 2, 3, 4]
    assert wandb.logged[1][1]["eval/return/gail"] == 12
    assert wandb.finished


def test_groups_carry_the_setting_when_the_grid_has_several():
    cells = make_cells(["gail"], num_seeds=1, label_ratios=(0.2, 0.5))
    scalars = chunk_scalars(cells, {"eval/return": np.array([[1.0], [3.0]])}, first_iteration=7)
    assert scalars == {
        7: {
            "eval/return/gail_label_ratio_0.2_noise_0": 1.0,
            "eval/return/gail_label_ratio_0.2_noise_0/seed0": 1.0,
            "eval/return/gail_label_ratio_0.5_noise_0": 3.0,
            "eval/return/gail_label_ratio_0.5_noise_0/seed0": 3.0,
        }
    }


def test_no_backend_means_no_logger(tmp_path):
    assert open_logger(tmp_path, [], {}, "run") is None
    assert not any(tmp_path.iterdir())


def test_unknown_backend_is_named_with_the_choices(tmp_path):
    with pytest.raises(ValueError, match=r"mlflow.*tensorboard.*wandb"):
        open_logger(tmp_path, ["tensorboard", "mlflow"], {}, "run")
    assert not any(tmp_path.iterdir())


def test_wandb_missing_says_how_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "wandb", None)  # makes `import wandb` fail
    with pytest.raises(ImportError, match="pip install wandb"):
        open_logger(tmp_path, ["tensorboard", "wandb"], {}, "run")
    assert not any(tmp_path.iterdir())
