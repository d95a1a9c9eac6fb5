"""The mapping from config fields to flags: every flag sets a real field, every field a user
may set has a flag, and a bad value is refused naming its flag."""

import argparse
import dataclasses
import json
import re

import pytest

from pngail_jax import envs
from pngail_jax.config.run_config import RunConfig
from pngail_jax.config.settings import REFERENCE_SETTINGS, settings_for
from pngail_jax.jobs.trainer_configs import adversarial_config
from pngail_jax.programs import flags, sweep

# RunConfig fields the sweep sets through its own flags or not at all.
NOT_FLAGS = {"env", "settings", "classifier", "discriminator_hidden_sizes", "preset_name"}


def field_value(config, path):
    for part in path.split("."):
        config = getattr(config, part)
    return config


def test_every_flag_sets_a_field_and_every_field_has_a_flag():
    config = RunConfig()
    for flag in (*flags.RUN_FLAGS, *flags.SETTINGS_FLAGS, *flags.LEARNER_FLAGS):
        field_value(config, flag.field)  # AttributeError for a field that does not exist
    top = {flag.field for flag in flags.RUN_FLAGS if "." not in flag.field}
    fields = {field.name for field in dataclasses.fields(RunConfig)}
    assert fields - NOT_FLAGS == top | {"learner"}  # the learner part: LEARNER_FLAGS
    learner = {flag.field for flag in flags.LEARNER_FLAGS}
    assert {"learner.name", "learner.trpo.fisher", "learner.ppo.num_epochs"} <= learner
    for part in (config.learner.trpo, config.learner.ppo):  # TRPO's and PPO's own flags
        assert {f.name for f in dataclasses.fields(part)} >= {
            flag.field.split(".")[2]
            for flag in flags.LEARNER_FLAGS
            if flag.field.count(".") == 2
            and flag.field.split(".")[1] == type(part).__name__[:-6].lower()
        }
    settings = {flag.field.split(".")[1] for flag in flags.SETTINGS_FLAGS}
    settings.add("ls_iterations")  # --solver sets both caps
    assert settings == {field.name for field in dataclasses.fields(REFERENCE_SETTINGS)}
    names = [flag.name for flag in (*flags.RUN_FLAGS, *flags.SETTINGS_FLAGS, *flags.LEARNER_FLAGS)]
    assert len(set(names)) == len(names)


def settings_of(env, *argv):
    parser = argparse.ArgumentParser()
    flags.add_settings_flags(parser)
    return flags.settings_from_flags(parser, parser.parse_args(argv), env)


def test_settings_flags_override_the_table_or_the_reference(capsys):
    assert settings_of("Hopper") == settings_for("Hopper")
    own = settings_of("Hopper", "--solver", "own", "--num-eval-episodes", "5")
    assert own.env_options == {} and own.num_eval_episodes == 5 and own.num_envs == 25
    reference = settings_of(
        "Hopper", "--settings", "reference", "--solver", "fast", "--normalize-observations"
    )
    assert (reference.num_envs, reference.unroll_length) == (25, 200)
    assert reference.env_options == envs.FAST_SOLVER and reference.normalize_observations
    assert settings_of("Pendulum-v1", "--solver", " own") == REFERENCE_SETTINGS
    for argv, line in [  # the error line, whole (a pattern)
        (("Pendulum-v1", "--solver", "fast"), r"--solver: Pendulum-v1 has no MJX solver"),
        (("Hopper", "--unroll-length", "0"), r"--unroll-length must be a positive integer, got 0"),
        (
            ("Hopper", "--solver", "4/x"),
            r"--solver: solver must be 'own', 'fast' or 'I/L' \(.*\), got '4/x'",
        ),
        (
            ("Pendulum-v1", "--physics", "c"),
            r"--physics: only gymnasium's MuJoCo tasks \(.*\) have a choice of engine, "
            r"not Pendulum-v1",
        ),
    ]:
        with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
            settings_of(*argv)
        assert re.search(f": error: {line}$", capsys.readouterr().err, re.MULTILINE), argv


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--seeds", "0"], "--seeds must be a positive integer, got 0"),
        (["--classifier-steps", "0"], "--classifier-steps must be a positive integer, got 0"),
        (["--bsc-eps", "0.7"], r"--bsc-eps must lie in (0, 0.5), got 0.7"),
        (["--num-demos", "1"], "--num-demos must be an integer in [2, 2**31), got 1"),
        (["--label-ratio", "0.2,0.2"], "--label-ratio values must not repeat"),
        (["--random-return", "-5"], "--random-return needs optimal_return"),
        (["--num-envs", "0"], "--num-envs must be a positive integer, got 0"),
        (["--value-epochs", "0"], "--value-epochs must be a positive integer, got 0"),
        (["--value-epochs", "3", "--learner", "ppo"], "--value-epochs is TRPO's value fit"),
        (["--fisher-subsample", "0"], "--fisher-subsample must be a positive integer, got 0"),
        (["--ppo-epochs", "0"], "--ppo-epochs must be a positive integer, got 0"),
        (
            ["--learner", "ppo", "--ppo-minibatches", "100000"],
            "samples per iteration (num_envs x unroll_length = 5000) must be at least PPO's",
        ),
        (["--iterations", "25"], "--iterations (25) must be a multiple of the evaluation"),
        (["--conf", __file__], "--conf: a confidence file needs demos"),
    ],
)
def test_a_bad_value_is_refused_naming_its_flag(argv, message, capsys):
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        sweep.parse_args(argv)
    assert f"python -m experiments.sweep: error: {message}" in capsys.readouterr().err


