"""RunConfig: validation naming the field, JSON round trips, presets, old config.json files.
(tests/test_config_properties.py tries arbitrary values for every field.)"""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from pngail_jax.confidence import ClassifierConfig
from pngail_jax.config.run_config import RunConfig
from pngail_jax.config.saved import upgrade_saved_config
from pngail_jax.config.settings import RunSettings, settings_for
from pngail_jax.jobs.trainer_configs import adversarial_config


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
        ({"noise_stds": (0.0, float("nan"))}, "noise stds must be finite"),
        ({"noise_stds": (0.1, 0.1)}, "noise stds must not repeat"),
        ({"label_ratios": ()}, "label ratios must not be empty"),
        ({"label_ratios": ("0.2",)}, r"label ratios must lie in \(0, 1\), got '0.2'"),
        ({"action_scale": float("inf")}, "action_scale must be finite and positive"),
        ({"action_scale": 10**400}, "action_scale must be finite and positive"),  # no float
        ({"bsc_eps": float("nan")}, r"bsc_eps must lie in \(0, 0.5\)"),
        ({"cpu_devices": 0}, "cpu_devices must be a positive integer, got 0"),
        ({"cpu_devices": True}, "cpu_devices must be a positive integer, got True"),
        ({"seeds": "3"}, "seeds must be a positive integer, got '3'"),
        ({"iterations": 300.0}, "iterations must be a positive integer, got 300.0"),
        ({"seed": -1}, r"seed must be an integer in \[0, 2\*\*63\)"),
        ({"num_demos": 1}, r"num_demos must be an integer in \[2, 2\*\*31\)"),
        ({"num_demos": 10**400}, r"num_demos must be an integer in \[2, 2\*\*31\)"),
        ({"methods": ()}, "methods must name at least one method"),
        ({"methods": (["gail"],)}, r"unknown method\(s\) \[\['gail'\]\]"),  # no TypeError
        ({"log": ("tensorboard", "tensorboard")}, "log backends must not repeat"),
        ({"learner": {"trpo": {"fisher": ["hessian"]}}}, "TRPOConfig.fisher must be one of"),
        ({"learner": {"name": "ppo", "ppo": {"num_epochs": 0}}}, "PPOConfig.num_epochs must be"),
        ({"learner": {"nam": "ppo"}}, r"learner: unknown key\(s\) \['nam'\]"),
        ({"discriminator_hidden_sizes": (100, 0)}, "discriminator_hidden_sizes must be positive"),
        ({"demos": 5}, "demos must be a non-empty string or None, got 5"),
        ({"env": 5}, "env must be an environment name, got 5"),
        ({"env": "CartPole", "settings": RunSettings()}, "unknown environment 'CartPole'"),
        (
            {"settings": {"num_envs": 4}},
            "settings must be a pngail_jax.config.settings.RunSettings",
        ),
        ({"classifier": {"num_steps": 5}}, "classifier must be a pngail_jax.confidence"),
        (
            {"classifier": ClassifierConfig(learning_rate=float("nan"))},
            "ClassifierConfig.learning_rate must be finite and positive, got nan",
        ),
        (
            {"classifier": ClassifierConfig(dropout_rate=1.0)},
            r"ClassifierConfig.dropout_rate must lie in \[0, 1\)",
        ),
        (
            {"classifier": ClassifierConfig(num_steps=True)},
            "ClassifierConfig.num_steps must be a positive integer, got True",
        ),
        ({"conf": "/x/conf.npy"}, "conf: a confidence file needs demos"),
        ({"grid_axes": (("num_envs", (4, 8)),)}, "'num_envs' is static: it fixes the shapes"),
        ({"grid_axes": (("max_kll", (0.1,)),)}, "'max_kll' is not a per-cell field"),
        ({"grid_axes": (("label_ratio", (0.1,)),)}, r"has its own axis \(label_ratios\)"),
        ({"grid_axes": (("max_kl", (0.1, 0.1)),)}, "max_kl values must not repeat"),
        ({"grid_axes": (("max_kl", (0.01, 0.010000001)),)}, "not distinct to 6 digits"),
        ({"grid_axes": (("bsc_eps", (0.0,)),)}, r"bsc_eps must lie in \(0, 0.5\)"),
        (
            {"grid_axes": (("adversarial_reward_coef", (0.0,)),)},
            "adversarial_reward_coef other than 1 needs a phase",
        ),
        ({"methods": ("gail",), "baseline": "pngail"}, "baseline must be one of the run's"),
        ({"grid_axes": (("max_kl", (0.0,)),)}, "max_kl=0: TRPOHyperparams.max_kl out of range"),
        ({"grid_axes": (("gamma", ()),)}, "gamma values must not be empty"),
        ({"grid_axes": (("pn_coef", (1.0,)),)}, "pn_coef=1 on method 'gail': pn_coef read"),
        ({"grid_axes": "max_kl"}, "grid_axes must be .field, values. pairs"),
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


