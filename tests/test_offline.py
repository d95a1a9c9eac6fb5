"""The offline trainer (pngail_jax.offline.trainer): the expert set it builds from the split,
vmapped equals one at a time, the same key the same bits, a cell's numbers independent of the parts
its grid compiles for other methods, the discriminator schedules, and bad configs refused."""

import csv
import dataclasses
import json
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax import envs
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.demos import make_split
from pngail_jax.grid import make_cells, stack_cells
from pngail_jax.offline.family import OFFLINE
from pngail_jax.offline.trainer import (
    OFFLINE_METHOD_NAMES,
    OfflineConfig,
    OfflineTrainer,
    offline_spec,
    program_groups,
    required_components,
)
from pngail_jax.storage import outputs

TINY = OfflineConfig(
    num_iterations=4,
    steps_per_iteration=10,
    eval_every=2,
    num_eval_episodes=2,
    batch_size=16,
    hidden_sizes=(16,),
    dwbc_discriminator_every=5,
    dwbc_branch_size=8,
    dwbc_hidden_size=16,
    iswbc_hidden_sizes=(16,),
    ilid_hidden_sizes=(16,),
    ilid_rollback=3,
    ilid_discriminator_steps=10,
    classifier=ClassifierConfig(num_steps=20),
    components=("dwbc", "iswbc", "ilid", "classifier"),
)
METHODS = (*OFFLINE_METHOD_NAMES, "dwbc+bsc")


@pytest.fixture(scope="module")
def demos():
    from conftest import tiny_offline_demos

    return tiny_offline_demos()


@pytest.fixture(scope="module")
def trainer(demos):
    return OfflineTrainer(TINY, envs.make("Pendulum-v1"), demos)


@pytest.fixture(scope="module")
def grid_run(trainer):
    """Every method x 2 seeds, and a last cell of BC on every row that stops learning after 20
    gradient steps, in one vmapped program: (cells, inputs, start state, final state,
    metrics, the compiled init and blocks)."""
    cells = make_cells(METHODS, 2)
    hyperparams, specs, keys = stack_cells([*cells, cells[2]], jax.random.key(3), family=OFFLINE)
    short = offline_spec(cells[2].method, num_gradient_steps=20.0)
    specs = jax.tree.map(lambda stacked, one: stacked.at[-1].set(one), specs, short)
    inputs = (hyperparams, specs, keys)
    init = jax.jit(jax.vmap(trainer.init))
    blocks = jax.jit(
        jax.vmap(lambda h, s, state: trainer.run_blocks(h, s, state, TINY.num_evaluations))
    )
    start, init_metrics = init(*inputs)
    state, metrics = blocks(hyperparams, specs, start)
    return cells, inputs, start, state, {**metrics, **init_metrics}, (init, blocks)


def _cell(inputs, index):
    return jax.tree.map(lambda x: x[index], inputs)


def _assert_close(params, other) -> None:
    """Two policies' parameters equal to float rounding (1e-4 relative)."""
    for got, want in zip(jax.tree.leaves(params), jax.tree.leaves(other), strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5)


def test_expert_set_is_the_labelled_rows_at_confidence_at_least_one_half(demos, grid_run):
    cells, inputs, _, state, metrics, _ = grid_run
    for index, cell in enumerate(cells):
        if cell.method.endswith("+bsc"):
            continue
        hyperparams, _, key = _cell(inputs, index)
        split_key = jax.random.split(key, 7)[0]
        split = make_split(split_key, jnp.asarray(demos.confidence), 200, 0.2)
        expected = np.asarray(split.labelled & (split.confidence >= 0.5))
        assert metrics["offline/num_expert"][index] == expected.sum() > 0
        probability = np.asarray(state.expert_probability[index])
        np.testing.assert_allclose(probability[expected], 1 / expected.sum(), rtol=1e-6)
        assert (probability[~expected] == 0).all()
        assert (np.asarray(state.other_probability[index])[expected] == 0).all()
        assert metrics["offline/expert_true_confidence"][index] >= 0.7


