"""RunConfig: validation naming the field, JSON round trips, presets, old config.json files."""

import dataclasses
import json

import pytest

from pngail_jax.run_config import RunConfig, upgrade_saved_config
from pngail_jax.settings import settings_for


def test_json_round_trip_and_presets(tmp_path):
    config = RunConfig.preset("paper", env="Hopper", methods=("gail", "pngail"), seeds=2)
    assert (config.iterations, config.seeds, config.preset_name) == (5000, 2, "paper")
    assert config.settings == settings_for("Hopper") and config.task_bsc_eps == 0.01
    path = tmp_path / "config.json"
    path.write_text(json.dumps({**config.to_dict(), "provenance": {"git_commit": "x"}}))
    assert RunConfig.from_json(path) == config  # extra keys (provenance, resolved) ignored
    walker = config.replace(env="Walker2d")
    assert walker.settings == settings_for("Walker2d") and walker.task_bsc_eps == 0.05
    assert config.replace(num_demos=None, bsc_eps=None) == config  # None sets a field to None


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"methods": ("gail", "pu-gail")}, r"unknown method\(s\) \['pu-gail'\]"),
        ({"env": "CartPole"}, "unknown environment 'CartPole'"),
        ({"label_ratios": (0.2, 1.5)}, r"label ratios must lie in \(0, 1\)"),
        ({"noise_stds": (float("inf"),)}, "noise stds must be finite"),
        ({"seeds": 0}, "seeds must be a positive integer"),
        ({"iterations": 25}, r"multiple of the evaluation interval \(10"),
        ({"cpu_devices": -1}, "cpu_devices must be a positive integer"),
        ({"log": ("mlflow",)}, r"unknown log backend\(s\) \['mlflow'\]"),
        ({"confidence_field": "r"}, "Minari dataset"),
        ({"demos": "/x/demos.npz", "action_scale": 2.0}, "no conf or action_scale"),
    ],
)
def test_bad_values_are_named(overrides, message):
    with pytest.raises(ValueError, match=message):
        RunConfig(**overrides)


def test_a_config_json_from_before_run_config_still_reads():
    old = {
        "env": "Pendulum-v1", "methods": ["gail"], "seeds": 2, "iterations": 20,
        "preset": None, "action_scale": 2.0, "num_demos": None, "label_ratios": [0.2],
        "noise_stds": [0.0], "seed": 0, "eval_every": 10, "chunk_iterations": 10,
        "classifier_steps": 50, "fisher": "gauss_newton", "fisher_subsample": 1,
        "cpu_devices": None, "num_envs": 4, "unroll_length": 50, "demos": "/d/mix.npy",
        "conf": None, "normalizer": None, "platform": "cpu", "device_count": 1,
        "local_device_count": 1,
    }  # fmt: skip
    config = RunConfig.from_dict(old)
    assert config.classifier.num_steps == 50 and config.action_scale == 2.0
    assert (config.settings.num_envs, config.settings.unroll_length) == (4, 50)
    assert upgrade_saved_config(old)["resolved"]["demos_path"] == "/d/mix.npy"
    assert dataclasses.asdict(config)["methods"] == ("gail",)
