"""The output contract every program follows: an output directory is new, or empty, or a run
of the same program (marked when it was created) that the user asked to resume or to replace
with --overwrite; anything else is refused before any computation, naming what is in the way,
and nothing is written. --overwrite removes exactly the files the run listed as written."""

import argparse
import dataclasses
import json
import shutil
import time
from collections.abc import Callable
from fnmatch import fnmatch
from pathlib import Path

import pytest
from conftest import tiny_sweep_args
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pngail_jax.jobs import chunks
from pngail_jax.programs import cli, paper, sweep, train_rl
from pngail_jax.programs.cli import claim_output
from pngail_jax.storage import outputs
from pngail_jax.storage.outputs import (
    MARKER,
    OUTPUT_LIST,
    OutputRefused,
    claimed,
    output_owner,
    prepare_output,
    record_outputs,
)

PROGRAMS = ["sweep", "paper", "train_rl", "make_demos", "compare_settings"]


class Refused(Exception):
    pass


class Parser(argparse.ArgumentParser):
    def error(self, message):
        raise Refused(message)


def listing(directory):
    return sorted(
        (str(p.relative_to(directory)), p.read_bytes() if p.is_file() else None)
        for p in directory.rglob("*")
    )


NAMES = ["README.md", "results.json", "metrics.csv", "notes", "config.json", "fig.png"] + [
    name for names in outputs.LEGACY_MARKS.values() for name in names
]


@settings(
    max_examples=80,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    names=st.lists(st.sampled_from(NAMES), max_size=3, unique=True),
    marker=st.none() | st.sampled_from(PROGRAMS),
    listed=st.none() | st.sets(st.sampled_from(NAMES), max_size=3),
    program=st.sampled_from(PROGRAMS),
    overwrite=st.booleans(),
    exists=st.booleans(),
)
def test_the_decision_over_any_contents_and_flags(
    tmp_path_factory, names, marker, listed, program, overwrite, exists
):
    directory = tmp_path_factory.mktemp("out") / "run"
    has_list = exists and marker is not None and listed is not None
    if exists:
        directory.mkdir()
        for name in names:
            (directory / name).write_text("theirs")
        if marker is not None:
            (directory / MARKER).write_text(json.dumps({"program": marker}))
        if has_list:
            (directory / OUTPUT_LIST).write_text(
                json.dumps({"program": marker, "files": sorted(listed)})
            )
    before = listing(directory) if exists else None
    empty = not exists or not (names or marker)
    owner = output_owner(directory) if exists else None
    marker_alone = not names and marker == program  # left by a start that failed: empty
    if has_list:  # only what the run listed is its own
        foreign, unknown = [n for n in names if n not in listed], []
    else:  # a run from before the lists: only names it writes exactly (no wildcard) are its own
        foreign = [n for n in names if not any(fnmatch(n, p) for p in outputs.OWNED[program])]
        unknown = [n for n in names if n not in foreign and n not in outputs.OWNED[program]]
    allowed = (
        empty or marker_alone or (owner == program and overwrite and not foreign and not unknown)
    )
    try:
        claim_output(Parser(), directory, program, overwrite)
        assert allowed, (names, marker, listed, program, overwrite)
    except Refused as refusal:
        assert not allowed
        message = str(refusal)
        if owner == program and overwrite and foreign:  # its run, and files it never wrote
            assert "--overwrite replaces only its own" in message
            assert all(name in message for name in foreign)
        elif owner == program and overwrite:  # fig.png beside a page's *.png: whose?
            assert f"made before runs listed their files ({OUTPUT_LIST})" in message
            assert "delete the run yourself" in message and unknown[0] in message
        elif owner == program:
            assert "pass --overwrite to replace it" in message
        elif owner is not None:
            assert f"it holds a run of experiments.{owner}" in message
        else:
            assert all(name in message for name in names)  # names what is in the way
    assert (listing(directory) if exists else None) == before  # nothing written
    assert exists or not directory.exists()