def test_classified_rows_join_the_expert_set_and_the_classifier_is_measured(grid_run):
    cells, _, _, _, metrics, _ = grid_run
    num_expert = dict(zip(cells, np.asarray(metrics["offline/num_expert"]), strict=False))
    mae = dict(zip(cells, np.asarray(metrics["confidence/mae"]), strict=False))  # not the last
    for seed in range(2):
        plain, classified = (
            next(c for c in cells if c.method == name and c.seed == seed)
            for name in ("dwbc", "dwbc+bsc")
        )
        assert num_expert[classified] > num_expert[plain]
        assert np.isnan(mae[plain]) and 0 <= mae[classified] < 1


def test_a_grid_equals_its_cells_run_one_at_a_time(trainer, grid_run):
    """vmap invariance: each cell alone (jit, no vmap) gives its grid row's returns and
    final policy to float rounding (1e-5 relative)."""
    cells, inputs, _, state, metrics, _ = grid_run
    train = jax.jit(trainer.train)
    ilid = next(i for i, c in enumerate(cells) if c.method == "ilid")
    for index in (0, 2, 3, 4, ilid):
        alone_state, alone_metrics = train(*_cell(inputs, index))
        np.testing.assert_allclose(
            alone_metrics["eval/return"], metrics["eval/return"][index], rtol=1e-5, atol=1e-3
        )
        _assert_close(alone_state.policy_params, _cell(state.policy_params, index))


def test_the_same_key_gives_the_same_bits(grid_run):
    _, inputs, _, state, metrics, (init, blocks) = grid_run
    start, init_metrics = init(*inputs)
    again_state, again = blocks(*inputs[:2], start)
    again |= init_metrics
    for name in metrics:
        np.testing.assert_array_equal(again[name], metrics[name], err_msg=name)
    for a, b in zip(jax.tree.leaves(again_state.policy_params),
                    jax.tree.leaves(state.policy_params), strict=True):  # fmt: skip
        np.testing.assert_array_equal(a, b)


def test_a_cell_does_not_depend_on_the_parts_compiled_for_other_methods(demos, grid_run):
    """BC (all rows) in a grid that compiles neither discriminator nor the classifier learns
    the same policy as in the grid with all three (common random numbers: no part draws
    from the policy's keys)."""
    cells, inputs, _, state, _, _ = grid_run
    bare = OfflineTrainer(dataclasses.replace(TINY, components=()), envs.make("Pendulum-v1"), demos)
    index = next(i for i, c in enumerate(cells) if c.method == "bc-all")
    alone_state, _ = jax.jit(bare.train)(*_cell(inputs, index))
    _assert_close(alone_state.policy_params, _cell(state.policy_params, index))


def test_each_discriminator_moves_only_in_its_own_cells_and_dwbc_on_schedule(grid_run):
    cells, _, start, state, _, _ = grid_run
    for index, cell in enumerate(cells):
        for part in ("dwbc", "iswbc"):
            before = jax.tree.leaves(_cell(getattr(start, f"{part}_params"), index))
            after = jax.tree.leaves(_cell(getattr(state, f"{part}_params"), index))
            moved = any(not np.array_equal(a, b) for a, b in zip(before, after, strict=True))
            assert moved == cell.method.startswith(part), (cell, part)
    # DWBC's Adam counts only its scheduled steps: 40 steps, one in 5.
    counts = jax.tree.leaves(state.dwbc_optimizer_state)[0]
    assert set(np.asarray(counts).tolist()) == {8}


