"""The method families' one interface (``grid.MethodFamily``): both families have every
member and answer it on a tiny cell list, ``grid.stack_cells`` stacks either family's cells
into the arrays its spec functions give (and, bit for bit, into the arrays of the two
functions it replaced), and ``grid.py`` imports neither family."""

import dataclasses
import hashlib
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax.adversarial.family import ADVERSARIAL
from pngail_jax.adversarial.methods import method_spec
from pngail_jax.adversarial.trainer import AdversarialHyperparams, AdversarialTrainer
from pngail_jax.grid import Cell, MethodFamily, make_cells, stack, stack_cells
from pngail_jax.offline.family import OFFLINE
from pngail_jax.offline.trainer import OfflineHyperparams, OfflineTrainer, offline_spec

FAMILIES = {"adversarial": ADVERSARIAL, "offline": OFFLINE}
# A tiny grid of each family: two settings, two methods (of two programs, offline), two seeds.
TINY_METHODS = {"adversarial": ("gail", "pngail"), "offline": ("bc-expert", "dwbc+bsc")}


def leaves_equal(a, b) -> bool:
    """Bit equality of two pytrees (PRNG keys as their key data)."""

    def data(x):
        return jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x

    left, right = jax.tree.leaves(jax.tree.map(data, a)), jax.tree.leaves(jax.tree.map(data, b))
    return jax.tree.structure(a) == jax.tree.structure(b) and all(
        x.dtype == y.dtype and np.array_equal(np.asarray(x), np.asarray(y))
        for x, y in zip(left, right, strict=True)
    )


def digest(tree) -> str:
    """The first 16 hex digits of the SHA-256 of a pytree's leaves' bytes, in order."""
    sha = hashlib.sha256()
    for leaf in jax.tree.leaves(tree):
        if jax.dtypes.issubdtype(leaf.dtype, jax.dtypes.prng_key):
            leaf = jax.random.key_data(leaf)
        sha.update(np.asarray(leaf).tobytes())
    return sha.hexdigest()[:16]


@pytest.mark.parametrize("name", FAMILIES)
def test_each_family_answers_every_member_on_a_tiny_cell_list(name):
    family = FAMILIES[name]
    assert isinstance(family, MethodFamily) and family.name == name
    assert {f.name for f in dataclasses.fields(MethodFamily)} == set(vars(family))
    methods = TINY_METHODS[name]
    cells = make_cells(methods, 2, label_ratios=(0.2, 0.5), noise_stds=(0.1,))
    assert set(methods) <= set(family.method_names)
    for method in methods:
        assert family.check_method(method) == method
    with pytest.raises(ValueError, match=methods[0]) as refused:  # it names the known ones
        family.check_method("no-such-method")
    assert "\n" not in str(refused.value) and "no-such-method" in str(refused.value)
    for cell in cells:
        spec, hyperparams = family.spec(cell.method), family.hyperparams(cell)
        assert all(leaf.shape == () and leaf.dtype == jnp.float32 for leaf in jax.tree.leaves(spec))
        assert all(leaf.shape == () for leaf in jax.tree.leaves(hyperparams))  # one cell's
        assert float(hyperparams.label_ratio) == np.float32(cell.label_ratio)
    with pytest.raises(ValueError, match="no_such_field"):
        family.spec(methods[0], no_such_field=1.0)
    parts = family.parts(methods)
    assert parts == tuple(dict.fromkeys(parts)) and parts == family.parts(methods[::-1])
    groups = family.program_groups(methods)
    assert [m for group in groups for m in group] == list(methods)  # a partition, in order
    for attribute in ("init", "run_blocks", "policy_state", "eval_every", "train"):
        assert hasattr(family.trainer, attribute)


