"""The offline family against its codebases' arithmetic, each number computed apart in NumPy:
every method's assembled policy loss (its coefficients, ILID's weighted term, the weight
decay), ILID's selection and weight d / (1 - d) from its discriminators' parameters, ILID's
union as its released code samples it (zero rows in the share its padded buffer gives), DWBC's
discriminator read at each evaluation, and the --ilid-union flag from the command line to
config.json, metrics.csv, the record and --resume."""

import csv
import dataclasses
import gzip
import json
import math
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax import envs
from pngail_jax.demos import Demonstrations, successor_rows
from pngail_jax.grid import make_cells, stack_cells
from pngail_jax.offline.family import OFFLINE
from pngail_jax.offline.ilid import (
    PROGRESS_REPORTS,
    RELEASED_UNION_PADDING,
    IlidSelection,
    released_zero_share,
    with_zero_rows,
)
from pngail_jax.offline.trainer import (
    OFFLINE_METHOD_NAMES,
    OfflineConfig,
    OfflineTrainer,
    offline_spec,
)

RNG = np.random.default_rng(7)
TINY = OfflineConfig(
    num_iterations=4, steps_per_iteration=10, eval_every=2, num_eval_episodes=2, batch_size=16,
    hidden_sizes=(16,), dwbc_discriminator_every=2, dwbc_branch_size=8, dwbc_hidden_size=16,
    ilid_hidden_sizes=(16,), ilid_rollback=3, ilid_discriminator_steps=20,
)  # fmt: skip


@pytest.fixture(scope="module")
def demos():
    from conftest import tiny_offline_demos

    return tiny_offline_demos()


def _trainer(demos, **changes) -> OfflineTrainer:
    return OfflineTrainer(dataclasses.replace(TINY, **changes), envs.make("Pendulum-v1"), demos)


# -- NumPy forward passes of the library's networks, written from their definitions ---------


def _dense(layer, x):
    return x @ np.asarray(layer["kernel"], np.float64) + np.asarray(layer["bias"], np.float64)


def _policy_log_density(params, batch, size=3):
    """float64[B, A]: the Gaussian policy (tanh MLP mean, state-independent log std)."""
    mlp, x = params["params"]["MLP_0"], np.asarray(batch[:, :size], np.float64)
    layers = [mlp[f"Dense_{i}"] for i in range(len(mlp))]
    for layer in layers[:-1]:
        x = np.tanh(_dense(layer, x))
    mean, log_std = _dense(layers[-1], x), np.asarray(params["params"]["log_std"], np.float64)
    z = (np.asarray(batch[:, size:], np.float64) - mean) * np.exp(-log_std)
    return -0.5 * z**2 - log_std - 0.5 * np.log(2 * np.pi)


def _clipped_sigmoid(logit):
    return np.clip(1 / (1 + np.exp(-logit)), 0.1, 0.9)


def _relu_logit(params, x):
    """float64[...]: ILID's discriminator (ReLU MLP, linear logit) before its clip."""
    layers = params["params"]
    x = np.asarray(x, np.float64)
    for i in range(len(layers) - 1):
        x = np.maximum(_dense(layers[f"Dense_{i}"], x), 0)
    return _dense(layers[f"Dense_{len(layers) - 1}"], x)[..., 0]


def _dwbc_d(params, rows, log_density):
    """float64[B]: DWBC's discriminator on rows and the log-density feature (clipped to
    [-20, 10], mapped to [0, 1])."""
    layers = params["params"]
    feature = (np.clip(log_density, -20, 10) + 20) / 30
    pairs = np.maximum(_dense(layers["Dense_0"], np.asarray(rows, np.float64)), 0)
    densities = np.maximum(_dense(layers["Dense_1"], feature), 0)
    hidden = np.maximum(_dense(layers["Dense_2"], np.concatenate([pairs, densities], -1)), 0)
    return _clipped_sigmoid(_dense(layers["Dense_3"], hidden)[..., 0])