def test_num_gradient_steps_stops_a_methods_policy(grid_run):
    """The grid's last cell: BC on every row, stopped after 20 of its 40 steps."""
    cells, _, _, state, metrics, _ = grid_run
    np.testing.assert_array_equal(metrics["gradient_steps"][-1], [10, 20, 20, 20])
    np.testing.assert_array_equal(metrics["gradient_steps"][2], [10, 20, 30, 40])
    returns = np.asarray(metrics["eval/return"][-1])
    assert returns[1] == returns[3]  # the same policy evaluated on the same episodes
    assert returns[3] != metrics["eval/return"][2][3]  # its twin learned on


def test_required_components_and_unknown_methods():
    assert required_components(["bc-all", "bc-expert"]) == ()
    assert required_components(["iswbc", "dwbc+bsc"]) == ("dwbc", "iswbc", "classifier")
    assert required_components(["ilid+bsc", "bc-all"]) == ("ilid", "classifier")
    with pytest.raises(ValueError, match="unknown offline method 'gail'"):
        required_components(["gail"])


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("num_iterations", 3, "multiple of eval_every"),
        ("batch_size", 0, "batch_size must be a positive integer"),
        ("components", ("gail",), "components must be distinct names"),
        ("ilid_rollback", 0, "ilid_rollback must be a positive integer"),
        ("num_demos", 1, "num_demos must be an integer >= 2"),
    ],
)
def test_bad_configs_are_refused_in_one_line(field, value, match):
    with pytest.raises(ValueError, match=match):
        dataclasses.replace(TINY, **{field: value})


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        ({"conf": "/x/conf.npy"}, "conf: a confidence file needs demos"),
        ({"demos": "/x/set.npz", "action_scale": 2.0}, "an .npz set carries its confidences"),
        ({"action_scale": -1.0}, "action_scale must be finite and positive"),
        ({"seed": 2**63}, r"seed must be an integer in \[0, 2\*\*63\)"),
        ({"noise_std": -0.1}, "noise_std must be finite and >= 0"),
        ({"env": "NoSuchTask-v0"}, "env: "),
    ],
)
def test_an_offline_run_config_checks_its_parts_when_made(overrides, match):
    """The demonstrations part, the budget's seeds and the task are checked where the sweep's
    are, when an OfflineRunConfig is made (not when its run first reads them)."""
    from pngail_jax.jobs.offline_config import OfflineRunConfig

    with pytest.raises(ValueError, match=match):
        OfflineRunConfig(**overrides)
    config = OfflineRunConfig(demos="/x/a_mixture.npy", action_scale=2)
    assert config.demonstrations.action_scale == 2.0 and config.demonstrations.demos == config.demos
    assert config.settings.num_eval_episodes == config.trainer_config(1000).num_eval_episodes


def test_demonstrations_without_confidences_are_refused(demos):
    bare = dataclasses.replace(demos, confidence=None)
    with pytest.raises(ValueError, match="need confidences"):
        OfflineTrainer(TINY, envs.make("Pendulum-v1"), bare)
    shuffled = dataclasses.replace(demos, trajectory_ids=None)  # as the authors' MuJoCo files
    with pytest.raises(ValueError, match="ILID selects rows by the states they lead to"):
        OfflineTrainer(TINY, envs.make("Pendulum-v1"), shuffled)


def test_ilid_selects_other_rows_that_lead_to_expert_like_states(demos, grid_run):
    """ILID's cells: the selected rows are other (not expert) rows, each with an expert-like
    state among its next K = 3 in its trajectory by the state discriminator it trained; the
    weighted set is the expert rows and those; the weights d / (1 - d) lie in [1/9, 9]."""
    cells, inputs, start, _, metrics, _ = grid_run
    for index, cell in enumerate(cells):
        if cell.method != "ilid":
            continue
        expert = np.asarray(start.expert_probability[index]) > 0
        selected = np.asarray(start.ilid_selected_probability[index]) > 0
        union = np.asarray(start.ilid_union_probability[index]) > 0
        assert metrics["ilid/num_selected"][index] == selected.sum() > 0
        assert not (selected & expert).any()
        np.testing.assert_array_equal(union, expert | selected)
        weights = np.asarray(start.ilid_weight[index])
        assert (weights >= 1 / 9 - 1e-6).all() and (weights <= 9 + 1e-5).all()
        rows = np.asarray(start.demo_rows[index])[selected]
        ids = demos.trajectory_ids
        for row in rows:  # each selected row has a successor in its own trajectory
            assert row + 1 < len(ids) and ids[row + 1] == ids[row]


