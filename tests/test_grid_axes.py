"""The config's grid part (pngail_jax.config.grid_axes) is plain data written out: it must
name exactly the trainers' own per-cell and static fields."""

from __future__ import annotations

import dataclasses

import pytest

from pngail_jax.adversarial.methods import MethodSpec
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.config.grid_axes import GRID_AXES, METHOD_AXES, STATIC_FIELDS, check_grid_axes
from pngail_jax.config.settings import RunSettings
from pngail_jax.config.validation import ConfigError
from pngail_jax.rl.on_policy import RolloutConfig
from pngail_jax.rl.ppo import PPOConfig, PPOHyperparams
from pngail_jax.rl.trpo import TRPOConfig, TRPOHyperparams


def _names(cls) -> set[str]:
    return {field.name for field in dataclasses.fields(cls)}


def test_the_method_axes_are_method_spec_fields_in_order():
    assert METHOD_AXES == tuple(field.name for field in dataclasses.fields(MethodSpec))


def test_the_hyperparameter_axes_are_the_learners_and_the_discriminators():
    learners = _names(TRPOHyperparams) | _names(PPOHyperparams)
    hyperparams = set(GRID_AXES) - set(METHOD_AXES) - {"discriminator_learning_rate"}
    assert hyperparams <= learners


def test_the_static_fields_are_the_static_configs_fields():
    configs = (RunSettings, RolloutConfig, TRPOConfig, ClassifierConfig, PPOConfig)
    run_fields = {"learner", "iterations", "seeds", "num_demos", "discriminator_hidden_sizes"}
    expected = set().union(*(_names(cls) for cls in configs)) | run_fields | {"chunk_iterations"}
    assert STATIC_FIELDS == expected


@pytest.mark.parametrize(
    ("axes", "message"),
    [
        ((("num_envs", (1, 2)),), "'num_envs' is static"),
        ((("nope", (1,)),), "'nope' is not a per-cell field"),
        ((("label_ratio", (0.1,)),), "label_ratio has its own axis"),
        ((("max_kl", (0.01,)), ("max_kl", (0.02,))), "an axis is given twice"),
    ],
)
def test_the_check_refuses_with_the_reason(axes, message):
    with pytest.raises(ConfigError, match=message):
        check_grid_axes(axes)


def test_the_check_returns_floats_in_tuples():
    assert check_grid_axes([["max_kl", [1, 0.02]]]) == (("max_kl", (1.0, 0.02)),)


def test_each_learners_hyperparameter_names_are_its_classes_fields():
    from pngail_jax.config.learner import HYPERPARAM_NAMES

    assert HYPERPARAM_NAMES == {
        "trpo": tuple(field.name for field in dataclasses.fields(TRPOHyperparams)),
        "ppo": tuple(field.name for field in dataclasses.fields(PPOHyperparams)),
    }
