"""Methods from outside the package: ``register``, ``package.module:preset`` names, and the
checks a preset passes before a grid runs it."""

import sys
import textwrap
from pathlib import Path

import jax
import numpy as np
import pytest
from test_grid import assert_close_across_programs, small_setup

from pngail_jax.adversarial import methods
from pngail_jax.adversarial.family import ADVERSARIAL
from pngail_jax.adversarial.methods import (
    PRESETS,
    Preset,
    check_preset,
    method_spec,
    register,
    resolve,
)
from pngail_jax.adversarial.trainer import AdversarialTrainer
from pngail_jax.config.run_config import RunConfig
from pngail_jax.config.validation import ConfigError
from pngail_jax.grid import make_cells, stack_cells
from pngail_jax.programs import sweep

# Halfway between 2IWIL's loss and PN-GAIL's (pn_coef from 0 to 1 is a continuum), with BSC
# confidences: a method defined in a user's own module.
OUTSIDE_MODULE = """
from pngail_jax.adversarial.methods import Preset

half_pn = Preset(
    "halfway between 2IWIL's and PN-GAIL's losses", "bsc",
    {"agent_coef": 1.0, "pn_coef": 0.5, "importance_weighted_coef": 0.5,
     "classifier_coef": 1.0, "bsc_coef": 1.0},
)
not_a_preset = 3
"""
OUTSIDE = "outside_methods:half_pn"


@pytest.fixture
def outside_module(tmp_path, monkeypatch):
    (tmp_path / "outside_methods.py").write_text(textwrap.dedent(OUTSIDE_MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    before = dict(PRESETS)
    yield
    sys.modules.pop("outside_methods", None)
    PRESETS.clear()
    PRESETS.update(before)


def test_every_built_in_passes_its_own_checks():
    for name, preset in PRESETS.items():
        assert check_preset(name, preset).phases == preset.phases


@pytest.mark.parametrize(
    ("preset", "message"),
    [
        (Preset("x", "none", {"pn_coeff": 1.0}), r"unknown MethodSpec field\(s\) \['pn_coeff'\]"),
        (Preset("x", "none", {"agent_coef": float("nan")}), "agent_coef must be a finite"),
        (Preset("x", "labels", {}), "confidence_source must be one of"),
        (Preset("x", "none", {"pn_coef": 1.0}), "pn_coef read confidences"),
        (Preset("x", "sc", {"classifier_coef": 1.0, "bsc_coef": 1.0}), "must be 'bsc'"),
        (Preset("x", "bsc", {}), "needs classifier_coef 1"),
        (Preset("x", "none", {"firl_coef": 1.0}), r"phase\(s\) \['firl'\]"),
        (Preset("x", "none", {"ranking_reward_coef": 1.0}), r"\['demo_rankings'\]"),
        (Preset("x", "none", {}, ("dagger",)), "phases must be among"),
        ({"agent_coef": 1.0}, "a pngail_jax.adversarial.methods.Preset"),
        (Preset("x", "none", {"gail_coef": 1.0, "bsc_eps": 0.0}), r"bsc_eps must lie in"),
        (Preset("x", "none", {"adversarial_reward_coef": 0.0}), "needs a phase whose reward"),
        (Preset("x", "none", {"policy_update_coef": 0.0}), "needs the 'bc' phase"),
        (Preset("x", "none", [("agent_coef", 1.0)]), "coefficients must be a dict"),
    ],
)
def test_a_preset_is_refused_naming_the_field(preset, message):
    with pytest.raises(ValueError, match=message):
        check_preset("mine", preset)


def test_register_adds_a_name_once_and_keeps_the_built_ins():
    mine = Preset("GAIL at half the agent weight", "none", {"agent_coef": 0.5, "gail_coef": 1.0})
    try:
        register("gail-half", mine)
        register("gail-half", mine)  # again, the same: a no-op
        assert float(method_spec("gail-half").agent_coef) == 0.5
        with pytest.raises(ValueError, match="already registered as another method"):
            register("gail-half", Preset("other", "none", {"agent_coef": 0.25}))
        with pytest.raises(ValueError, match="already registered"):
            register("gail", mine)
        assert RunConfig(methods=("gail", "gail-half")).methods == ("gail", "gail-half")
    finally:
        PRESETS.pop("gail-half", None)


def test_a_module_preset_is_imported_by_name_and_errors_name_it(outside_module):
    assert resolve(OUTSIDE).confidence_source == "bsc" and OUTSIDE in PRESETS
    config = RunConfig(methods=("gail", OUTSIDE))
    assert RunConfig.from_dict(config.to_dict()) == config  # a saved run names it again
    with pytest.raises(ConfigError, match="cannot import it") as error:
        RunConfig(methods=("outside_methods:missing",))
    assert error.value.field == "methods"
    with pytest.raises(ConfigError, match="a pngail_jax.adversarial.methods.Preset"):
        RunConfig(methods=("outside_methods:not_a_preset",))
    assert sweep.parse_args(["--methods", f"gail,{OUTSIDE}", "--out", "unused"]).config.methods


def test_an_outside_method_in_a_grid_with_built_ins_equals_its_cells_alone(outside_module):
    names = ("gail", OUTSIDE, "pngail")
    env, demos, config = small_setup()
    trainer = AdversarialTrainer(config, env, demos)
    trainer.check_methods(names)
    cells = make_cells(names, 1)
    hyperparams, specs, keys = stack_cells(cells, jax.random.key(0), family=ADVERSARIAL)
    _, grid_metrics = jax.jit(jax.vmap(trainer.train))(hyperparams, specs, keys)
    single = jax.jit(trainer.train)
    for index in range(len(cells)):
        pick = jax.tree.map(lambda x, i=index: x[i], (hyperparams, specs, keys))
        _, metrics = single(*pick)
        for name in ("eval/return", "disc/loss", "train/reward"):
            assert_close_across_programs(grid_metrics[name][index], metrics[name], name)
    # The halfway loss is its own method: its discriminator loss is neither neighbour's.
    losses = np.asarray(grid_metrics["disc/loss"])[:, -1]
    assert losses[1] != losses[0] and losses[1] != losses[2]
    assert methods.required_phases(names) == ()


def test_the_pu_examples_are_presets_from_outside_the_package(monkeypatch):
    """examples/pu_methods.py (PU-GAIL and UID) through the public route: imported by name,
    checked, and a grid's config accepts them beside the built-ins."""
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1]))
    before = dict(PRESETS)
    try:
        names = ("examples.pu_methods:pu_gail", "examples.pu_methods:uid")
        for name in names:
            assert resolve(name).confidence_source == "none"
        spec = method_spec(names[0])
        assert float(spec.pu_coef) == 1.0 and float(spec.agent_coef) == 0.0
        assert RunConfig(methods=("gail", "pngail", *names)).methods[2:] == names
    finally:
        PRESETS.clear()
        PRESETS.update(before)