@pytest.mark.parametrize(
    ("overrides", "field", "flag", "reason"),
    [
        ({"label_ratio": 1.5}, "label_ratio", "--label-ratio", "must lie in (0, 1), got 1.5"),
        ({"label_ratio": 0.0}, "label_ratio", "--label-ratio", "must lie in (0, 1), got 0.0"),
        ({"noise_std": -0.1}, "noise_std", "--noise", "must be finite and >= 0, got -0.1"),
        ({"methods": ("gail",)}, "methods", "--methods", ": unknown offline method 'gail'"),
        ({"methods": ("bc-all", "bc-all")}, "methods", "--methods", "must be distinct"),
        ({"methods": ()}, "methods", "--methods", "must be a non-empty list"),
        ({"seeds": 0}, "seeds", "--seeds", "must be a positive integer, got 0"),
        ({"seed": -1}, "seed", "--seed", "must be an integer in [0, 2**63), got -1"),
        ({"gradient_steps": 0}, "gradient_steps", "--gradient-steps",
         "must be a positive integer, got 0"),
        ({"steps_per_iteration": 0}, "steps_per_iteration", "--steps-per-iteration",
         "must be a positive integer, got 0"),
        ({"eval_every": 0}, "eval_every", "--eval-every", "must be a positive integer, got 0"),
        ({"chunk_iterations": 0}, "chunk_iterations", "--chunk-iterations",
         "must be a positive integer, got 0"),
        ({"batch_size": 0}, "batch_size", "--batch-size", "must be a positive integer, got 0"),
        ({"ilid_discriminator_steps": 0}, "ilid_discriminator_steps",
         "--ilid-discriminator-steps", "must be a positive integer, got 0"),
        ({"gradient_steps": 1500}, "gradient_steps", "--gradient-steps",
         "(1500) must be a multiple of steps_per_iteration x eval_every = 5000"),
        ({"ilid_discriminator_learning_rate": 2.0}, "ilid_discriminator_learning_rate",
         "--ilid-discriminator-learning-rate", "must lie in (0, 1), got 2.0"),
        ({"dwbc_discriminator_updates": 3}, "dwbc_discriminator_updates",
         "--dwbc-discriminator-updates", "must be a positive integer that divides gradient_steps"),
        ({"action_scale": -1.0}, "action_scale", "--action-scale",
         "must be finite and positive, got -1.0"),
        ({"conf": "c.npy"}, "conf", "--conf", ": a confidence file needs demos"),
    ],
)  # fmt: skip
def test_each_bad_offline_flag_is_named_in_one_line(
    overrides, field, flag, reason, tmp_path, capsys
):
    """OfflineRunConfig's checks raise ConfigError with the field's path (as RunConfig's);
    the offline program names the flag that set it, and the flags of the other settings its
    reason names, in one line."""
    from pngail_jax.config.validation import ConfigError
    from pngail_jax.jobs.offline_config import OfflineRunConfig
    from pngail_jax.programs import offline as program

    with pytest.raises(ConfigError) as refused:
        OfflineRunConfig(**overrides)
    assert refused.value.field == field and refused.value.reason.startswith(reason)
    argv = []
    for name, value in overrides.items():
        text = ",".join(value) if isinstance(value, tuple) else str(value)
        argv += [program.FLAGS.get(name, "--" + name.replace("_", "-")), text]
    with pytest.raises(SystemExit, match="^2$"):
        program.parse_args([*argv, "--out", str(tmp_path / "refused")])
    error = capsys.readouterr().err.strip()
    spelled = program.flag_words(reason)  # the other settings a reason names, by their flags
    assert "\n" not in error and f"error: {flag}{'' if reason[0] == ':' else ' '}{spelled}" in error
    assert "_" not in error.partition("error: ")[2]  # no field name left for a flag's user