def test_prepare_marks_a_run_and_overwrite_removes_exactly_what_it_listed(tmp_path):
    run = tmp_path / "run"
    prepare_output(run, "sweep")
    assert output_owner(run) == "sweep"
    assert json.loads((run / OUTPUT_LIST).read_text()) == {"program": "sweep", "files": []}
    (run / "metrics.csv").write_text("old")
    (run / "checkpoints" / "chunk_0001").mkdir(parents=True)
    (run / "checkpoints" / "chunk_0001" / "state").write_text("old")
    (run / "policies").mkdir()  # an empty folder of the run's: listed with a trailing /
    (run / "notes.txt").write_text("mine")  # not a name the sweep writes: never listed
    listed = record_outputs(run, "sweep", since=0.0)  # as if the run wrote all of them
    assert listed == ["checkpoints/chunk_0001/state", "metrics.csv", "policies/"]
    before = listing(run)
    with pytest.raises(OutputRefused, match=r"files it did not make \(notes.txt\)"):
        prepare_output(run, "sweep", overwrite=True)  # removes nothing then
    assert listing(run) == before
    (run / "notes.txt").unlink()
    prepare_output(run, "sweep", overwrite=True)  # its own run: emptied, marked again
    assert sorted(p.name for p in run.iterdir()) == sorted([MARKER, OUTPUT_LIST])
    (run / "summary.md").write_text("old")
    record_outputs(run, "sweep", 0.0)
    (run / "my-notes.txt").write_text("mine")  # a user's file: never removed
    (run / "plots").mkdir()
    with pytest.raises(OutputRefused, match=r"files it did not make \(my-notes.txt, plots\)"):
        prepare_output(run, "sweep", overwrite=True)
    assert sorted(p.name for p in run.iterdir()) == sorted(
        [MARKER, OUTPUT_LIST, "my-notes.txt", "plots", "summary.md"]
    )
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "keep.txt").write_text("mine")
    (theirs / MARKER).write_text(json.dumps({"program": "paper"}))
    prepare_output(theirs, "sweep", overwrite=True)  # not its own: nothing removed
    assert (theirs / "keep.txt").read_text() == "mine"


def test_a_run_lists_only_what_appeared_after_its_claim_began(tmp_path, capsys):
    """A user's file put into a run between two of its sessions (older than the resumed
    claim) is not taken for the run's, though it lies in the run's own checkpoints/."""
    run = tmp_path / "run"
    with claimed(run, "sweep") as claim:
        claim.prepare()
        (run / "checkpoints").mkdir()
        (run / "checkpoints" / "chunk_0001").write_text("the run's")
    users = run / "checkpoints" / "mine.txt"
    users.write_text("the user's")
    while filesystem_now(tmp_path) <= users.stat().st_ctime:  # the file older than the claim
        time.sleep(0.01)
    with claimed(run, "sweep", resume=True):
        (run / "summary.md").write_text("the run's")
    listed = json.loads((run / OUTPUT_LIST).read_text())["files"]
    assert listed == ["checkpoints/chunk_0001", "summary.md"]
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        sweep.parse_args(["--out", str(run), "--overwrite"])
    assert (
        f"--out {run} holds a run of experiments.sweep and files it did not make "
        "(checkpoints/mine.txt): --overwrite replaces only its own"
    ) in capsys.readouterr().err


def test_a_run_inside_a_run_is_in_both_lists_once_it_ends(tmp_path):
    """A plan's grid is a sweep of its own inside the plan's folder: when the grid's claim
    ends, the plan lists what it wrote too (a plan killed then has them listed)."""
    plan = tmp_path / "plan"
    with claimed(plan, "paper") as outer:
        outer.prepare()
        grid = plan / "grids" / "Pendulum-v1-main"
        with claimed(grid, "sweep") as inner:
            inner.prepare()
            (grid / "summary.json").write_text("{}")
        assert json.loads((grid / OUTPUT_LIST).read_text())["files"] == ["summary.json"]
        assert "grids/Pendulum-v1-main/summary.json" in listed_files(plan)
    assert outputs.overwrite_refusal(plan, "paper") is None
    prepare_output(plan, "paper", overwrite=True)
    assert sorted(p.name for p in plan.iterdir()) == sorted([MARKER, OUTPUT_LIST])