ROOT = Path(__file__).resolve().parents[1]
# The records of a run folder (a sweep's, an offline run's): each keeps its config.json (a
# settings comparison's keeps its arms' results instead).
RECORDS = sorted(
    path for path in ROOT.glob("records/*/record.json") if "config" in json.loads(path.read_text())
)


@pytest.mark.parametrize("path", RECORDS, ids=lambda path: path.parent.name)
def test_every_committed_records_config_json_reads_as_the_run_it_was(path):
    """Each committed record's config.json (most of a layout before the learner part: a flat
    ``learner``, ``fisher``, ``fisher_subsample``, ``value_epochs``, no PPO settings) reads
    as the config it ran: the flat keys in the learner part, every setting it did not hold
    at the default it ran with; today's config of it is no other run to the records'
    comparison (``config_differences``), and it round-trips through today's layout."""
    from pngail_jax.analysis.run_records import config_differences
    from pngail_jax.analysis.runs import read_run_config
    from pngail_jax.config.learner import LearnerConfig, PPOConfig, TRPOConfig
    from pngail_jax.jobs.offline_config import OfflineRunConfig, offline_defaults

    record = json.loads(path.read_text())
    document = record["config"]
    if read_run_config(document).program == "offline":
        values = {**offline_defaults(), **read_run_config(document).settings}
        for name in ("methods", "hidden_sizes"):
            values[name] = tuple(values[name])
        assert OfflineRunConfig(**values).demonstrations.demos == document["config"]["demos"]
        return
    config = RunConfig.from_dict(document)
    trpo = TRPOConfig(
        fisher=document.get("fisher", "gauss_newton"),
        fisher_subsample=document.get("fisher_subsample", 1),
        num_value_epochs=document.get("value_epochs", 1),
    )
    if isinstance(document.get("learner"), dict):  # a record of today's layout
        assert config.learner == LearnerConfig(**{
            **document["learner"], "trpo": TRPOConfig(**document["learner"]["trpo"]),
            "ppo": PPOConfig(**document["learner"]["ppo"]),
        })  # fmt: skip
    else:
        assert config.learner == LearnerConfig(document.get("learner", "trpo"), trpo, PPOConfig())
    today = json.loads(json.dumps(config.to_dict()))
    assert RunConfig.from_dict(today) == config
    assert config_differences(today, record, RunConfig().to_dict()) == []
    older = {**today, "learner": {**today["learner"], "name": "ppo"}}
    assert config_differences(older, record, RunConfig().to_dict()) == ["learner"]