def test_an_offline_run_config_stores_its_numbers_in_their_types():
    """A NumPy count and an int ratio read as Python ints and floats (config.json and the
    trainer's static config see the same values)."""
    from pngail_jax.jobs.offline_config import OfflineRunConfig

    config = OfflineRunConfig(
        seeds=np.int64(2), noise_std=0, methods=["bc-all"], hidden_sizes=[8],
        dwbc_discriminator_updates=np.int32(500),
    )  # fmt: skip
    assert type(config.seeds) is int and type(config.noise_std) is float
    assert config.methods == ("bc-all",) and config.hidden_sizes == (8,)
    assert type(config.dwbc_discriminator_updates) is int


def test_demonstrations_a_run_cannot_use_are_refused_before_it_writes(demos_path, tmp_path):
    """ILID on rows without trajectories, and demonstrations of another task: one line each,
    before config.json is written."""
    from pngail_jax.programs import offline as program

    with pytest.raises(SystemExit, match="no trajectories .its rows carry no trajectory ids"):
        program.main(["--demos", str(demos_path), "--methods", "ilid", "--out",
                      str(tmp_path / "refused")])  # fmt: skip
    with pytest.raises(SystemExit, match="demonstrations of Pendulum-v1 do not fit Hopper-v4"):
        program.main(["--demos", str(demos_path), "--env", "Hopper-v4", "--out",
                      str(tmp_path / "other-task")])  # fmt: skip
    for folder in ("refused", "other-task"):
        assert not (tmp_path / folder / "config.json").exists()


def test_the_program_writes_the_sweeps_outputs_and_refuses_a_second_run(
    demos_path, tmp_path, capsys
):
    """experiments.offline end to end on a tiny grid: config.json, metrics.csv (no
    environment step), summary.json with each method's probability of beating BC on every
    row, curves.png; a second run into the same folder is refused."""
    from pngail_jax.demos import load_npz, save_npz
    from pngail_jax.programs import offline as program

    with_trajectories = tmp_path / "trajectories.npz"  # the same rows, in 5 trajectories
    save_npz(with_trajectories, dataclasses.replace(
        load_npz(demos_path), trajectory_ids=np.repeat(np.arange(5), 20)))  # fmt: skip
    out = tmp_path / "offline"
    argv = [
        "--demos", str(with_trajectories), "--methods", "bc-all,dwbc,bc-expert,ilid",
        "--seeds", "2", "--gradient-steps", "40", "--steps-per-iteration", "10",
        "--eval-every", "2", "--chunk-iterations", "2", "--batch-size", "8",
        "--ilid-discriminator-steps", "5", "--out", str(out),
    ]  # fmt: skip
    summary = program.main(argv)
    assert {p.name for p in out.iterdir()} >= {
        "config.json",
        "metrics.csv",
        "summary.json",
        "summary.md",
        "curves.png",
    }
    assert list(summary["methods"]) == ["bc-all", "dwbc", "bc-expert", "ilid"]  # three programs
    assert "ILID's two discriminators, 5 steps each" in capsys.readouterr().out
    assert set(summary["ilid"]) == {"num_selected", "num_other", "selected_true_confidence",
                                    "other_true_confidence"}  # fmt: skip
    assert "ILID's selection: a mean" in (out / "summary.md").read_text()
    assert outputs.unaccounted(out, "offline") == []  # --overwrite knows all it wrote
    assert summary["gradient_steps"] == 40
    assert "bc-expert" in summary["probability_of_improvement"]
    with (out / "metrics.csv").open() as file:
        rows = list(csv.DictReader(file))
    assert len(rows) == 4 * 2 * 4  # 4 methods x 2 seeds x 4 iterations
    assert [row["method"] for row in rows[::8]] == ["bc-all", "dwbc", "bc-expert", "ilid"]
    assert {row["env_steps"] for row in rows} == {"0"}  # no environment step taken
    assert all(row["wall_seconds"] for row in rows)
    assert sum(bool(row["normalized_return"]) for row in rows) == 4 * 2 * 2  # 2 evaluations
    with pytest.raises(SystemExit, match="^2$"):
        program.parse_args(argv)
    assert f"--out {out} already holds a run of experiments.offline" in capsys.readouterr().err
    assert_compare_and_the_record_read_it(out, rows, tmp_path / "records")
    # Sealed as the sweep is: a config.json edited by hand is not resumed under its label.
    document = json.loads((out / "config.json").read_text())
    document["config"]["gradient_steps"] = 80
    (out / "config.json").write_text(json.dumps(document))
    with pytest.raises(SystemExit, match="config.json was changed since the run began"):
        program.main(["--resume", str(out)])