def test_help_reads_the_defaults_of_the_config():
    text = sweep.build_parser().format_help()
    smoke = RunConfig.preset("smoke")
    assert f"(default {smoke.seeds})" in text and f"(default {smoke.iterations})" in text
    assert f"(default {smoke.classifier.num_steps:,};" in text


def test_a_config_files_baseline_and_axes_follow_the_flags(tmp_path):
    saved = RunConfig(
        methods=("gail", "pngail"), baseline="gail", grid_axes=(("max_kl", (0.005, 0.01)),)
    )
    path = tmp_path / "config.json"
    path.write_text(json.dumps(saved.to_dict()))
    out = str(tmp_path / "out")
    config = sweep.parse_args(["--config", str(path), "--methods", "pngail", "--out", out]).config
    assert config.baseline is None and config.grid_axes == saved.grid_axes  # gail left out
    config = sweep.parse_args(
        ["--config", str(path), "--grid", "none", "--baseline", "none", "--out", out]
    ).config
    assert config.grid_axes == () and config.baseline is None


def test_a_resume_refuses_a_method_whose_preset_changed(tmp_path):
    from pngail_jax.adversarial.methods import preset_record
    from pngail_jax.jobs import record as record_job

    record = json.loads(json.dumps(preset_record("pngail")))
    record_job.check_methods_unchanged(tmp_path, {"pngail": record})  # unchanged: passes
    record["coefficients"]["pn_coef"] = 0.5
    with pytest.raises(record_job.RunError, match="'pngail' is not the preset the run began with"):
        record_job.check_methods_unchanged(tmp_path, {"pngail": record})


def test_value_epochs_reach_the_learners_config(tmp_path):
    config = sweep.parse_args(["--value-epochs", "3", "--out", str(tmp_path / "out")]).config
    assert config.learner.trpo.num_value_epochs == 3
    assert adversarial_config(config).learner.trpo.num_value_epochs == 3


def test_ppo_settings_reach_the_learners_config_and_config_json(tmp_path):
    """PPO's static settings are set from the sweep's flags as TRPO's are, kept in the
    config's learner part (config.json) and given to the trainer."""
    argv = ["--learner", "ppo", "--ppo-epochs", "4", "--ppo-minibatches", "8",
            "--no-ppo-normalize-rewards", "--no-ppo-clip-value-loss"]  # fmt: skip
    argv += ["--out", str(tmp_path)]
    config = sweep.parse_args(argv).config
    assert config.learner.name == "ppo" and adversarial_config(config).learner == config.learner
    ppo = adversarial_config(config).learner.ppo
    assert (ppo.num_epochs, ppo.num_minibatches) == (4, 8)
    assert not ppo.normalize_rewards and not ppo.clip_value_loss and ppo.anneal_learning_rate
    assert RunConfig.from_dict(json.loads(json.dumps(config.to_dict()))) == config
    assert config.to_dict()["learner"]["ppo"]["num_epochs"] == 4