def test_numbers_are_stored_in_their_annotated_types():
    config = RunConfig(
        seeds=np.int64(2),
        label_ratios=[np.float32(0.5), 0.25],
        noise_stds=[0, 1],
        action_scale=2,
        cpu_devices=np.int32(2),
        discriminator_hidden_sizes=[np.int64(8)],
        classifier=ClassifierConfig(learning_rate=1, hidden_sizes=[4]),
    )
    assert type(config.seeds) is int and type(config.cpu_devices) is int
    assert config.label_ratios == (0.5, 0.25) and config.noise_stds == (0.0, 1.0)
    assert all(type(value) is float for value in (*config.label_ratios, *config.noise_stds))
    assert type(config.action_scale) is float and config.discriminator_hidden_sizes == (8,)
    assert config.classifier.hidden_sizes == (4,)
    assert type(config.classifier.learning_rate) is float
    assert RunConfig.from_dict(json.loads(json.dumps(config.to_dict()))) == config


def _saved(**changes):
    """A config.json document (the config's fields and the sweep's records) with changes
    (``...``: the key removed)."""
    document = {**RunConfig().to_dict(), "resolved": {}, "provenance": {}}
    for key, value in changes.items():
        if value is ...:
            del document[key]
        else:
            document[key] = value
    return json.loads(json.dumps(document))


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"seedz": 4}, r"unknown key\(s\) \['seedz'\]; a run config's keys: action_scale"),
        ({"seeds": "3"}, "seeds must be a positive integer, got '3'"),
        ({"noise_stds": [0.0, "0.1"]}, "noise stds must be finite and >= 0"),
        ({"methods": {"gail": 1}}, r"unknown method\(s\) \[\{'gail': 1\}\]"),
        ({"settings": [25, 200]}, "settings must be a pngail_jax.config.settings.RunSettings"),
        (
            {"settings": {**dataclasses.asdict(RunSettings()), "num_env": 4}},
            r"settings: unknown key\(s\) \['num_env'\]",
        ),
        (
            {"settings": {**dataclasses.asdict(RunSettings()), "num_envs": "25"}},
            "RunSettings.num_envs must be a positive integer, got '25'",
        ),
        ({"classifier": "fast"}, "classifier must be a pngail_jax.confidence.ClassifierConfig"),
        ({"classifier": 3}, "classifier must be a pngail_jax.confidence.ClassifierConfig"),
        ({"classifier": {"num_steps": 10, "lr": 1}}, r"classifier: unknown key\(s\) \['lr'\]"),
        ({"classifier": {"hidden_sizes": "40"}}, "ClassifierConfig.hidden_sizes must be positive"),
        ({"classifier": {"num_steps": 2.5}}, "ClassifierConfig.num_steps must be a positive int"),
        ({"cpu_devices": -1}, "cpu_devices must be a positive integer, got -1"),
    ],
)
def test_from_dict_names_the_key_of_a_bad_file(changes, message, tmp_path):
    with pytest.raises(ValueError, match=message):
        RunConfig.from_dict(_saved(**changes))
    path = tmp_path / "config.json"
    path.write_text(json.dumps(_saved(**changes)))
    with pytest.raises(ValueError, match=f"{path}: "):
        RunConfig.from_json(path)


def test_from_dict_fills_missing_keys_with_defaults_and_refuses_what_is_not_an_object(tmp_path):
    assert RunConfig.from_dict({"env": "Hopper", "seeds": 2}) == RunConfig(env="Hopper", seeds=2)
    partial = RunConfig.from_dict({"settings": {"num_envs": 4}, "classifier": {"num_steps": 7}})
    assert partial.settings == RunSettings(num_envs=4) and partial.classifier.num_steps == 7
    assert RunConfig.from_dict(_saved(log=..., preset_name=...)) == RunConfig()
    with pytest.raises(ValueError, match="a run config is a JSON object of fields, got list"):
        RunConfig.from_dict([["seeds", 3]])
    path = tmp_path / "config.json"
    for text, message in (("[1, 2]", "JSON object"), ('{"seeds": 3', "not a run config")):
        path.write_text(text)
        with pytest.raises(ValueError, match=message):
            RunConfig.from_json(path)


def test_an_old_config_json_missing_keys_is_named():
    with pytest.raises(
        ValueError, match=r"old layout \(classifier_steps\) lacks key\(s\) \['demos'"
    ):
        RunConfig.from_dict({"classifier_steps": 5, "num_envs": 4})


