"""save_tree / restore_tree: whole training states, PRNG keys and empty MJX leaves included;
load_policies: the stacked policies save_policies wrote."""

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


def test_load_policies_gives_back_the_stacked_policies_save_policies_wrote(tmp_path):
    """Every array as saved (a leading seed axis), the normaliser rebuilt, and a diverged
    seed's return (stored as null) back as NaN; a damaged folder is refused."""
    from pngail_jax.rl.on_policy import ObservationNormalizer
    from pngail_jax.storage.checkpoint import load_policies, save_policies
    from pngail_jax.storage.integrity import IntegrityError

    params = {"params": {"w": jax.random.normal(jax.random.key(0), (2, 3, 1))}}
    normalizer = ObservationNormalizer(
        count=jnp.array([4.0, 8.0]), mean=jnp.ones((2, 3)), sum_squares=jnp.full((2, 3), 2.5)
    )
    save_policies(
        tmp_path / "iter_0002", env_name="Pendulum-v1", observation_size=3,
        action_low=np.array([-2.0]), action_high=np.array([2.0]), hidden_sizes=(4,),
        policy_params=params, normalizer=normalizer, normalize_observations=True,
        final_eval_returns=np.array([-1244.0167236328125, np.nan], np.float32),
    )  # fmt: skip
    loaded, loaded_normalizer, returns = load_policies(tmp_path / "iter_0002")
    np.testing.assert_array_equal(loaded["params"]["w"], params["params"]["w"])
    for name in ("count", "mean", "sum_squares"):
        np.testing.assert_array_equal(
            getattr(loaded_normalizer, name), getattr(normalizer, name), err_msg=name
        )
    assert isinstance(loaded_normalizer, ObservationNormalizer)
    # -1244.0167236328125 is a float32 exactly: back to the bit.
    np.testing.assert_array_equal(returns, [-1244.0167236328125, np.nan])
    (tmp_path / "iter_0002" / "policy.json").write_text("{}")
    with pytest.raises(IntegrityError):
        load_policies(tmp_path / "iter_0002")