def assert_compare_and_the_record_read_it(out, rows, records):
    """An offline run's rows join the online methods' tables: compare reads its headline,
    and a record keeps it."""
    from pngail_jax.analysis import compare, record_tables, run_records

    scores = compare.load_scores([out])
    evaluated = [
        float(r["normalized_return"]) for r in rows if r["method"] == "dwbc" and r["eval_return"]
    ]  # seed 0 at iterations 2 and 4, then seed 1: the late 20% of 2 evaluations is the last
    assert scores.values["dwbc"][scores.tasks[0]].tolist() == pytest.approx(
        evaluated[1::2], abs=1e-5
    )
    record = run_records.check_record(run_records.write_record(out, "tiny-offline", records))
    assert record["program"] == "experiments.offline" and record["complete"]
    assert "BC (all rows)" in record_tables.record_table(record, "bc-all")


@pytest.mark.heavy
@pytest.mark.slow
def test_each_method_beats_bc_on_every_row_on_a_mostly_poor_mixture():
    """A 1:4 mixture of five episodes of conftest's swing-up controller (confidence 1, returns -240
    to 0) and twenty of uniform random torques (confidence 0, about -1,400); label ratio 0.2, so
    about 200 controller rows are labelled expert. BC on every row copies mostly the random
    torques. 3 seeds x 20,000 gradient steps of small networks (batch 64; DWBC's discriminator
    every 10th step). Measured here, key 0, all four in one program, final returns: BC (all
    rows) -1249, -1228, -1137; BC (expert rows) -443, -1181, -374; DWBC -681, -1173, -1089;
    ISW-BC -1022, -1305, -1142; ILID (its own program, its discriminators 2,000 steps at 3e-4
    instead of its codebase's 100,000 at 1e-5) -1020, -1153, -1055. The bars are on medians (BC
    on every row: -1228), with room for float rounding: BC on the expert rows 300 above it,
    DWBC, ISW-BC and ILID 40 above; and on what each discriminator learned: DWBC's d higher on
    expert rows than on the others, ISW-BC's weight on expert rows at least twice the union's
    mean, ILID's selected rows richer in controller rows than those it chose from."""
    from conftest import swing_up_episodes_and_random

    demos, returns = swing_up_episodes_and_random(5, 20)
    assert max(returns[:5]) > -250 and max(returns[5:]) < -850
    config = OfflineConfig(
        num_iterations=20, steps_per_iteration=1000, eval_every=5, num_eval_episodes=8,
        batch_size=64, dwbc_discriminator_every=10, dwbc_branch_size=32, dwbc_hidden_size=64,
        iswbc_hidden_sizes=(64, 64), ilid_hidden_sizes=(64, 64), ilid_discriminator_steps=2000,
    )  # fmt: skip
    final, metrics = {}, {}
    for methods in program_groups(OFFLINE_METHOD_NAMES):  # one program each, as the job runs
        components = required_components(methods)
        trainer = OfflineTrainer(
            dataclasses.replace(config, components=components), envs.make("Pendulum-v1"), demos
        )
        inputs = stack_cells(  # ILID's discriminators: 2,000 steps at 3e-4 here
            make_cells(methods, 3), jax.random.key(0), {"ilid_discriminator_learning_rate": 3e-4},
            family=OFFLINE,
        )  # fmt: skip
        _, group = jax.jit(jax.vmap(trainer.train))(*inputs)
        returns = np.asarray(group["eval/return"])[:, -1].reshape(len(methods), 3)
        final |= dict(zip(methods, returns, strict=True))
        metrics |= {  # per iteration: the last; the selection's (at the start): as is
            name: np.asarray(values)[..., -1] if np.ndim(values) == 2 else np.asarray(values)
            for name, values in group.items()
            if name.startswith(("dwbc/", "iswbc/", "ilid/"))
        }
    median = {name: np.median(values) for name, values in final.items()}
    assert median["bc-expert"] > median["bc-all"] + 300, final
    assert median["dwbc"] > median["bc-all"] + 40, final
    assert median["iswbc"] > median["bc-all"] + 40, final
    assert median["ilid"] > median["bc-all"] + 40, final
    # ILID's selection is richer in controller rows than the other rows it picks from
    # (800 of about 4,800, 0.17): measured 0.54-0.56.
    assert (metrics["ilid/selected_true_confidence"] > 0.3).all()
    assert (metrics["dwbc/mean_d_expert"] > metrics["dwbc/mean_d_other"] + 0.3).all()
    assert (metrics["iswbc/weight_expert"] > 2 * metrics["iswbc/mean_weight"]).all()


