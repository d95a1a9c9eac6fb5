"""experiments.paper: the plan of figures and grids, the made mixtures, and a tiny run that
writes the results page."""

import json

import numpy as np
import pytest
from conftest import sigterm_to_self

from pngail_jax.adversarial.methods import display_name
from pngail_jax.analysis.runs import sealed_part
from pngail_jax.demos import Demonstrations
from pngail_jax.jobs.errors import RunError
from pngail_jax.programs import paper
from pngail_jax.storage import outputs
from pngail_jax.storage.integrity import CONFIG_SEAL, seal


def test_fig2_and_fig3_share_one_grid_per_task_and_each_figure_has_its_grids():
    figures, grids = paper.plan(["fig2", "fig3", "table1"], ["Hopper", "Pendulum-v1"], set())
    assert sorted(grids) == ["Hopper-main", "Pendulum-v1-main"]
    assert grids["Hopper-main"].methods == paper.SEVEN_METHODS
    assert [s.method for s in figures[0].panels["Hopper"]] == list(paper.FIG2_METHODS)
    # With the authors' Hopper file, Hopper's main grid uses it; Pendulum's stays made.
    _, grids = paper.plan(["fig2"], ["Hopper", "Pendulum-v1"], {"Hopper"})
    assert grids["Hopper-main"].demos.ratio is None
    assert grids["Pendulum-v1-main"].demos.ratio == (1, 4)


def test_the_gpu_preset_takes_each_tasks_solver_caps_from_the_study_and_nothing_else():
    """Its -v4 tasks' grids and demonstration runs get GPU_SOLVERS' caps (gymnasium's own
    where a task is not named); every other field is the paper preset's; Pendulum-v1 has
    no solver and is untouched."""
    import dataclasses

    from pngail_jax.config.settings import parse_solver
    from pngail_jax.paper.plan import BUDGETS, GPU_SOLVERS, MUJOCO_TASKS

    gpu, paper_budget = BUDGETS["gpu"], BUDGETS["paper"]
    assert set(GPU_SOLVERS) <= set(MUJOCO_TASKS) and GPU_SOLVERS
    for task in MUJOCO_TASKS:
        for demos in (False, True):
            row, base = (
                gpu.settings_for(task, "mjx", demos),
                paper_budget.settings_for(task, "mjx", demos),
            )
            caps = parse_solver(GPU_SOLVERS.get(task, "own"))
            assert (row.solver_iterations, row.ls_iterations) == (
                caps["solver_iterations"], caps["ls_iterations"]
            )  # fmt: skip
            assert dataclasses.replace(row, **parse_solver("own")) == base
    assert gpu.settings_for("Pendulum-v1", None) == paper_budget.settings_for("Pendulum-v1", None)
    assert BUDGETS["cpu"].solvers == {} and paper_budget.solvers == {}


def test_every_built_figure_plans_on_all_six_tasks():
    figures, grids = paper.plan(paper.FIGURES, list(paper.envs.ENV_NAMES), set())
    assert [figure.name for figure in figures] == list(paper.FIGURES)
    for figure in figures:  # every series names a grid of the plan and one of its methods
        for series_list in figure.panels.values():
            for series in series_list:
                assert series.method in grids[series.grid].methods
    # The 1:4 cells of Fig. 7 and the full set of Fig. 10 are the main grids' own.
    fig7 = next(f for f in figures if f.name == "fig7").panels["Pendulum-v1"]
    fig10 = next(f for f in figures if f.name == "fig10").panels["Ant"]
    assert fig7[1].grid == "Pendulum-v1-main" and fig10[0].grid == "Ant-main"
    # Table 4 and Fig. 5 share their grids: Fig. 2's demonstrations, Fig. 8's on Ant; one
    # grid per set of training phases, so no cell runs a phase it does not read.
    assert grids["Ant-appendix-cail"].demos == paper.DemoSet("Ant", (1, 10))
    assert grids["Pendulum-v1-appendix-firl"].demos == grids["Pendulum-v1-main"].demos
    assert grids["Pendulum-v1-appendix-firl"].methods == ("firl-fkl", "firl-rkl", "firl-js")
    appendix = [name for name in grids if name.startswith("Pendulum-v1-appendix-")]
    assert sorted(appendix) == [
        f"Pendulum-v1-appendix-{group}"
        for group in ("bc", "cail", "drex", "firl", "pngail", "trex")
    ]
    # Fig. 6 keeps the labelled rows and scales the unlabelled ones: 200 + 0.5 * 800.
    grid = grids["Pendulum-v1-unlabelled-0.5"]
    config = paper.grid_config(grid, ("x.npz", 1.0), paper.BUDGETS["test"], 1000)
    assert config.num_demos == 600
    assert config.label_ratios == (pytest.approx(200 / 600),)