# -- the assembled policy loss ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("method", "overrides"),
    [(name, {}) for name in OFFLINE_METHOD_NAMES]
    + [("bc-all", {  # every term at once, with a cut-off and a large weight decay
        "expert_bc_coef": 0.7, "union_bc_coef": 0.3, "dwbc_coef": 1.3, "iswbc_coef": 0.6,
        "ilid_coef": 0.9, "dwbc_alpha": 5.0, "dwbc_eta": 0.3, "iswbc_cutoff": 0.8,
        "policy_weight_decay": 0.2})],
)  # fmt: skip
def test_each_methods_policy_loss_against_numpy(demos, method, overrides):
    """L = c_E mean_E nll + c_U mean_U nll + c_DWBC (alpha mean_E nll - mean_E[w_E nll]
    + mean_O[w_O nll]) + c_ISW mean_U[1[w >= cut] w nll] + c_ILID (mean_{E+S}[w nll] +
    mean_S nll) + wd / 2 ||theta||^2, every batch, d and weight random, the policy's
    parameters random (log std too), by a NumPy forward pass."""
    trainer = _trainer(demos, components=("dwbc", "iswbc", "ilid"))
    spec = offline_spec(method, **overrides)
    params = trainer.policy.init(jax.random.key(0), jnp.zeros(3))
    params = jax.tree.map(lambda p: p + 0.3 * RNG.normal(size=p.shape).astype(np.float32), params)
    batch = 16
    expert, union, other, selected, ilid_union = (
        np.concatenate([RNG.normal(size=(batch, 3)), RNG.uniform(-2, 2, (batch, 1))], -1)
        .astype(np.float32) for _ in range(5)
    )  # fmt: skip
    d_expert, d_other = RNG.uniform(0.1, 0.9, (2, batch)).astype(np.float32)
    iswbc_weights = RNG.uniform(0.01, 3.0, batch).astype(np.float32)
    ilid_weights = RNG.uniform(1 / 9, 9, batch).astype(np.float32)
    fixed = {"dwbc": (d_expert, d_other), "iswbc_weights": iswbc_weights,
             "ilid": (selected, ilid_union, ilid_weights)}  # fmt: skip
    loss, _ = jax.jit(trainer.policy_loss)(spec, params, expert, union, other, fixed)

    def nll(rows):
        return -_policy_log_density(params, rows).sum(-1)

    c = {field.name: float(getattr(spec, field.name)) for field in dataclasses.fields(spec)}
    w_expert = c["dwbc_eta"] / (d_expert * (1.0 - d_expert)) + 1
    w_other = np.where(d_other >= 0.5, d_other / (1.0 - d_other), 0.0)
    kept = np.where(iswbc_weights >= c["iswbc_cutoff"], iswbc_weights, 0.0)
    squares = sum(np.sum(np.asarray(p, np.float64) ** 2) for p in jax.tree.leaves(params))
    expected = (
        c["expert_bc_coef"] * nll(expert).mean() + c["union_bc_coef"] * nll(union).mean()
        + c["dwbc_coef"] * (c["dwbc_alpha"] * nll(expert).mean()
                            - np.mean(w_expert * nll(expert)) + np.mean(w_other * nll(other)))
        + c["iswbc_coef"] * np.mean(kept * nll(union))
        + c["ilid_coef"] * (np.mean(ilid_weights * nll(ilid_union)) + nll(selected).mean())
        + 0.5 * c["policy_weight_decay"] * squares
    )  # fmt: skip
    np.testing.assert_allclose(loss, expected, rtol=2e-5)


# -- ILID's selection, its weights and its union -----------------------------------------