def test_program_groups_compile_each_part_only_for_its_methods():
    assert program_groups(["dwbc", "bc-all", "iswbc", "bc-expert", "dwbc+bsc"]) == [
        ("dwbc",), ("bc-all", "bc-expert"), ("iswbc",), ("dwbc+bsc",)
    ]  # fmt: skip


def test_a_run_resumed_from_a_checkpoint_equals_the_uninterrupted_run(demos_path, tmp_path, capsys):
    """Each program keeps a checkpoint per chunk; a run whose last chunk is lost (its newest
    checkpoints removed, its outputs not written) resumes from the chunk before to the same
    evaluations, bit for bit; a resume of another config's run, or of no run, is refused."""
    import shutil

    from pngail_jax.jobs.errors import RunError
    from pngail_jax.jobs.offline import load_offline_config, run_offline
    from pngail_jax.programs import offline as program

    whole = tmp_path / "whole"
    argv = [
        "--demos", str(demos_path), "--methods", "bc-all,dwbc", "--seeds", "2",
        "--gradient-steps", "40", "--steps-per-iteration", "10", "--eval-every", "2",
        "--chunk-iterations", "2", "--batch-size", "8", "--out", str(whole),
    ]  # fmt: skip
    program.main(argv)
    cut = tmp_path / "cut"
    shutil.copytree(whole, cut)
    for group in ("bc-all", "dwbc"):
        chunks = sorted((cut / "checkpoints" / group).glob("chunk_*"))
        assert [c.name for c in chunks] == ["chunk_0001", "chunk_0002"]
        shutil.rmtree(chunks[-1])
    for name in ("metrics.csv", "summary.json", "summary.md", "curves.png"):
        (cut / name).unlink()
    capsys.readouterr()
    program.main(["--resume", str(cut)])
    said = capsys.readouterr().out
    for group in ("bc-all", "dwbc"):  # from the chunk before, not from the start
        assert f"resumed from {cut / 'checkpoints' / group / 'chunk_0001'}" in said

    def evaluations(run):
        with (run / "metrics.csv").open() as file:
            return [(r["method"], r["seed"], r["eval_return"]) for r in csv.DictReader(file)]

    assert evaluations(cut) == evaluations(whole)
    other = dataclasses.replace(load_offline_config(cut), seeds=3)
    with pytest.raises(RunError, match="began with another config"):
        run_offline(other, cut, resume=True)
    with pytest.raises(SystemExit, match="^2$"):
        program.main(["--resume", str(tmp_path / "nothing")])
    assert f"--resume {tmp_path / 'nothing'}: no offline run there" in capsys.readouterr().err