def test_trajectory_counts_reach_the_tasks_rows_at_the_ratio():
    # Pendulum's 200-step episodes: 2:1 doubled to reach 1,000 rows; 1:9 is 2,000 already.
    assert paper.DemoSet("Pendulum-v1", (2, 1)).trajectory_counts(1000, 200) == (4, 2)
    assert paper.DemoSet("Pendulum-v1", (1, 9)).trajectory_counts(1000, 200) == (1, 9)
    assert paper.DemoSet("Ant", (1, 4), 0.5).trajectory_counts(600, 1000) == (1, 2)


def made_set(lengths, num_optimal):
    ids = np.repeat(np.arange(len(lengths)), lengths)
    returns = [100.0 - 10 * i for i in range(len(lengths))]
    confidence = np.clip(np.array(returns)[ids] / 100, 0, 1)
    return Demonstrations(
        observations=np.arange(len(ids) * 2, dtype=np.float32).reshape(-1, 2),
        actions=np.zeros((len(ids), 1), np.float32),
        confidence=confidence.astype(np.float32),
        trajectory_ids=ids,
        metadata={
            "env": "Pendulum-v1",
            "num_optimal_trajectories": num_optimal,
            "trajectory_returns": returns,
            "random_return": 0.0,
            "optimal_return": 100.0,
        },
    )


def test_a_mixture_takes_the_first_trajectories_of_each_kind_and_renumbers_them():
    source = made_set([3, 2, 4, 1, 5], num_optimal=2)  # optimal: 0, 1; intermediate: 2, 3, 4
    from pngail_jax.demos import cut_mixture

    mixed = cut_mixture(source, 1, 2, "made-1to2")
    np.testing.assert_array_equal(mixed.trajectory_ids, [0, 0, 0, 1, 1, 1, 1, 2])
    np.testing.assert_array_equal(mixed.observations[:, 0], [0, 2, 4, 10, 12, 14, 16, 18])
    assert mixed.metadata["trajectory_returns"] == [100.0, 80.0, 70.0]
    assert mixed.metadata["num_optimal_trajectories"] == 1 and mixed.metadata["ratio"] == "1:2"
    with pytest.raises(ValueError, match="needs 1 optimal \\+ 4 intermediate .* has 2 \\+ 3"):
        cut_mixture(source, 1, 4)


def test_figures_without_a_panel_on_the_tasks_asked_for_are_refused(tmp_path):
    with pytest.raises(SystemExit, match="none of table4, fig8 has a panel on Hopper"):
        paper.main(["--only", "table4,fig8", "--envs", "Hopper", "--out", str(tmp_path / "p")])
    assert not (tmp_path / "p").exists()  # refused before anything is written


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--only", "fig11"], "--only: unknown figure(s) ['fig11']; available: fig2, fig3"),
        (["--envs", "Hoper"], "--envs: unknown task(s) ['Hoper']; available: Pendulum-v1"),
        (
            ["--resume", "nowhere", "--only", "fig2"],
            "--resume takes its options from the run: drop --only",
        ),
        (["--resume", "nowhere"], "--resume nowhere: no paper.json there (not a run of this)"),
        (
            ["--resume", "nowhere", "--preset", "cpu"],
            "--resume takes its options from the run: drop --preset",
        ),  # not silently ignored
        (
            ["--resume", "nowhere", "--demo-learner", "ppo"],
            "--resume takes its options from the run: drop --demo-learner",
        ),
        (["--preset", "huge"], "argument --preset/--budget: invalid choice: 'huge' (choose from"),
    ],
)
def test_bad_flags_are_named(flags, message, capsys):
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        paper.parse_args(flags)
    assert f"python -m experiments.paper: error: {message}" in capsys.readouterr().err


