"""Every preset's discriminator loss against a NumPy transcription of its REFERENCE.md row."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from pngail_jax.adversarial.losses import ConfidenceStats, discriminator_loss, policy_reward
from pngail_jax.adversarial.methods import METHOD_NAMES, PRESETS, method_spec, stack
from pngail_jax.networks import Discriminator


def sp(x):
    return np.logaddexp(0.0, x)


def masked_mean(values, mask):
    return values[mask].mean()


# NumPy transcriptions of ../shared/REFERENCE.md, "Discriminator objectives".
def reference_loss(name, za, zd, r, labelled, w, mean_r, mean_rc):
    agent = sp(-za).mean()
    if name == "gail":
        return agent + sp(zd).mean()
    if name in ("2iwil", "pngail-no-pn"):
        return agent + (r / mean_r * sp(zd)).mean()
    if name in ("pngail", "pngail-no-bsc"):
        return agent + (r * sp(zd) + (1 - r) * sp(-zd)).mean()
    if name == "icgail":
        z_prior = max(mean_rc, 0.7)
        return (
            z_prior * agent
            + (1 - z_prior) / (1 - mean_rc) * masked_mean((1 - r) * sp(-zd), labelled)
            + masked_mean(sp(zd), ~labelled)
        )
    if name == "wgail":
        return agent + (w * sp(zd)).mean()
    raise AssertionError(name)


def random_batch(seed, num_agent=64, num_demo=48):
    rng = np.random.default_rng(seed)
    za = rng.normal(0, 2, num_agent).astype(np.float32)
    zd = rng.normal(0, 2, num_demo).astype(np.float32)
    r = rng.uniform(0, 1, num_demo).astype(np.float32)
    labelled = rng.uniform(size=num_demo) < 0.3
    w = rng.uniform(0.1, 2, num_demo).astype(np.float32)
    mean_r = float(rng.uniform(0.3, 0.8))  # a split-wide mean, not the batch's
    mean_rc = float(rng.uniform(0.3, 0.9))
    return za, zd, r, labelled, w, mean_r, mean_rc


def library_loss(name, za, zd, r, labelled, w, mean_r, mean_rc):
    stats = ConfidenceStats(jnp.float32(mean_r), jnp.float32(mean_rc))
    loss, _ = jax.jit(discriminator_loss)(method_spec(name), za, zd, r, labelled, w, stats)
    return float(loss)


@pytest.mark.parametrize("name", METHOD_NAMES)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_preset_matches_reference_row(name, seed):
    batch = random_batch(seed)
    expected = reference_loss(name, *batch)
    np.testing.assert_allclose(library_loss(name, *batch), expected, rtol=1e-5)


def test_icgail_uses_the_floor_and_the_labelled_mean():
    # mean r_c = 0.9 > 0.7: Z = 0.9 and the labelled term's coefficient is 0.1 / 0.1 = 1.
    za, zd, r, labelled, w, mean_r, _ = random_batch(5)
    expected = reference_loss("icgail", za, zd, r, labelled, w, mean_r, 0.9)
    np.testing.assert_allclose(
        library_loss("icgail", za, zd, r, labelled, w, mean_r, 0.9), expected, rtol=1e-5
    )
    # Every labelled row certain: Z = 1, the labelled term vanishes (no 0 / 0).
    got = library_loss("icgail", za, zd, r, labelled, w, mean_r, 1.0)
    np.testing.assert_allclose(got, sp(-za).mean() + sp(zd)[~labelled].mean(), rtol=1e-5)


def test_reductions_to_gail():
    za, zd, r, labelled, w, mean_r, mean_rc = random_batch(7)
    gail = library_loss("gail", za, zd, r, labelled, w, mean_r, mean_rc)
    ones = np.ones_like(r)
    # PN-GAIL with every r = 1 is GAIL.
    np.testing.assert_allclose(
        library_loss("pngail", za, zd, ones, labelled, w, mean_r, mean_rc), gail, rtol=1e-6
    )
    # 2IWIL with a constant r (so mean(r) = r) is GAIL.
    constant = np.full_like(r, 0.37)
    np.testing.assert_allclose(
        library_loss("2iwil", za, zd, constant, labelled, w, 0.37, mean_rc), gail, rtol=1e-6
    )
    # WGAIL with w = 1 (its value before the first refresh) is GAIL.
    np.testing.assert_allclose(
        library_loss("wgail", za, zd, r, labelled, ones, mean_r, mean_rc), gail, rtol=1e-6
    )


def test_pn_gradient_matches_hand_derivative():
    # d/dz_d of mean[r sp(z) + (1-r) sp(-z)] = [r sigmoid(z) - (1-r) sigmoid(-z)] / B;
    # d/dz_a of mean sp(-z) = -sigmoid(-z) / N.
    za, zd, r, labelled, w, mean_r, mean_rc = random_batch(3)
    stats = ConfidenceStats(jnp.float32(mean_r), jnp.float32(mean_rc))
    spec = method_spec("pngail")

    def loss(za, zd):
        return discriminator_loss(spec, za, zd, r, labelled, w, stats)[0]

    grad_a, grad_d = jax.grad(loss, argnums=(0, 1))(za, zd)
    sigmoid = lambda x: 1 / (1 + np.exp(-x))  # noqa: E731
    np.testing.assert_allclose(grad_a, -sigmoid(-za) / len(za), rtol=1e-5, atol=1e-8)
    np.testing.assert_allclose(
        grad_d, (r * sigmoid(zd) - (1 - r) * sigmoid(-zd)) / len(zd), rtol=1e-5, atol=1e-8
    )


def test_methods_vmap_as_data():
    batch = random_batch(11)
    za, zd, r, labelled, w, mean_r, mean_rc = batch
    stats = ConfidenceStats(jnp.float32(mean_r), jnp.float32(mean_rc))
    specs = stack([method_spec(name) for name in METHOD_NAMES])
    losses, metrics = jax.jit(
        jax.vmap(discriminator_loss, in_axes=(0, None, None, None, None, None, None))
    )(specs, za, zd, r, labelled, w, stats)
    expected = [reference_loss(name, *batch) for name in METHOD_NAMES]
    np.testing.assert_allclose(losses, expected, rtol=1e-5)
    np.testing.assert_allclose(metrics["disc/acc_agent"], np.mean(za > 0))


def test_policy_reward_is_minus_log_sigmoid():
    z = np.linspace(-8, 8, 33, dtype=np.float32)
    expected = -np.log(1 / (1 + np.exp(-z.astype(np.float64))))
    np.testing.assert_allclose(policy_reward(z), expected, rtol=1e-5)


def test_unknown_method_and_field_are_named():
    with pytest.raises(ValueError, match="unknown method 'pu-gail'"):
        method_spec("pu-gail")
    with pytest.raises(ValueError, match="unknown MethodSpec field"):
        method_spec("gail", temperature=1.0)
    sources = {p.confidence_source for p in PRESETS.values()}
    assert sources == {"none", "given", "sc", "bsc", "rankings"}


def test_theorem_4_3_optimal_discriminator():
    """A discriminator trained to convergence on the PN objective reaches
    D*(x) = ((1 - r) p + p_theta) / (p + p_theta) on a 5-state discrete problem.

    Batches list each state in proportion to its probability (multiples of 1/20), so the
    batch means are the population expectations exactly.
    """
    p = np.array([6, 5, 4, 3, 2]) / 20  # demonstrations
    p_theta = np.array([1, 3, 4, 5, 7]) / 20  # agent
    r = np.array([0.9, 0.1, 0.5, 0.75, 0.3], np.float32)  # confidence per state
    states = np.eye(5, dtype=np.float32)
    agent_x = np.repeat(states, (p_theta * 20).astype(int), axis=0)
    demo_index = np.repeat(np.arange(5), (p * 20).astype(int))
    demo_x, demo_r = states[demo_index], r[demo_index]
    spec = method_spec("pngail")
    stats = ConfidenceStats(jnp.float32(demo_r.mean()), jnp.float32(1.0))
    model = Discriminator((16,))
    params = model.init(jax.random.key(0), states[0])
    optimizer = optax.adam(0.02)

    def loss(params):
        za, zd = model.apply(params, agent_x), model.apply(params, demo_x)
        ones = jnp.ones_like(zd)
        return discriminator_loss(spec, za, zd, demo_r, ones > 0, ones, stats)[0]

    @jax.jit
    def train(params):
        def step(carry, _):
            params, state = carry
            updates, state = optimizer.update(jax.grad(loss)(params), state)
            return (optax.apply_updates(params, updates), state), None

        return jax.lax.scan(step, (params, optimizer.init(params)), length=4000)[0][0]

    d_learned = jax.nn.sigmoid(model.apply(train(params), states))
    d_star = ((1 - r) * p + p_theta) / (p + p_theta)
    np.testing.assert_allclose(d_learned, d_star, atol=2e-3)
    # The learned reward -log D stays within -log(1 - r) (REFERENCE.md), up to the tolerance.
    assert np.all(-np.log(d_learned) <= -np.log(1 - r) + 5e-3)


def reference_nnpu(prior, labelled_own, labelled_other, unlabelled_other):
    """Kiryo et al.'s non-negative PU risk, written from its definition."""
    return prior * labelled_own + max(0.0, unlabelled_other - prior * labelled_other)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("prior", [0.2, 0.5, 0.9])