def test_the_offline_program_is_checked_as_the_sweep_is(demos_path, tmp_path, capsys, monkeypatch):
    """The offline program under the sweep's rules: its stored command runs as written (the
    program's own parser takes it); a copy without its dot-files is named by its missing seal
    when resumed, compared or recorded, and --allow-unsealed resumes it and says so; Ctrl-C
    is one line; compare --expected against its own record finds no difference (its timings
    are not settings)."""
    from pngail_jax.jobs import offline as offline_job
    from pngail_jax.programs import compare as compare_program
    from pngail_jax.programs import offline as program
    from pngail_jax.programs import record as record_program

    out = tmp_path / "offline"
    argv = [
        "--demos", str(demos_path), "--methods", "bc-all,dwbc", "--seeds", "2",
        "--gradient-steps", "40", "--steps-per-iteration", "10", "--eval-every", "2",
        "--chunk-iterations", "2", "--batch-size", "8", "--out", str(out),
    ]  # fmt: skip
    program.main(argv)
    command = json.loads((out / "config.json").read_text())["provenance"]["command_line"]
    assert command == ["python", "-m", "experiments.offline", *argv]
    stored = program.build_parser().parse_args(command[3:])
    assert stored.methods == "bc-all,dwbc" and stored.out == out

    bare = tmp_path / "bare"  # copied without its dot-files
    shutil.copytree(out, bare, ignore=lambda folder, names: [n for n in names if n[0] == "."])
    seal = "its seal .config.sealed.json is missing"
    for run, argv_of in (
        (program, ["--resume", str(bare)]),
        (compare_program, [str(bare), "--out", str(tmp_path / "cmp")]),
        (record_program, [str(bare), "--name", "b", "--records", str(tmp_path / "r")]),
    ):
        with pytest.raises(SystemExit, match=seal) as refused:
            run.main(argv_of)
        assert "\n" not in str(refused.value.code)
    capsys.readouterr()
    program.main(["--resume", str(bare), "--allow-unsealed"])
    assert "no seal, config.json unchecked (--allow-unsealed)" in capsys.readouterr().out

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(program, "run_offline", interrupted)
    with pytest.raises(SystemExit) as stopped:
        program.main(["--resume", str(out)])
    assert str(stopped.value.code).strip() == (
        f"interrupted: finished chunks are kept; --resume {out} continues from the last one"
    )
    monkeypatch.undo()
    assert offline_job.run_offline is not interrupted

    [record] = record_program.main([str(out), "--name", "mine", "--records", str(tmp_path / "r")])
    result = compare_program.main([str(out), "--expected", str(record),
                                   "--out", str(tmp_path / "against")])  # fmt: skip
    expected = json.loads((result / "compare.json").read_text())["expected"]
    assert expected["config_differences"] == [] and expected["unfinished"] == []
    assert {row["verdict"] for row in expected["rows"]} == {"within"}


def test_an_authors_file_picks_its_task(tmp_path):
    """--demos Hopper-v2_mixture.npy alone runs on Hopper-v4, as the sweep's does."""
    from pngail_jax.programs import offline as program

    argv = ["--demos", str(tmp_path / "Hopper-v2_mixture.npy"), "--out", str(tmp_path / "o")]
    assert program.parse_args(argv).config.env == "Hopper-v4"
    assert program.parse_args([*argv, "--env", "Pendulum-v1"]).config.env == "Pendulum-v1"