def test_a_run_from_before_the_lists_is_replaced_only_where_names_tell(tmp_path, capsys):
    """Without a list, a folder (checkpoints/) or a wildcard's name (mine.png beside a page's
    *.png) cannot be told from the user's: refused, the user deletes the run; a run holding
    only files of names its program writes exactly is replaced as before."""
    old = tmp_path / "old-sweep"
    (old / "checkpoints" / "chunk_0001").mkdir(parents=True)
    (old / "checkpoints" / "chunk_0001" / "state").write_text("the run's, or the user's?")
    (old / "config.json").write_text(json.dumps({"resolved": {}}))
    before = listing(old)
    with pytest.raises(SystemExit, match="^2$"):
        sweep.parse_args(["--out", str(old), "--overwrite"])
    assert (
        f"--out {old} holds a run of experiments.sweep made before runs listed their files "
        f"({OUTPUT_LIST}): --overwrite cannot tell its files in checkpoints from others; delete "
        "the run yourself, or choose another --out"
    ) in capsys.readouterr().err
    with pytest.raises(OutputRefused, match="made before runs listed their files"):
        prepare_output(old, "sweep", overwrite=True)
    assert listing(old) == before
    page = tmp_path / "old-page"
    page.mkdir()
    (page / MARKER).write_text(json.dumps({"program": "paper-page"}))
    for name in ("README.md", "results.json", "mine.png"):
        (page / name).write_text("?")
    assert "its files in mine.png from others" in outputs.output_refusal(page, "paper-page", True)
    (page / "mine.png").unlink()
    assert outputs.output_refusal(page, "paper-page", True) is None
    prepare_output(page, "paper-page", overwrite=True)
    assert sorted(p.name for p in page.iterdir()) == sorted([MARKER, OUTPUT_LIST])
    (page / "README.md").write_text("the page's")
    (page / OUTPUT_LIST).write_text("[")  # a damaged list: nothing is taken for the run's
    assert "delete the run yourself" in outputs.output_refusal(page, "paper-page", True)


@pytest.mark.parametrize(
    ("program", "argv", "message"),
    [
        (sweep, ["--out", ""], "argument --out: must name a path, got ''"),
        (paper, ["--out", ""], "argument --out: must name a path, got ''"),
        (paper, ["--only", ""], "--only: empty item in '' (expected comma-separated figure names)"),
        (paper, ["--envs", ""], "--envs: empty item in '' (expected comma-separated task names)"),
        (train_rl, ["--out", ""], "argument --out: must name a path, got ''"),
        (sweep, ["--demos", ""], "argument --demos: must name a path, got ''"),
    ],
)
def test_empty_strings_are_refused_not_read_as_here_or_everything(program, argv, message, capsys):
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        program.parse_args(argv)
    assert f": error: {message} (usage: python -m experiments." in capsys.readouterr().err