def test_the_gradient_penalty_is_compiled_when_a_cell_uses_it():
    assert not adversarial_config(RunConfig()).gradient_penalty
    assert not RunConfig(grid_axes=(("gradient_penalty_coef", (0.0,)),)).uses_gradient_penalty
    by_axis = RunConfig(methods=("pngail",), grid_axes=(("gradient_penalty_coef", (0.0, 1.0)),))
    assert adversarial_config(by_axis).gradient_penalty


def test_a_runs_provenance_names_the_checkouts_commit():
    """provenance's git_commit is this checkout's HEAD (None was written after saved.py moved
    one folder down, so records kept no commit)."""
    import subprocess
    from pathlib import Path

    from pngail_jax.config.saved import provenance

    root = Path(__file__).resolve().parents[1]
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True)
    if head.returncode != 0:
        pytest.skip("not a git checkout")
    commit = provenance(command=["x"])["git_commit"]
    assert commit is not None and commit.removesuffix("+dirty") == head.stdout.strip()


def test_check_budgets_shrink_the_appendix_phases_and_results_budgets_keep_the_codebases():
    """The sweep's check preset and the paper's check and test budgets give the appendix
    phases their small check sizes, recorded as the config's ``phase_sizes`` (config.json)
    and in the trainer's config (config.json's ``resolved.adversarial``); the results budgets
    (the sweep's smoke and paper presets, the paper's paper, gpu and cpu budgets) keep the
    codebases' sizes: T-REX 10,000 steps, D-REX 50,000 cloning steps, 5 episodes per level
    and 3 x 10,000 reward steps, CAIL 10 rounds, f-IRL 1,200 discriminator steps."""
    from pngail_jax.config.budget import CHECK_PHASE_SIZES
    from pngail_jax.paper.grids import grid_config
    from pngail_jax.paper.plan import APPENDIX_COMPARISON, BUDGETS, DemoSet, GridSpec

    def sizes(config: RunConfig) -> tuple:
        adversarial = adversarial_config(config)
        return (
            adversarial.ranking.num_steps,
            adversarial.ranking.pairs_per_step,
            adversarial.drex.ranking.pairs_per_step,
            adversarial.drex.bc.num_steps,
            adversarial.drex.rollouts_per_level,
            adversarial.drex.ranking.num_steps,
            adversarial.cail.num_rounds,
            adversarial.firl.discriminator_iterations,
        )

    small = CHECK_PHASE_SIZES
    check_sizes = (
        small["ranking_steps"], small["ranking_pairs_per_step"], small["ranking_pairs_per_step"],
        small["drex_bc_steps"], small["drex_rollouts_per_level"], small["ranking_steps"],
        small["cail_rounds"], small["firl_discriminator_iterations"],
    )  # fmt: skip
    codebase_sizes = (10_000, 64, 64, 50_000, 5, 10_000, 10, 1_200)
    assert check_sizes == (100, 16, 16, 500, 1, 100, 2, 50)
    check = RunConfig.preset("check")
    assert check.phase_sizes == "check" and sizes(check) == check_sizes
    assert RunConfig.from_dict(json.loads(json.dumps(check.to_dict()))).phase_sizes == "check"
    for name in ("smoke", "paper"):
        config = RunConfig.preset(name)
        assert config.phase_sizes == "codebase" and sizes(config) == codebase_sizes
    assert sizes(RunConfig.preset("check", phase_sizes="codebase")) == codebase_sizes
    grid = GridSpec("appendix", "Pendulum-v1", DemoSet("Pendulum-v1", None), APPENDIX_COMPARISON)
    for name, budget in BUDGETS.items():
        expected = "check" if name in ("check", "test") else "codebase"
        config = grid_config(grid, ("demos.npy", 1.0), budget, None)
        assert budget.phase_sizes == config.phase_sizes == expected, name
        assert sizes(config) == (check_sizes if expected == "check" else codebase_sizes), name