@pytest.mark.parametrize("union", ["intended", "released"])
def test_ilids_selection_and_weights_from_its_discriminators_against_numpy(union):
    """On random rows in 6 trajectories of 20: the selected rows are the other rows with an
    expert-like state (d(s) >= the bar) among their next K = 3; the weight of each row is
    d / (1 - d) of the clipped state-action discriminator; with the released union, the
    share of zero rows is 1e6 / (1e6 + |E| + |S|) and a zero row's weight d(0) / (1 - d(0))."""
    num_rows, size = 120, 3
    rows = np.concatenate(
        [RNG.normal(size=(num_rows, size)), RNG.uniform(-2, 2, (num_rows, 1))], -1
    ).astype(np.float32)
    rows[:30, :size] += 1.5  # the expert rows' states lie apart, so the state discriminator
    expert = np.zeros(num_rows, bool)  # finds expert-like states among the others' too
    expert[:30] = True
    rows[60:70, :size] += 1.5
    successors = successor_rows(np.repeat(np.arange(6), 20), 3)
    spec = offline_spec("ilid", ilid_discriminator_learning_rate=3e-2, ilid_bar=0.5)
    selection = IlidSelection((16,), 40, 32, union)
    fields, metrics, params = selection.select(
        spec, jnp.asarray(rows), jnp.asarray(rows[:, :size]), jnp.asarray(successors),
        jnp.asarray(expert), jnp.asarray(RNG.uniform(size=num_rows), jnp.float32),
        jax.random.key(1),
    )  # fmt: skip

    d_state = _clipped_sigmoid(_relu_logit(params["state"], rows[:, :size]))
    reach = np.where(successors >= 0, d_state[np.maximum(successors, 0)], 0.0)
    selected = ~expert & (reach >= 0.5).any(-1)
    # Rows whose decision rests within float rounding of the bar are not judged.
    sure = ~(np.abs(reach - 0.5) < 1e-5).any(-1)
    assert 0 < selected.sum() < (~expert).sum()
    got_selected = np.asarray(fields["ilid_selected_probability"]) > 0
    np.testing.assert_array_equal(got_selected[sure], selected[sure])
    assert metrics["ilid/num_selected"] == got_selected.sum()
    np.testing.assert_array_equal(np.asarray(fields["ilid_union_probability"]) > 0,
                                  expert | got_selected)  # fmt: skip
    d_pair = _clipped_sigmoid(_relu_logit(params["pair"], rows))
    np.testing.assert_allclose(fields["ilid_weight"], d_pair / (1 - d_pair), rtol=1e-5)
    if union == "intended":
        assert "ilid_zero_share" not in fields and "ilid/union_zero_share" not in metrics
        return
    num_union = (expert | got_selected).sum()
    np.testing.assert_allclose(fields["ilid_zero_share"], 1e6 / (1e6 + num_union), rtol=1e-6)
    assert metrics["ilid/union_zero_share"] == fields["ilid_zero_share"]
    d_zero = _clipped_sigmoid(_relu_logit(params["pair"], np.zeros(size + 1)))
    np.testing.assert_allclose(fields["ilid_zero_weight"], d_zero / (1 - d_zero), rtol=1e-5)