def test_the_families_parts_and_programs():
    assert ADVERSARIAL.trainer is AdversarialTrainer and OFFLINE.trainer is OfflineTrainer
    assert ADVERSARIAL.parts(["gail", "pngail"]) == ()
    assert ADVERSARIAL.parts(["bc", "cail"]) == ("bc", "cail")
    assert ADVERSARIAL.program_groups(["gail", "bc", "cail"]) == [("gail", "bc", "cail")]
    assert OFFLINE.parts(["bc-expert", "dwbc+bsc"]) == ("dwbc", "classifier")
    assert OFFLINE.program_groups(["bc-expert", "dwbc", "bc-all", "iswbc+bsc"]) == [
        ("bc-expert", "bc-all"), ("dwbc",), ("iswbc+bsc",),
    ]  # fmt: skip
    assert "ilid+bsc" in OFFLINE.method_names and "pngail" in ADVERSARIAL.method_names
    with pytest.raises(ValueError, match="unknown offline method 'pngail'"):
        OFFLINE.program_groups(["pngail"])
    with pytest.raises(ValueError, match="unknown method 'dwbc'"):
        ADVERSARIAL.program_groups(["dwbc"])


def adversarial_cells() -> list[Cell]:
    axes = [("bsc_eps", (0.01, 0.05)), ("max_kl", (0.01, 0.02))]  # a spec and a learner axis
    return make_cells(["gail", "pngail", "2iwil"], 2, (0.2, 0.5), (0.0, 0.1), axes=axes)


def offline_cells() -> list[Cell]:
    return make_cells(["bc-expert", "dwbc+bsc", "iswbc", "ilid"], 2, (0.2, 0.4), (0.0, 0.3))


def test_stacking_adversarial_cells_gives_each_cells_spec_and_hyperparams():
    cells, key = adversarial_cells(), jax.random.key(7)
    stacked = stack_cells(cells, key, {"bsc_eps": 0.05}, family=ADVERSARIAL, learner="trpo")
    expected = []
    for cell in cells:
        axes = dict(cell.axes)
        hyperparams = AdversarialHyperparams.create(
            label_ratio=cell.label_ratio, noise_std=cell.noise_std, learner="trpo",
            max_kl=axes["max_kl"],
        )  # fmt: skip
        expected.append((hyperparams, method_spec(cell.method, bsc_eps=axes["bsc_eps"])))
    keys = jnp.stack([jax.random.fold_in(key, cell.seed) for cell in cells])
    hyperparams, specs = stack([h for h, _ in expected]), stack([s for _, s in expected])
    assert leaves_equal(stacked, (hyperparams, specs, keys))
    # The arrays of grid.stack_cells before the family was passed in (at ded145a), bit for bit.
    assert digest(stacked) == "bef8f0c030588850"


def test_stacking_offline_cells_gives_each_cells_spec_and_hyperparams():
    cells, key = offline_cells(), jax.random.key(7)
    overrides = {"bsc_eps": 0.05, "ilid_discriminator_learning_rate": 2e-5}
    stacked = stack_cells(cells, key, overrides, family=OFFLINE)
    hyperparams = stack([OfflineHyperparams.create(c.label_ratio, c.noise_std) for c in cells])
    specs = stack([offline_spec(c.method, **overrides) for c in cells])
    keys = jnp.stack([jax.random.fold_in(key, cell.seed) for cell in cells])
    assert leaves_equal(stacked, (hyperparams, specs, keys))
    # The arrays of offline.trainer.stack_offline_cells, which this replaced (at ded145a).
    assert digest(stacked) == "bdf8635564d231f4"


def test_a_cell_with_an_axis_its_family_does_not_take_is_refused():
    cell = Cell("dwbc", 0, axes=(("max_kl", 0.02),))
    with pytest.raises(
        ValueError, match=r"the offline family's cells take no grid axis \['max_kl'\]"
    ):
        stack_cells([cell], jax.random.key(0), family=OFFLINE)
    with pytest.raises(ValueError, match="at least one cell"):
        stack_cells([], jax.random.key(0), family=OFFLINE)
    with pytest.raises(TypeError, match="family"):
        stack_cells([cell], jax.random.key(0))  # a grid does not guess the family


def test_the_grid_imports_neither_family():
    """``grid.py`` is generic: the families are passed in. Its own imports, read in a fresh
    interpreter (tests/test_layers.py holds the rest of the house's imports)."""
    code = (
        "import sys, pngail_jax.grid\n"
        "found = sorted(m for m in sys.modules if m.startswith(('pngail_jax.adversarial', "
        "'pngail_jax.offline')))\n"
        "print(found)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"