def test_the_pu_risks_match_their_definitions(seed, prior):
    """PU-GAIL's (demonstrations labelled expert, sp(z); the agent's rows unlabelled) and
    UID's (the agent's rows labelled agent, sp(-z); the demonstrations unlabelled), each on
    its own and with another method's terms added."""
    za, zd, r, labelled, w, mean_r, mean_rc = random_batch(seed)
    za = za + (seed - 1.5)  # some batches clip the max, some do not
    stats = ConfidenceStats(jnp.float32(mean_r), jnp.float32(mean_rc))
    pu_gail = reference_nnpu(prior, sp(zd).mean(), sp(-zd).mean(), sp(-za).mean())
    uid = reference_nnpu(prior, sp(-za).mean(), sp(za).mean(), sp(zd).mean())
    loss = jax.jit(discriminator_loss)
    for overrides, expected in [
        ({"pu_coef": 1.0, "pu_prior": prior}, pu_gail),
        ({"pu_agent_coef": 1.0, "pu_agent_prior": prior}, uid),
        ({"agent_coef": 1.0, "gail_coef": 1.0, "pu_coef": 0.5, "pu_prior": prior},
         reference_loss("gail", za, zd, r, labelled, w, mean_r, mean_rc) + 0.5 * pu_gail),
    ]:  # fmt: skip
        spec = method_spec("gail", **{"agent_coef": 0.0, "gail_coef": 0.0, **overrides})
        value, _ = loss(spec, za, zd, r, labelled, w, stats)
        np.testing.assert_allclose(float(value), expected, rtol=1e-5)