def test_old_spellings_still_work_with_a_note_naming_the_new_one(tmp_path, capsys):
    """--budget is --preset, and the old 'smoke' preset (20 x 2) is 'check': the sweep's
    smoke preset is 300 x 3, and one name means one scale everywhere."""
    args = paper.parse_args(["--budget", "smoke", "--out", str(tmp_path / "a")])
    assert args.budget == "check" and paper.BUDGETS["check"].iterations == 20
    err = capsys.readouterr().err
    assert "--budget is deprecated; it is now --preset" in err and "now 'check'" in err
    assert paper.parse_args(["--out", str(tmp_path / "b")]).budget == "check"  # the default


@pytest.mark.filterwarnings("ignore:.*normalised returns run backwards")  # 4 iterations
def test_a_tiny_fig2_run_writes_the_page_with_every_method_resumes_and_adopts(
    tmp_path, monkeypatch, capsys
):
    out = tmp_path / "paper"
    argv = ["--preset", "test", "--only", "fig2", "--envs", "Pendulum-v1", "--out", str(out)]
    page = paper.main(argv)
    text = page.read_text()
    for method in paper.FIG2_METHODS:
        assert f"| Pendulum-v1 | {display_name(method)} |" in text  # the paper's names
    assert "--only fig2 --envs Pendulum-v1" in text and (out / "fig2.png").stat().st_size > 0
    assert "Preset `test`" in text and "its numbers are not results" in text
    assert "training phases run at small check sizes" in text  # the appendix baselines'
    results = json.loads((out / "results.json").read_text())
    final = results["fig2"]["Pendulum-v1"]["pngail"]["final"]
    assert final["seeds"] == 2 and len(final["ci95"]) == 2
    summary = json.loads((out / "grids" / "Pendulum-v1-main" / "summary.json").read_text())
    assert summary["complete"] and sorted(summary["methods"]) == sorted(paper.SEVEN_METHODS)
    assert outputs.unaccounted(out, "paper") == []  # --overwrite knows all it wrote
    # The same run again is refused; --resume keeps the finished grid and rewrites the page.
    capsys.readouterr()
    with pytest.raises(SystemExit, match="^2$"):
        paper.parse_args(argv)
    assert (
        f"--out {out} already holds a run of experiments.paper: --resume {out} to continue it"
    ) in capsys.readouterr().err
    before = (out / "grids" / "Pendulum-v1-main" / "metrics.csv").read_bytes()
    assert paper.main(["--resume", str(out)]).read_text() == text
    assert (out / "grids" / "Pendulum-v1-main" / "metrics.csv").read_bytes() == before
    assert_a_page_so_far_shows_what_ran(out, text, capsys)
    assert_a_sweep_of_the_grid_is_adopted(out, text, monkeypatch)


