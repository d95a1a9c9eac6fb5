"""save_tree / restore_tree: whole training states, PRNG keys and empty MJX leaves included."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax.storage.checkpoint import restore_tree, save_tree


def test_round_trip_with_keys_empty_leaves_and_dtypes(tmp_path):
    tree = {
        "key": jax.random.split(jax.random.key(3), 4),
        "empty": jnp.zeros((4, 0, 3)),  # MJX states carry zero-size contact arrays
        "flags": jnp.array([True, False, True]),
        "count": jnp.arange(5, dtype=jnp.int32),
        "params": {"w": jax.random.normal(jax.random.key(1), (3, 2))},
    }
    save_tree(tmp_path / "state", tree)
    restored = restore_tree(tmp_path / "state", jax.eval_shape(lambda: tree))
    assert jax.tree.structure(restored) == jax.tree.structure(tree)
    np.testing.assert_array_equal(
        jax.random.key_data(restored["key"]), jax.random.key_data(tree["key"])
    )
    # The restored key draws the same numbers.
    np.testing.assert_array_equal(
        jax.random.normal(restored["key"][2], (3,)), jax.random.normal(tree["key"][2], (3,))
    )
    for name in ("empty", "flags", "count"):
        np.testing.assert_array_equal(restored[name], tree[name])
        assert restored[name].dtype == tree[name].dtype
    np.testing.assert_array_equal(restored["params"]["w"], tree["params"]["w"])


def test_a_template_of_another_state_is_a_clear_error(tmp_path):
    save_tree(tmp_path / "state", {"a": jnp.ones(3), "b": jnp.ones(2)})
    with pytest.raises(ValueError, match=r"leaf 0 is float32\(3,\), expected float32\(4,\)"):
        restore_tree(tmp_path / "state", {"a": jnp.ones(4), "b": jnp.ones(2)})
    # A state with a field more or less (another version's): named as such.
    with pytest.raises(ValueError, match="holds 2 arrays where this version's state has 1"):
        restore_tree(tmp_path / "state", {"a": jnp.ones(3)})
    with pytest.raises(ValueError, match="holds 2 arrays where this version's state has 3"):
        restore_tree(tmp_path / "state", {"a": jnp.ones(3), "b": jnp.ones(2), "c": jnp.ones(1)})