def test_the_pu_risks_max_stops_the_gradient_of_a_negative_estimate():
    """Where the unlabelled rows' estimate is below 0, only the labelled term moves z."""
    spec = method_spec("gail", agent_coef=0.0, gail_coef=0.0, pu_coef=1.0, pu_prior=0.9)
    # mean_agent sp(-z) - 0.9 mean_demo sp(-z) = sp(-6) - 0.9 sp(6) < 0
    za, zd = jnp.full(8, 6.0), jnp.full(8, -6.0)
    ones = jnp.ones(8)
    stats = ConfidenceStats(jnp.float32(0.5), jnp.float32(0.5))

    def loss(za, zd):
        return discriminator_loss(spec, za, zd, ones, ones > 0, ones, stats)[0]

    grad_agent, grad_demo = jax.grad(loss, argnums=(0, 1))(za, zd)
    np.testing.assert_array_equal(grad_agent, 0.0)
    # d/dz of 0.9 mean sp(z) at z = -6: 0.9 sigmoid(-6) / 8 per row
    np.testing.assert_allclose(grad_demo, 0.9 * jax.nn.sigmoid(-6.0) / 8, rtol=1e-5)


# -- remedies for a saturating PN discriminator (MethodSpec fields beyond the paper) ----------


@pytest.mark.parametrize("negative", [0.0, 0.4, 1.0])
@pytest.mark.parametrize("balanced", [0.0, 1.0, 0.5])
def test_pn_negative_weight_and_class_balance_against_numpy(negative, balanced):
    """PN-GAIL with the negative term weighted by lambda and the classes balanced (b = 1):
    the positive side r sp(z) over the split's mean r m, the negative side (agent term and
    lambda (1 - r) sp(-z)) over its total 1 + lambda (1 - m); b blends the factors in."""
    za, zd, r, labelled, w, mean_r, mean_rc = random_batch(13)
    stats = ConfidenceStats(jnp.float32(mean_r), jnp.float32(mean_rc))
    spec = method_spec("pngail", pn_negative_coef=negative, pn_balanced_coef=balanced)
    loss, _ = jax.jit(discriminator_loss)(spec, za, zd, r, labelled, w, stats)
    positive = (1 - balanced) + balanced / mean_r
    negative_side = (1 - balanced) + balanced / (1 + negative * (1 - mean_r))
    expected = (
        negative_side * sp(-za).mean()
        + (positive * r * sp(zd) + negative_side * negative * (1 - r) * sp(-zd)).mean()
    )
    np.testing.assert_allclose(float(loss), expected, rtol=1e-5)
    if balanced == 1.0:  # each side's weight over the split is 1: positive m / m, negative
        np.testing.assert_allclose(positive * mean_r, 1.0, rtol=1e-6)
        np.testing.assert_allclose(negative_side * (1 + negative * (1 - mean_r)), 1.0, rtol=1e-6)