def assert_a_page_so_far_shows_what_ran(out, text, capsys):
    """--page writes the page of a plan's grids as they are into its own folder, touching
    nothing in the plan: a finished plan's as its own page; a grid in progress at the
    iteration it reached, a task not started left out, each said; no outputs, one line."""

    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    page = paper.main(["--page", str(out), "--out", str(out.parent / "page")]).read_text()
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert outputs.unaccounted(out.parent / "page", "paper-page") == []

    def rows(page_text):
        return [line for line in page_text.splitlines() if line.startswith("| Pendulum-v1 |")]

    assert rows(page) == rows(text)
    assert "](../paper/grids/Pendulum-v1-main/summary.md)" in page and "so far" not in page
    capsys.readouterr()
    with pytest.raises(SystemExit, match="^2$"):  # its own page again: --overwrite
        paper.main(["--page", str(out), "--out", str(out.parent / "page")])
    assert (
        f"--out {out.parent / 'page'} already holds a run of experiments.paper-page: pass "
        "--overwrite"
    ) in capsys.readouterr().err
    with pytest.raises(SystemExit, match="^2$"):
        paper.parse_args(["--page", str(out), "--preset", "cpu"])
    assert "--page writes the page of the plan in DIR as it is: drop --preset" in (
        capsys.readouterr().err
    )
    assert_a_page_of_a_partial_plan(out)


def assert_a_page_of_a_partial_plan(out):
    """The same plan on two tasks, its Pendulum grid at iteration 2 of 4 and Hopper not
    begun: the page says what ran, what is in progress and what has not started."""
    import shutil

    from pngail_jax.paper.run import PAPER_SEAL
    from pngail_jax.storage.integrity import seal

    partial = out.parent / "partial"
    shutil.copytree(out, partial)
    options = json.loads((partial / "paper.json").read_text())
    options["envs"] = ["Pendulum-v1", "Hopper-v4"]
    (partial / "paper.json").write_text(json.dumps(options))
    seal(partial / PAPER_SEAL, options)
    summary_path = partial / "grids" / "Pendulum-v1-main" / "summary.json"
    summary = json.loads(summary_path.read_text())
    summary.update(complete=False, iterations_done=2)
    summary_path.write_text(json.dumps(summary))
    page = paper.main(["--page", str(partial), "--out", str(out.parent / "p2")]).read_text()
    assert "| Hopper-v4 | made, 1:4 |" in page and "| not started |" in page
    assert "| in progress: 2 of 4 iterations |" in page and "A page so far" in page
    assert "Pendulum-v1 is unfinished: Pendulum-v1-main in progress: 2 of 4 iterations." in page
    assert "Not in this figure yet: Hopper-v4 (Hopper-v4-main has not started)." in page
    assert "| Hopper-v4 | GAIL |" not in page and "| Pendulum-v1 | GAIL |" in page
    assert "| Hopper-v4-main | Hopper-v4 |" in page  # not started: no link to a summary
    results = json.loads((out.parent / "p2" / "results.json").read_text())
    assert list(results["fig2"]) == ["Pendulum-v1"]
    assert results["unfinished"] == {
        "Pendulum-v1-main": "in progress: 2 of 4 iterations",
        "Hopper-v4-main": "not started",
    }
    with pytest.raises(SystemExit, match="is inside the plan's folder"):
        paper.main(["--page", str(partial), "--out", str(partial / "page")])
    shutil.rmtree(partial / "grids" / "Pendulum-v1-main")
    with pytest.raises(SystemExit, match=f"--page {partial}: no grid of the plan has outputs"):
        paper.main(["--page", str(partial), "--out", str(out.parent / "p3")])
    with pytest.raises(SystemExit, match="no paper.json there"):
        paper.main(["--page", str(out.parent / "p2"), "--out", str(out.parent / "p4")])