def test_each_program_refuses_a_directory_it_did_not_make(tmp_path, capsys):
    checkout = tmp_path / "checkout"  # e.g. a checkout's own README.md
    checkout.mkdir()
    (checkout / "README.md").write_text("the project's")
    (checkout / "results.json").write_text("{}")
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        paper.parse_args(["--out", str(checkout)])
    err = capsys.readouterr().err
    assert f"--out {checkout} is not empty: it holds files it did not make (README.md, " in err
    assert "results.json); experiments.paper writes only into a new or empty directory" in err
    metrics = tmp_path / "analysis"
    metrics.mkdir()
    (metrics / "metrics.csv").write_text("mine")
    with pytest.raises(SystemExit, match="^2$"):
        sweep.parse_args(["--out", str(metrics)])
    assert f"--out {metrics} is not empty: it holds files it did not make (metrics.csv)" in (
        capsys.readouterr().err
    )
    finished_sweep = tmp_path / "sweep-run"
    prepare_output(finished_sweep, "sweep")
    (finished_sweep / "config.json").write_text("{}")
    record_outputs(finished_sweep, "sweep", since=0.0)  # listed, as the run lists what it wrote
    with pytest.raises(SystemExit, match="^2$"):
        train_rl.parse_args(["--out", str(finished_sweep)])
    assert (
        f"--out {finished_sweep} is not empty: it holds a run of experiments.sweep; "
        "experiments.train_rl writes only into a new or empty directory"
    ) in capsys.readouterr().err
    with pytest.raises(SystemExit, match="^2$"):
        sweep.parse_args(["--out", str(finished_sweep)])
    assert (
        f"--out {finished_sweep} already holds a run of experiments.sweep: --resume "
        f"{finished_sweep} to continue it, pass --overwrite"
    ) in capsys.readouterr().err
    assert sweep.parse_args(["--out", str(finished_sweep), "--overwrite"]).out == finished_sweep
    (finished_sweep / "notes.txt").write_text("the user's")  # --overwrite would not remove it
    (finished_sweep / "my-plots").mkdir()
    with pytest.raises(SystemExit, match="^2$"):
        sweep.parse_args(["--out", str(finished_sweep), "--overwrite"])
    assert (
        f"--out {finished_sweep} holds a run of experiments.sweep and files it did not make "
        "(my-plots, notes.txt)"
    ) in capsys.readouterr().err
    assert (finished_sweep / "notes.txt").read_text() == "the user's"
    paper_run = tmp_path / "paper-run"
    prepare_output(paper_run, "paper")
    with pytest.raises(SystemExit, match="^2$"):
        sweep.parse_args(["--resume", str(paper_run)])
    assert f"--resume {paper_run} holds a run of experiments.paper, not a sweep" in (
        capsys.readouterr().err
    )
    for name in ("README.md", "results.json"):
        assert (checkout / name).exists()  # untouched
    assert (metrics / "metrics.csv").read_text() == "mine"


def test_the_run_lock_refuses_a_live_holder_and_takes_over_a_dead_ones(tmp_path, capsys):
    import os
    import subprocess
    import sys

    from pngail_jax.storage.outputs import LOCK, RunLocked, run_lock

    with run_lock(tmp_path, "sweep"):
        holder = json.loads((tmp_path / LOCK).read_text())
        assert holder["pid"] == os.getpid()
        with pytest.raises(RunLocked, match=rf"in use by experiments.sweep, process {os.getpid()}"):
            with run_lock(tmp_path, "sweep"):
                pass
    assert not (tmp_path / LOCK).exists()  # released
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)  # fmt: skip
    pid = int(gone.stdout)
    (tmp_path / LOCK).write_text(json.dumps({"pid": pid, "host": os.uname().nodename}))
    with run_lock(tmp_path, "sweep"):
        assert json.loads((tmp_path / LOCK).read_text())["pid"] == os.getpid()
    assert f"taking over {tmp_path / LOCK}, left by process {pid}" in capsys.readouterr().err
    with pytest.raises(KeyboardInterrupt), run_lock(tmp_path, "sweep"):
        raise KeyboardInterrupt  # Ctrl-C: the lock goes with it
    assert not (tmp_path / LOCK).exists()