@pytest.mark.parametrize("steps", [250, 37])  # blocks of 2 and a remainder; of 1
def test_ilids_progress_reports_its_steps_and_changes_no_number(steps):
    """With ``progress`` set, both discriminators' training reports its steps (once for the
    grid's every cell, ``PROGRESS_REPORTS`` times each), and every output is bit for bit the
    one of the same steps in one loop; under jit(vmap), as a grid runs it."""
    num_rows, size = 60, 3
    rows = jnp.asarray(RNG.normal(size=(num_rows, size + 1)), jnp.float32)
    expert = jnp.arange(num_rows) < 20
    successors = jnp.asarray(successor_rows(np.repeat(np.arange(3), 20), 3))
    spec = offline_spec("ilid", ilid_discriminator_learning_rate=3e-2, ilid_bar=0.5)

    class OneLoop(IlidSelection):
        def _reporting_loop(self, step, carry, phase):
            return jax.lax.fori_loop(0, self.discriminator_steps, step, carry)

    def run(selection):
        def one(key):
            return selection.select(spec, rows, rows[:, :size], successors, expert,
                                    jnp.zeros(num_rows), key)  # fmt: skip

        return jax.jit(jax.vmap(one))(jax.random.split(jax.random.key(3), 2))

    reported = []
    reporting = IlidSelection((16,), steps, 16)
    reporting.progress = lambda done: reported.append(int(done))
    got, expected = run(reporting), run(OneLoop((16,), steps, 16))
    for made, wanted in zip(jax.tree.leaves(got), jax.tree.leaves(expected), strict=True):
        np.testing.assert_array_equal(made, wanted)
    every = max(1, steps // PROGRESS_REPORTS)
    blocks = [every * (block + 1) for block in range(steps // every)]
    assert sorted(reported) == blocks + [steps + done for done in blocks]


def test_the_released_zero_share_is_its_padded_buffers():
    """main.py:231 allocates 1,000,000 zero rows and 282-291 concatenate E and S onto them;
    sample() draws from range(size), size the whole length: 1e6 / (1e6 + |E| + |S|)."""
    assert RELEASED_UNION_PADDING == 1_000_000
    for rows in (0, 82, 1_000, 1_001_000):  # the last: the paper's 1 + 1,000 trajectories
        np.testing.assert_allclose(released_zero_share(rows), 1e6 / (1e6 + rows), rtol=1e-6)


@pytest.mark.parametrize("share", [0.05, 0.5, 1e6 / (1e6 + 300)])
def test_zero_rows_are_drawn_in_their_share(share):
    """Each of n = 400,000 rows becomes a zero row with probability ``share``, the rest
    untouched. Tolerance by Hoeffding's bound for a binomial share: P(|p_hat - p| >= t) <=
    2 exp(-2 n t^2), so t = sqrt(ln(2 / 1e-9) / (2 n)) = 0.0052 fails once in 1e9 runs."""
    n = 400_000
    rows = jnp.asarray(RNG.uniform(1, 2, (n, 4)), jnp.float32)
    padded, zero = jax.jit(with_zero_rows)(jax.random.key(5), rows, jnp.float32(share))
    padded, zero = np.asarray(padded), np.asarray(zero)
    tolerance = math.sqrt(math.log(2 / 1e-9) / (2 * n))
    assert abs(zero.mean() - share) < tolerance, (zero.mean(), share, tolerance)
    assert (padded[zero] == 0).all()
    np.testing.assert_array_equal(padded[~zero], np.asarray(rows)[~zero])


def test_the_released_union_changes_only_ilids_union(demos):
    """The trainer with ilid_union "released" against "intended", same key: the same state
    discriminator and selection, the zero share of its union stored and, over 4 x 10 steps x
    16 = 640 union draws, almost all zero rows: a real row is drawn with q = n / (1e6 + n)
    (n = |E| + |S|, a few dozen here), so the count X of real rows is binomial with
    E[X] = 640 q (below 0.1), and by the Chernoff bound P(X >= k) <= (e E[X] / k)^k the
    test allows X below the smallest k at which that bound is under 1e-6."""
    cells = make_cells(["ilid"], 1)
    inputs = jax.tree.map(lambda x: x[0], stack_cells(cells, jax.random.key(2), family=OFFLINE))
    trainers = {union: _trainer(demos, components=("ilid",), ilid_union=union)
                for union in ("intended", "released")}  # fmt: skip
    results = {union: jax.jit(trainer.train)(*inputs) for union, trainer in trainers.items()}
    (intended, intended_metrics), (released, metrics) = results["intended"], results["released"]
    np.testing.assert_array_equal(released.ilid_selected_probability,
                                  intended.ilid_selected_probability)  # fmt: skip
    num_union = int((np.asarray(released.ilid_union_probability) > 0).sum())
    np.testing.assert_allclose(released.ilid_zero_share, 1e6 / (1e6 + num_union), rtol=1e-6)
    assert intended.ilid_zero_share is None and "ilid/union_zero_rows" not in intended_metrics
    draws = TINY.num_iterations * TINY.steps_per_iteration * TINY.batch_size
    real_rows = round(draws * (1 - float(np.mean(metrics["ilid/union_zero_rows"]))))
    expected = draws * num_union / (1e6 + num_union)
    bound = next(k for k in range(1, draws) if (math.e * expected / k) ** k < 1e-6)
    assert real_rows < bound, (real_rows, expected, bound)
    assert 1 / 9 - 1e-6 <= float(released.ilid_zero_weight) <= 9 + 1e-5
    # A step's union batch at a zero share of one half: each zero row (all of it zero) weighs
    # the zero row's weight (here a stand-in, 123), each real row a union row's d / (1 - d).
    halved = released.replace(ilid_zero_share=jnp.float32(0.5), ilid_zero_weight=jnp.float32(123))
    (_, rows, weights), step_metrics = jax.jit(trainers["released"].ilid_batches)(
        halved, jax.random.key(9)
    )
    zero = (np.asarray(rows) == 0).all(-1)
    assert 0 < zero.sum() < len(zero) and step_metrics["ilid/union_zero_rows"] == zero.mean()
    assert (np.asarray(weights)[zero] == 123).all()
    union_weights = np.asarray(released.ilid_weight)[
        np.asarray(released.ilid_union_probability) > 0
    ]
    assert np.isin(np.asarray(weights)[~zero], union_weights).all()


# -- DWBC's discriminator at each evaluation ----------------------------------------------


def test_dwbcs_evaluation_metrics_against_numpy(demos):
    """At each evaluation, DWBC's d on every split row (with the policy's log-density
    feature) averaged over E and over O, and its BC weights' means (an expert row's net
    alpha - w_E, an other row's w_O); NaN between evaluations; the last against a NumPy
    computation from the final state's networks."""
    trainer = _trainer(demos, components=("dwbc",))
    cells = make_cells(["dwbc"], 1)
    inputs = jax.tree.map(lambda x: x[0], stack_cells(cells, jax.random.key(4), family=OFFLINE))
    state, metrics = jax.jit(trainer.train)(*inputs)
    metrics = {name: np.asarray(value) for name, value in metrics.items()}
    names = ["dwbc/eval_d_expert", "dwbc/eval_d_other", "dwbc/eval_weight_expert",
             "dwbc/eval_weight_other"]  # fmt: skip
    for name in names:  # evaluations at iterations 2 and 4
        assert np.isnan(metrics[name][[0, 2]]).all() and np.isfinite(metrics[name][[1, 3]]).all()

    normalizer = state.normalizer
    std = np.sqrt(np.asarray(normalizer.sum_squares) / max(float(normalizer.count), 1)) + 1e-8
    raw = demos.inputs[np.asarray(state.demo_rows)]
    rows = np.concatenate([np.clip((raw[:, :3] - np.asarray(normalizer.mean)) / std, -10, 10),
                           np.clip(raw[:, 3:], -2, 2)], -1)  # fmt: skip
    d = _dwbc_d(state.dwbc_params, rows, _policy_log_density(state.policy_params, rows))
    expert = np.asarray(state.expert_probability) > 0
    assert 0 < expert.sum() < len(expert)
    alpha, eta = float(inputs[1].dwbc_alpha), float(inputs[1].dwbc_eta)  # 7.5, 0.5
    expected = {
        "dwbc/eval_d_expert": d[expert].mean(),
        "dwbc/eval_d_other": d[~expert].mean(),
        "dwbc/eval_weight_expert": np.mean(alpha - eta / (d[expert] * (1 - d[expert])) - 1),
        "dwbc/eval_weight_other": np.mean(np.where(d[~expert] >= 0.5,
                                                   d[~expert] / (1 - d[~expert]), 0.0)),
    }  # fmt: skip
    for name in names:
        np.testing.assert_allclose(metrics[name][-1], expected[name], rtol=1e-4, err_msg=name)


# -- the command line: --ilid-union, metrics.csv, the record, --resume -------------------------


def five_trajectories(path):
    """A made Pendulum set of 5 trajectories of 20 rows (one at confidence 1) at ``path``."""
    from pngail_jax.demos import save_npz

    rng = np.random.default_rng(0)
    save_npz(path, Demonstrations(
        observations=rng.normal(size=(100, 3)).astype(np.float32),
        actions=rng.uniform(-2, 2, size=(100, 1)).astype(np.float32),
        confidence=np.repeat([1.0, 0.4, 0.45, 0.5, 0.35], 20).astype(np.float32),
        trajectory_ids=np.repeat(np.arange(5), 20),
        metadata={"env": "Pendulum-v1", "random_return": -1200.0, "optimal_return": -150.0},
    ))  # fmt: skip
    return path


def test_an_ilid_run_cut_before_its_first_chunk_resumes_after_its_discriminators(
    tmp_path, capsys, monkeypatch
):
    """ILID's discriminators train before its first chunk (an hour at its codebase's budget
    on a 2-core CPU); the start is saved at once (chunk_0000), so a run cut before its first
    chunk ends resumes from there without training them again, to the uninterrupted run's
    evaluations and selection, bit for bit."""
    from pngail_jax.jobs import offline as job
    from pngail_jax.programs import offline as program

    argv = [
        "--demos", str(five_trajectories(tmp_path / "demos.npz")), "--methods", "ilid",
        "--seeds", "2", "--gradient-steps", "40", "--steps-per-iteration", "10",
        "--eval-every", "2", "--chunk-iterations", "2", "--batch-size", "8",
        "--ilid-discriminator-steps", "50",
    ]  # fmt: skip
    program.main([*argv, "--out", str(tmp_path / "whole")])
    cut = tmp_path / "cut"
    with monkeypatch.context() as patched:

        def stopped(*args, **kwargs):  # a Ctrl-C as the first chunk runs
            raise KeyboardInterrupt

        patched.setattr(job, "run_chunks", stopped)
        with pytest.raises(SystemExit, match="--resume"):
            program.main([*argv, "--out", str(cut)])
    assert [c.name for c in (cut / "checkpoints" / "ilid").iterdir()] == ["chunk_0000"]
    capsys.readouterr()
    program.main(["--resume", str(cut)])
    said = capsys.readouterr().out
    assert f"resumed from {cut / 'checkpoints' / 'ilid' / 'chunk_0000'}" in said
    assert "ILID's two discriminators" not in said

    def rows(run):
        with (run / "metrics.csv").open() as file:
            rows = list(csv.DictReader(file))
        return [{k: v for k, v in row.items() if k != "wall_seconds"} for row in rows]

    assert rows(cut) == rows(tmp_path / "whole")
    assert (
        json.loads((cut / "summary.json").read_text())["ilid"]
        == (json.loads((tmp_path / "whole" / "summary.json").read_text())["ilid"])
    )


def test_the_ilid_union_flag_reaches_config_metrics_record_and_resume(tmp_path, capsys):
    """--ilid-union released is written in config.json (the run's settings and its trainer's)
    and read back by --resume; DWBC's evaluation columns are in metrics.csv and its record,
    filled at the evaluations of DWBC's rows only; a bad value is one line naming the flag."""
    from pngail_jax.analysis.run_records import write_record
    from pngail_jax.jobs.offline import OfflineRunConfig, load_offline_config
    from pngail_jax.programs import offline as program

    path = five_trajectories(tmp_path / "demos.npz")
    out = tmp_path / "run"
    argv = [
        "--demos", str(path), "--methods", "dwbc,ilid", "--seeds", "1", "--gradient-steps",
        "40", "--steps-per-iteration", "10", "--eval-every", "2", "--chunk-iterations", "2",
        "--batch-size", "8", "--ilid-discriminator-steps", "5", "--ilid-union", "released",
        "--out", str(out),
    ]  # fmt: skip
    with pytest.raises(SystemExit, match="^2$"):
        program.parse_args([*argv[:-2], "--ilid-union", "padded", "--out", str(tmp_path / "x")])
    error = capsys.readouterr().err
    assert "argument --ilid-union: invalid choice: 'padded' (choose from " in error
    assert error.count("\n") == 1
    with pytest.raises(ValueError, match="^ilid_union must be one of intended, released, got 'x'$"):
        OfflineRunConfig(ilid_union="x")
    with pytest.raises(ValueError, match="OfflineConfig.ilid_union must be one of"):
        dataclasses.replace(TINY, ilid_union="padded")

    summary = program.main(argv)
    document = json.loads((out / "config.json").read_text())
    assert document["config"]["ilid_union"] == "released"
    assert document["resolved"]["trainer"]["ilid_union"] == "released"
    assert load_offline_config(out).ilid_union == "released"
    assert summary["ilid"]["union_zero_share"] > 0.999
    assert "of its draws are zero rows" in (out / "summary.md").read_text()
    columns = ["dwbc_d_expert", "dwbc_d_other", "dwbc_weight_expert", "dwbc_weight_other"]
    with (out / "metrics.csv").open() as file:
        rows = list(csv.DictReader(file))
    for row in rows:
        filled = row["method"] == "dwbc" and row["iteration"] in ("2", "4")
        assert all(bool(row[column]) == filled for column in columns), row
    record = write_record(out, "tiny-ilid-released", tmp_path / "records")
    with gzip.open(record / "metrics.csv.gz", "rt") as file:
        assert set(columns) <= set(next(csv.reader(file)))

    for group in ("dwbc", "ilid"):  # the last chunk lost: --resume reads the union back
        shutil.rmtree(sorted((out / "checkpoints" / group).glob("chunk_*"))[-1])
    capsys.readouterr()
    resumed = program.main(["--resume", str(out)])
    assert resumed["ilid"]["union_zero_share"] == summary["ilid"]["union_zero_share"]
    with (out / "metrics.csv").open() as file:
        assert [r["dwbc_d_expert"] for r in csv.DictReader(file)] == [
            r["dwbc_d_expert"] for r in rows
        ]


def test_a_run_resumed_from_before_a_metric_existed_gets_nan_for_its_earlier_chunks():
    """A DWBC run checkpointed before its evaluation metrics existed resumes: the chunk joined
    after it has them, the chunks before are NaN there (metrics.csv leaves them empty)."""
    from pngail_jax.jobs.chunks import Progress

    progress = Progress(1, {}, {"eval/return": np.ones((2, 3))}, {"seconds": 0.0, "steps": 0})
    progress.add({"eval/return": np.zeros((2, 3)), "dwbc/eval_d_expert": np.full((2, 3), 0.5)},
                 1.0, 10)  # fmt: skip
    np.testing.assert_array_equal(progress.metrics["eval/return"], [[1, 1, 1, 0, 0, 0]] * 2)
    np.testing.assert_array_equal(
        progress.metrics["dwbc/eval_d_expert"], [[np.nan] * 3 + [0.5] * 3] * 2
    )


def test_dwbc_discriminator_updates_set_its_cadence_and_bad_values_are_one_line(tmp_path, capsys):
    """--dwbc-discriminator-updates N spaces N Adam steps of DWBC's discriminator over the
    run (every gradient_steps / N-th step: its codebase's 5,000 of 500,000 are every 100th,
    5,000 of 50,000 every 10th, the default); every-100 (None) gives every 100th step, as
    runs did before, and a config.json from before the field loads that way; a count of at
    least the steps is one a step; a count that does not divide the steps is one line."""
    from pngail_jax.jobs.offline import OfflineRunConfig
    from pngail_jax.programs import offline as program

    assert OfflineRunConfig().dwbc_discriminator_updates == 5000
    assert OfflineRunConfig().dwbc_discriminator_every == 10  # the codebase's 5,000 updates
    assert OfflineRunConfig().trainer_config(1000).dwbc_discriminator_every == 10
    assert OfflineRunConfig(gradient_steps=500_000).dwbc_discriminator_every == 100
    assert OfflineRunConfig(gradient_steps=1000, steps_per_iteration=100, eval_every=1,
                            ).dwbc_discriminator_every == 1  # fmt: skip
    former = OfflineRunConfig(dwbc_discriminator_updates=None)
    assert former.trainer_config(1000).dwbc_discriminator_every == 100  # 500 at 50,000
    argv = ["--demos", "data/released/Pendulum-v1_mixture.npy", "--gradient-steps", "40000"]
    for flag, every in (("4000", 10), ("every-100", 100), ("40000", 1), ("90000", 1)):
        args = program.parse_args([*argv, "--dwbc-discriminator-updates", flag,
                                   "--out", str(tmp_path / "a")])  # fmt: skip
        assert args.config.dwbc_discriminator_every == every, flag
    for flag in ("3000", "many"):
        with pytest.raises(SystemExit, match="^2$"):
            program.parse_args([*argv, "--dwbc-discriminator-updates", flag,
                                "--out", str(tmp_path / "b")])  # fmt: skip
        error = capsys.readouterr().err
        assert "--dwbc-discriminator-updates must be a positive integer that divides" in error
        assert f"got {flag if flag.isdigit() else repr(flag)}" in error
        assert error.count("\n") == 1


def test_an_offline_config_json_from_before_the_dwbc_default_resumes_as_it_ran(tmp_path):
    """A run's config.json written before 5,000 updates became DWBC's default (without the
    field) resumes at the cadence it began with, every 100th step, not today's default."""
    from pngail_jax.analysis.runs import run_document
    from pngail_jax.jobs.offline_config import load_offline_config, offline_defaults
    from pngail_jax.storage.integrity import write_json

    fields = offline_defaults()
    assert fields["dwbc_discriminator_updates"] is None  # what such a record ran with
    del fields["dwbc_discriminator_updates"]
    write_json(tmp_path / "config.json", run_document("offline", fields, {}, {}))
    assert load_offline_config(tmp_path).dwbc_discriminator_every == 100