def assert_a_sweep_of_the_grid_is_adopted(out, text, monkeypatch):
    """The finished grid moved out (as a sweep run on its own would be) comes back with
    --adopt, no grid running; a sweep of another config is refused, the plan kept."""
    import shutil

    from pngail_jax.paper import grids as plan

    def no_grid_runs(*args, **kwargs):
        raise AssertionError("a grid ran")

    monkeypatch.setattr(plan, "run", no_grid_runs)
    sweep = out.parent / "sweep"
    shutil.move(out / "grids" / "Pendulum-v1-main", sweep)
    other = out.parent / "other"
    shutil.copytree(sweep, other)
    config = json.loads((other / "config.json").read_text())

    def with_fields(**changes):  # the sweep's config.json with these config fields
        return {**config, "config": {**config["config"], **changes}}

    (other / "config.json").write_text(json.dumps(with_fields(seeds=3)))
    with pytest.raises(
        SystemExit, match=r"config.json was changed since the run began \(config.seeds"
    ):
        paper.main(["--resume", str(out), "--adopt", str(other)])  # edited by hand: refused
    (other / "config.json").write_text(json.dumps(with_fields(seed=7)))  # another base seed
    seal(other / CONFIG_SEAL, sealed_part(with_fields(seed=7)))  # as its run sealed it
    with pytest.raises(SystemExit, match="seed 7, the plan's 0 .the plan so far is kept: --r"):
        paper.main(["--resume", str(out), "--adopt", str(other)])
    adopted = paper.main(["--resume", str(out), "--adopt", str(sweep)]).read_text()
    copied = out / "grids" / "Pendulum-v1-main"
    assert (copied / "metrics.csv").read_bytes() == (sweep / "metrics.csv").read_bytes()
    commit = (config["provenance"]["git_commit"] or "unknown")[:7]
    assert f"adopted from `{sweep.absolute()}` (commit {commit})" in adopted
    assert json.loads((out / "results.json").read_text())["adopted"]["Pendulum-v1-main"]
    # The same adoption again is a no-op.
    assert paper.main(["--resume", str(out), "--adopt", str(sweep)]).read_text() == adopted
    # A plan's own grid adopted into the plan being overwritten: refused, nothing deleted.
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    argv = ["--preset", "test", "--only", "fig2", "--envs", "Pendulum-v1", "--out", str(out)]
    with pytest.raises(SystemExit, match="lies inside --out .*, which --overwrite empties first"):
        paper.main([*argv, "--overwrite", "--adopt", str(copied)])
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_the_page_warns_of_a_made_expert_worse_than_random_and_the_plan_has_an_eta(
    tmp_path, recwarn
):
    from pngail_jax.demos import save_npz

    directory = tmp_path / "demos" / "Pendulum-v1"
    directory.mkdir(parents=True)
    weak = Demonstrations(
        np.zeros((4, 3), np.float32),
        np.zeros((4, 1), np.float32),
        np.ones(4, np.float32),
        metadata={"random_return": -1200.0, "optimal_return": -1300.0, "ratio": "1:1",
                  "optimal_beats_random": False},
    )  # fmt: skip
    save_npz(directory / "demos.npz", weak)
    grids = {"g": paper.main_grid("Pendulum-v1", released=False)}
    (note,) = paper.weak_expert_notes(tmp_path, grids)
    assert "Pendulum-v1's made expert (-1300.0) does not beat the random policy" in note
    assert paper.weak_expert_notes(tmp_path, {"g": paper.main_grid("Pendulum-v1", True)}) == []
    from pngail_jax.paper.page import made_expert_notes

    (line,) = made_expert_notes(tmp_path, grids)  # the made expert beside Table 3's
    assert "random policy -1,200.0, expert -1,300.0 (the paper's Table 3: -1,201.0 and" in line
    assert "-116.8, so the made expert is at -0.09 of the paper's normalised scale)" in line
    assert paper.plan_eta([], 3) == ""
    assert paper.plan_eta([60.0, 120.0], 2) == ", about 3m00s left for the plan"


def test_an_interrupted_grid_keeps_its_wall_time_on_the_plan_record(tmp_path, monkeypatch):
    """The page's wall time sums every call on a grid: a call stopped with Ctrl-C (the way a
    many-hour grid is run a chunk at a time) adds its time before the interrupt goes on."""
    import time

    from pngail_jax.paper import grids as plan

    def interrupted(*args):
        time.sleep(0.05)
        raise KeyboardInterrupt

    grid = paper.main_grid("Pendulum-v1", released=True)
    (tmp_path / "timings.json").write_text(json.dumps({"g": 60.0}))  # an earlier call's
    monkeypatch.setattr(plan, "run_grid", interrupted)
    with pytest.raises(KeyboardInterrupt):
        plan.run_grids({"g": grid}, {"g": None}, tmp_path, [])
    assert 60.05 <= json.loads((tmp_path / "timings.json").read_text())["g"] < 70.0