@pytest.mark.parametrize("name", ["SIGTERM", "SIGINT"])
def test_a_signal_outside_a_chunk_stops_at_once_and_the_lock_goes_with_it(tmp_path, name):
    """SIGTERM is a batch scheduler's at a job's time limit: without the handler the process
    died with its lock left (a resume on another host is then refused)."""
    import os
    import signal
    import time

    from pngail_jax.programs.cli import signals_stop_at_a_checkpoint
    from pngail_jax.storage.outputs import LOCK, run_lock

    number = signal.Signals[name]
    before = {n: signal.getsignal(n) for n in (signal.SIGINT, signal.SIGTERM)}
    with pytest.raises(KeyboardInterrupt, match=name):
        with signals_stop_at_a_checkpoint(), run_lock(tmp_path / "run", "sweep"):
            assert (tmp_path / "run" / LOCK).exists()
            os.kill(os.getpid(), number)
            time.sleep(30)  # the handler raises here, at once
    assert not (tmp_path / "run" / LOCK).exists()
    assert {n: signal.getsignal(n) for n in before} == before  # restored on leaving


def test_a_failing_environment_factory_or_cache_path_is_one_line(tmp_path, monkeypatch):
    import sys
    import types

    from pngail_jax import envs

    module = types.ModuleType("user_envs")

    def raises():
        raise RuntimeError("boom")

    module.raises, module.wrong = raises, lambda: 42
    monkeypatch.setitem(sys.modules, "user_envs", module)
    with pytest.raises(ValueError, match="user_envs:raises: the factory raised RuntimeError: boom"):
        envs.make("user_envs:raises")
    with pytest.raises(ValueError, match="the factory returned a int, not a pngail_jax.envs.Env"):
        envs.make("user_envs:wrong")
    cache_file = tmp_path / "cache"
    cache_file.write_text("")
    args = argparse.Namespace(no_compile_cache=False, compile_cache=cache_file)
    with pytest.raises(SystemExit, match=f"--compile-cache: compilation cache {cache_file} is a"):
        cli.use_compile_cache(args)


def test_a_config_files_log_backend_is_checked_before_anything_runs(tmp_path, monkeypatch, capsys):
    from pngail_jax.config.run_config import RunConfig

    def missing(backends):
        if "wandb" in backends:
            raise ImportError("the 'wandb' tracking backend needs wandb: pip install wandb")

    monkeypatch.setattr(sweep, "check_backends", missing)
    config = tmp_path / "config.json"
    config.write_text(json.dumps({**RunConfig().to_dict(), "log": ["wandb"]}))
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        sweep.parse_args(["--config", str(config), "--out", str(tmp_path / "run")])
    assert "log ['wandb']: the 'wandb' tracking backend needs wandb" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_an_unwritable_output_is_refused_before_any_computation(tmp_path, monkeypatch):
    import os

    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: p != tmp_path and real(p, mode))
    reason = outputs.output_refusal(tmp_path / "run", "sweep")  # as root, chmod would not tell
    assert (
        reason
        == f"--out {tmp_path / 'run'}: {tmp_path} is not writable (read-only disk or permissions)"
    )


def test_runs_made_before_the_marker_are_known_by_their_own_files(tmp_path):
    def folder(name, files):
        directory = tmp_path / name
        directory.mkdir()
        for file, text in files.items():
            (directory / file).write_text(text)
        return directory

    assert output_owner(folder("sweep", {"config.json": '{"resolved": {}}'})) == "sweep"
    trpo = folder("trpo", {"config.json": '{"trpo": {}}', "policy.json": "{}"})
    assert output_owner(trpo) == "train_rl"  # not a sweep: its config.json has no "resolved"
    assert output_owner(folder("cut", {"config.json": '{"trpo": {}}'})) == "train_rl"
    # Today's layout (analysis.runs.run_document) names its program beside "resolved".
    today = '{"program": "train_rl", "family": "reinforcement", "config": {}, "resolved": {}}'
    assert output_owner(folder("today", {"config.json": today})) == "train_rl"
    assert output_owner(folder("demos", {"normalizer.json": "{}"})) == "make_demos"
    assert output_owner(folder("mine", {"config.json": '{"lr": 3}'})) is None  # not ours
    reason = outputs.output_refusal(tmp_path / "mine", "sweep", overwrite=True)
    assert "files it did not make (config.json)" in reason  # --overwrite cannot empty it