def test_pn_without_its_negative_term_is_2iwils_loss_up_to_the_demo_terms_scale():
    """lambda = 0 leaves agent sp(-z) + mean r sp(z); balanced, r sp(z) / m: 2IWIL's loss."""
    batch = random_batch(17)
    za, zd, r, labelled, w, mean_r, mean_rc = batch
    stats = ConfidenceStats(jnp.float32(mean_r), jnp.float32(mean_rc))
    spec = method_spec("pngail", pn_negative_coef=0.0, pn_balanced_coef=1.0)
    loss, _ = discriminator_loss(spec, za, zd, r, labelled, w, stats)
    np.testing.assert_allclose(float(loss), reference_loss("2iwil", *batch), rtol=1e-5)


def test_remedy_defaults_keep_every_preset_bit_for_bit():
    """The defaults (lambda = 1, b = 0, no logit reward) leave every preset's loss its
    NumPy formula and the reward sp(-z) to the bit. (That the seven's runs are the same
    floats as before these fields existed was checked on whole sweeps, docs/results.md.)"""
    za, zd, r, labelled, w, mean_r, mean_rc = random_batch(19)
    stats = ConfidenceStats(jnp.float32(mean_r), jnp.float32(mean_rc))
    for name in METHOD_NAMES:
        plain = method_spec(name)
        assert float(plain.pn_negative_coef) == 1.0 and float(plain.pn_balanced_coef) == 0.0
        loss, _ = discriminator_loss(plain, za, zd, r, labelled, w, stats)
        eq11 = reference_loss(name, za, zd, r, labelled, w, mean_r, mean_rc)
        np.testing.assert_allclose(float(loss), eq11, rtol=1e-5)
    z = np.linspace(-8, 8, 33, dtype=np.float32)
    np.testing.assert_array_equal(policy_reward(z, 0.0), jax.nn.softplus(-z))


def test_logit_reward_against_numpy():
    """sp(-z) - c sp(z): c = 1 is the logit -z, which keeps ranking pairs where sp(-z) has
    vanished (z = 8 and z = 12 differ by 4 in -z, by 3e-4 in sp(-z))."""
    z = np.linspace(-12, 12, 49, dtype=np.float32)
    for c in (0.0, 0.5, 1.0):
        np.testing.assert_allclose(
            policy_reward(z, c), sp(-z.astype(np.float64)) - c * sp(z.astype(np.float64)),
            rtol=1e-5, atol=1e-5,
        )  # fmt: skip
    np.testing.assert_allclose(policy_reward(z, 1.0), -z, atol=1e-5)


def test_remedy_coefficients_are_checked():
    from pngail_jax.adversarial.methods import Preset, check_preset

    base = dict(PRESETS["pngail"].coefficients)
    for field, bad in (
        ("pn_negative_coef", -0.1), ("logit_reward_coef", -1.0),
        ("gradient_penalty_coef", -2.0), ("pn_balanced_coef", 1.5),
    ):  # fmt: skip
        with pytest.raises(ValueError, match=field):
            check_preset("bad", Preset("bad", "bsc", {**base, field: bad}))