def test_a_sigterm_ends_the_plan_as_ctrl_c_does(tmp_path, monkeypatch):
    from pngail_jax.storage.outputs import LOCK

    monkeypatch.setattr(paper, "run_paper", sigterm_to_self)
    out = tmp_path / "paper"
    with pytest.raises(SystemExit, match=f"interrupted: finished grids are kept; --resume {out}"):
        paper.main(["--preset", "test", "--envs", "Pendulum-v1", "--out", str(out)])
    assert not (out / LOCK).exists()


def test_a_resume_checks_the_authors_files_and_its_own_options(tmp_path):
    mixture = tmp_path / "released" / "Pendulum-v1_mixture.npy"
    mixture.parent.mkdir()
    np.save(mixture, np.zeros((4, 4), np.float32))
    np.save(mixture.with_name("Pendulum-v1_mixture_conf.npy"), np.ones((4, 1)))
    released = {"Pendulum-v1": mixture}
    options = {"inputs": paper.released_inputs(released)}
    paper.check_paper_inputs(tmp_path, options, released)  # unchanged: goes on
    with pytest.raises(RunError, match="authors' files for Pendulum-v1 are no longer found"):
        paper.check_paper_inputs(tmp_path, options, {})  # the folder moved
    np.save(mixture, np.ones((4, 4), np.float32))
    with pytest.raises(RunError, match=f"demonstrations {mixture} has changed"):
        paper.check_paper_inputs(tmp_path, options, released)
    run = tmp_path / "run"
    run.mkdir()
    (run / "paper.json").write_text(json.dumps({"budget": "huge"}))
    with pytest.raises(
        SystemExit, match="names an unknown preset 'huge' .known: check, paper, gpu, cpu, test"
    ):
        paper.main(["--resume", str(run)])
    (run / "paper.json").write_text("{")
    with pytest.raises(SystemExit, match="paper.json: damaged paper run options"):
        paper.main(["--resume", str(run)])


def test_a_grid_config_is_the_sweep_config_of_the_same_flags(tmp_path):
    """The paper builds RunConfigs for the library runner; each is the config the sweep makes
    of the flags that say the same (so a grid can be rerun by hand with the sweep)."""
    from pngail_jax.programs import sweep

    demos = tmp_path / "demos.npz"
    demos.write_bytes(b"")  # the sweep checks that the file exists, not what it holds
    _, grids = paper.plan(["fig2", "fig4"], ["Hopper-v4", "Pendulum-v1"], set())
    grid = grids["Hopper-v4-main"]
    budget = paper.BUDGETS["check"]
    config = paper.grid_config(grid, (demos, 1.0), budget, None, physics="c")
    flags = [
        "--env", "Hopper-v4", "--demos", str(demos), "--methods", ",".join(grid.methods),
        "--seeds", "2", "--iterations", "20", "--chunk-iterations", "10",
        "--label-ratio", "0.2", "--noise", "0", "--num-envs", "5", "--unroll-length", "100",
        "--eval-every", "10", "--num-eval-episodes", "1", "--classifier-steps", "500",
        "--physics", "c", "--phase-sizes", "check", "--out", str(tmp_path / "out"),
    ]  # fmt: skip
    assert config == sweep.parse_args(flags).config
    noisy = grids["Pendulum-v1-noise"]
    released = tmp_path / "Pendulum-v1_mixture.npy"  # an authors' file, torques halved
    released.write_bytes(b"")
    config = paper.grid_config(noisy, (released, 2.0), paper.BUDGETS["cpu"], None)
    flags = [
        "--env", "Pendulum-v1", "--demos", str(released), "--methods", ",".join(noisy.methods),
        "--seeds", "5", "--iterations", "500", "--chunk-iterations", "100",
        "--label-ratio", "0.2", "--noise", "0,0.2,0.4", "--action-scale", "2",
        "--out", str(tmp_path / "out"),
    ]  # fmt: skip
    assert config == sweep.parse_args(flags).config