# -- real runs: a user's file anywhere in a run folder stops --overwrite, which deletes nothing;
# without one, --overwrite replaces the run and leaves no file of the old one.

OFFLINE_FLAGS = [
    "--methods", "bc-all", "--seeds", "2", "--gradient-steps", "40", "--steps-per-iteration",
    "10", "--eval-every", "2", "--chunk-iterations", "2", "--batch-size", "8",
]  # fmt: skip


@dataclasses.dataclass
class TinyRun:
    """A finished tiny run of ``program`` in ``out``; ``main(out, *flags)`` runs it again into
    ``out``; ``lists``: its list of files after each chunk (what a run killed then keeps)."""

    program: str
    out: Path
    main: Callable
    lists: list


def tiny_run(program, main, out) -> TinyRun:
    lists = []
    real = chunks.record_held_outputs

    def recording(path):
        real(path)
        lists.append(json.loads((out / OUTPUT_LIST).read_text())["files"])

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(chunks, "record_held_outputs", recording)
        main(out)
    return TinyRun(program, out, main, lists)


@pytest.fixture(scope="module")
def sweep_run(demos_path, tmp_path_factory):
    def main(out, *flags):
        return sweep.main([*tiny_sweep_args(demos_path, out), *flags])

    return tiny_run("sweep", main, tmp_path_factory.mktemp("sweep") / "run")


@pytest.fixture(scope="module")
def offline_run(demos_path, tmp_path_factory):
    from pngail_jax.programs import offline

    def main(out, *flags):
        return offline.main(["--demos", str(demos_path), *OFFLINE_FLAGS, "--out", str(out), *flags])

    return tiny_run("offline", main, tmp_path_factory.mktemp("offline") / "run")


def newest(folder: Path) -> str:
    return sorted(path.name for path in folder.iterdir())[-1]


def listed_files(run: Path) -> set[str]:
    return {name for name in json.loads((run / OUTPUT_LIST).read_text())["files"]
            if not name.endswith("/")}  # fmt: skip


def files_in(run: Path) -> set[str]:
    found = {path.relative_to(run).as_posix() for path in run.rglob("*") if path.is_file()}
    return found - {MARKER, OUTPUT_LIST}


def filesystem_now(folder: Path) -> float:
    """The time by the filesystem's own clock (which lags ``time.time()`` by up to a tick)."""
    probe = folder / "now"
    probe.write_text("")
    return probe.stat().st_mtime


def test_each_run_lists_every_file_it_wrote_and_did_so_after_each_chunk(sweep_run, offline_run):
    for run in (sweep_run, offline_run):
        assert listed_files(run.out) == files_in(run.out)
        assert len(run.lists) == 2  # two chunks
        first = run.lists[0]  # the list a run killed after its first chunk keeps
        assert "config.json" in first
        assert any(name.startswith("checkpoints/") and "chunk_0001/" in name for name in first)


USERS_FILES = {
    "sweep": ["notes.txt", "checkpoints/mine.txt", "checkpoints/{newest}/mine.txt",
              "policies/mine.txt", "policies/gail/mine.txt", "wandb/mine.txt", "mine.png"],
    "offline": ["notes.txt", "checkpoints/mine.txt", "checkpoints/bc-all/mine.txt",
                "checkpoints/bc-all/{newest}/mine.txt", "wandb/mine.txt", "mine.png"],
}  # fmt: skip