def test_adoption_refuses_unfinished_and_different_sweeps(tmp_path):
    from pngail_jax.config.run_config import RunConfig
    from pngail_jax.paper.adopt import finished_sweep, matching_grid

    with pytest.raises(RunError, match="not a sweep run"):
        finished_sweep(tmp_path)
    (tmp_path / "config.json").write_text(json.dumps(RunConfig().to_dict()))
    (tmp_path / "summary.json").write_text(json.dumps(
        {"complete": False, "iterations_done": 100, "iterations": 300}
    ))  # fmt: skip
    with pytest.raises(RunError, match=r"not finished \(100 of 300 iterations\); finish it first"):
        finished_sweep(tmp_path)
    planned = {"Pendulum-v1-main": RunConfig(seeds=5, chunk_iterations=100)}
    saved = RunConfig(seeds=5, chunk_iterations=10).to_dict()
    assert matching_grid(tmp_path, saved, planned) == "Pendulum-v1-main"  # chunks aside
    saved["seeds"], saved["iterations"] = 3, 200
    with pytest.raises(
        RunError, match="not the plan's grid Pendulum-v1-main: seeds 3, the plan's 5; iterations"
    ):
        matching_grid(tmp_path, saved, planned)


def test_an_unset_action_scale_compares_as_the_scale_the_loader_applies():
    """A sweep of the authors' Pendulum file given no --action-scale runs on its known scale
    (2), as the plan's grid, which names it: adoptable. Another scale is not."""
    from pngail_jax.config.run_config import RunConfig
    from pngail_jax.paper.adopt import adoption_fields

    def config(scale, name="Pendulum-v1_mixture.npy"):
        return RunConfig(env="Pendulum-v1", demos=f"/data/{name}", action_scale=scale)

    assert adoption_fields(config(None)) == adoption_fields(config(2.0))
    assert adoption_fields(config(None)) != adoption_fields(config(1.0))
    assert adoption_fields(config(None, "Hopper-v2_mixture.npy"))["action_scale"] == 1.0


def test_the_made_experts_learner_is_the_demo_learner_and_the_grids_keep_theirs(
    tmp_path, monkeypatch
):
    """--demo-learner ppo trains the made sets' experts by PPO (a stronger Ant expert at the
    preset's budget) while every grid keeps --learner (TRPO, the paper's); the page says so."""
    from pngail_jax.paper import run as plan_run
    from pngail_jax.paper.page import learner_line

    seen = {}

    def demo_paths(grids, out, budget, released, physics, learner):
        seen["demos"] = learner
        return {}

    def planned_configs(grids, demos, budget, physics, learner):
        seen["grids"] = learner
        raise RunError("stop here")

    monkeypatch.setattr(plan_run, "demo_paths", demo_paths)
    monkeypatch.setattr(plan_run, "planned_configs", planned_configs)
    out = tmp_path / "p"
    argv = ["--preset", "test", "--envs", "Ant-v4", "--only", "fig2", "--out", str(out)]
    with pytest.raises(SystemExit, match="stop here"):
        paper.main([*argv, "--demo-learner", "ppo"])
    assert seen == {"demos": "ppo", "grids": "trpo"}
    options = json.loads((out / "paper.json").read_text())
    assert (options["learner"], options["demo_learner"]) == ("trpo", "ppo")
    assert learner_line(options) == (
        "Policy learner: TRPO, as the paper. The made demonstrations' experts were trained by PPO."
    )
    assert learner_line({"learner": "trpo"}) == "Policy learner: TRPO, as the paper."
    seen.clear()
    with pytest.raises(SystemExit, match="stop here"):  # by default, the grids' learner
        paper.main([*argv, "--learner", "ppo", "--overwrite"])
    assert seen == {"demos": "ppo", "grids": "ppo"}