@pytest.mark.parametrize(
    ("program", "where"), [(p, where) for p, places in USERS_FILES.items() for where in places]
)
def test_overwrite_refuses_a_users_file_anywhere_in_a_run_and_deletes_nothing(
    program, where, request, tmp_path, capsys
):
    run = request.getfixturevalue(f"{program}_run")
    copy = tmp_path / "run"
    shutil.copytree(run.out, copy)
    if "{newest}" in where:  # the newest checkpoint's folder
        where = where.format(newest=newest(copy / Path(where).parent.parent))
    users = copy / where
    users.parent.mkdir(parents=True, exist_ok=True)
    users.write_text("the user's")
    before = listing(copy)
    named = "wandb" if where.startswith("wandb/") else where  # a folder the run never wrote
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        run.main(copy, "--overwrite")
    assert (
        f"--out {copy} holds a run of experiments.{program} and files it did not make "
        f"({named}): --overwrite replaces only its own"
    ) in capsys.readouterr().err
    with pytest.raises(OutputRefused, match="files it did not make"):  # past the parser
        with claimed(copy, program, overwrite=True):
            pass
    with pytest.raises(OutputRefused, match="files it did not make"):
        prepare_output(copy, program, overwrite=True)
    assert listing(copy) == before  # the user's file, and every file of the run's, kept


@pytest.mark.parametrize("program", ["sweep", "offline"])
def test_overwrite_replaces_a_run_and_leaves_no_stale_file(program, request, tmp_path):
    run = request.getfixturevalue(f"{program}_run")
    copy = tmp_path / "run"
    shutil.copytree(run.out, copy)
    checkpoints = copy / "checkpoints" / ("" if program == "sweep" else "bc-all")
    stale = checkpoints / "chunk_0000" / "progress.json"  # one the new run does not write
    stale.parent.mkdir()
    stale.write_text("{}")
    record_outputs(copy, program, since=0.0)  # listed, as the old run would have
    started = filesystem_now(tmp_path)
    run.main(copy, "--overwrite")
    assert not stale.parent.exists()
    assert files_in(copy) == listed_files(copy)
    for name in files_in(copy):  # each written by the new run
        status = (copy / name).lstat()
        assert max(status.st_mtime, status.st_ctime) >= started, name


def test_a_comparison_keeps_a_users_png_and_is_replaced_without_it(sweep_run, tmp_path, capsys):
    """The compare program writes *.png: a user's mine.png there is not its own."""
    from pngail_jax.programs import compare

    out = tmp_path / "comparison"
    argv = [str(sweep_run.out), "--out", str(out)]
    compare.main(argv)
    assert listed_files(out) == files_in(out)
    (out / "mine.png").write_text("the user's")
    before = listing(out)
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        compare.main([*argv, "--overwrite"])
    assert (
        f"--out {out} holds a run of experiments.compare and files it did not make (mine.png)"
    ) in capsys.readouterr().err
    assert listing(out) == before
    (out / "mine.png").unlink()
    (out / "old.png").write_text("a figure the comparison no longer draws")
    record_outputs(out, "compare", since=0.0)
    compare.main([*argv, "--overwrite"])
    assert not (out / "old.png").exists() and files_in(out) == listed_files(out)


def test_a_page_folder_keeps_a_users_png(tmp_path):
    """A results page (paper --page) writes README.md, results.json and *.png, as here."""
    page = tmp_path / "page"
    with claimed(page, "paper-page") as claim:
        claim.prepare()
        for name in ("README.md", "results.json", "fig2.png"):
            (page / name).write_text("the page's")
    (page / "mine.png").write_text("the user's")
    before = listing(page)
    assert "files it did not make (mine.png)" in outputs.output_refusal(page, "paper-page", True)
    with pytest.raises(OutputRefused, match=r"\(mine.png\)"):
        prepare_output(page, "paper-page", overwrite=True)
    assert listing(page) == before
    (page / "mine.png").unlink()
    with claimed(page, "paper-page", overwrite=True) as claim:
        claim.prepare()
    assert sorted(p.name for p in page.iterdir()) == sorted([MARKER, OUTPUT_LIST])
