"""The output contract every program follows: an output directory is new, or empty, or a run
of the same program (marked when it was created) that the user asked to resume or to replace
with --overwrite; anything else is refused before any computation, naming what is in the way,
and nothing is written."""

import argparse
import json
from fnmatch import fnmatch

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pngail_jax import outputs
from pngail_jax.outputs import MARKER, output_owner, prepare_output
from pngail_jax.programs import cli, paper, sweep, train_rl
from pngail_jax.programs.cli import claim_output

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


@settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    names=st.lists(
        st.sampled_from(
            ["README.md", "results.json", "metrics.csv", "notes", "config.json"]
            + [name for names in outputs.LEGACY_MARKS.values() for name in names]
        ),
        max_size=3,
        unique=True,
    ),
    marker=st.none() | st.sampled_from(PROGRAMS),
    program=st.sampled_from(PROGRAMS),
    overwrite=st.booleans(),
    exists=st.booleans(),
)
def test_the_decision_over_any_contents_and_flags(
    tmp_path_factory, names, marker, program, overwrite, exists
):
    directory = tmp_path_factory.mktemp("out") / "run"
    if exists:
        directory.mkdir()
        for name in names:
            (directory / name).write_text("theirs")
        if marker is not None:
            (directory / MARKER).write_text(json.dumps({"program": marker}))
    before = listing(directory) if exists else None
    empty = not exists or not (names or marker)
    owner = output_owner(directory) if exists else None
    marker_alone = not names and marker == program  # left by a start that failed: empty
    foreign = [n for n in names if not any(fnmatch(n, p) for p in outputs.OWNED[program])]
    allowed = empty or marker_alone or (owner == program and overwrite and not foreign)
    try:
        claim_output(Parser(), directory, program, overwrite)
        assert allowed, (names, marker, program, overwrite)
    except Refused as refusal:
        assert not allowed
        message = str(refusal)
        if owner == program and overwrite:  # its run, and files it never writes
            assert "--overwrite replaces only its own" in message
            assert all(name in message for name in foreign)
        elif owner == program:
            assert "pass --overwrite to replace it" in message
        elif owner is not None:
            assert f"it holds a run of experiments.{owner}" in message
        else:
            assert all(name in message for name in names)  # names what is in the way
    assert (listing(directory) if exists else None) == before  # nothing written
    assert exists or not directory.exists()


def test_a_marker_wins_over_legacy_files_and_prepare_marks_and_empties_only_its_own(tmp_path):
    run = tmp_path / "run"
    prepare_output(run, "sweep")
    assert output_owner(run) == "sweep"
    (run / "metrics.csv").write_text("old")
    (run / "checkpoints").mkdir()
    prepare_output(run, "sweep", overwrite=True)  # its own run: emptied, marked again
    assert sorted(p.name for p in run.iterdir()) == [MARKER]
    (run / "summary.md").write_text("old")
    (run / "my-notes.txt").write_text("mine")  # a user's file: never removed
    (run / "plots").mkdir()
    prepare_output(run, "sweep", overwrite=True)
    assert sorted(p.name for p in run.iterdir()) == [MARKER, "my-notes.txt", "plots"]
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "keep.txt").write_text("mine")
    (theirs / MARKER).write_text(json.dumps({"program": "paper"}))
    prepare_output(theirs, "sweep", overwrite=True)  # not its own: nothing removed
    assert (theirs / "keep.txt").read_text() == "mine"


@pytest.mark.parametrize(
    ("program", "argv", "message"),
    [
        (sweep, ["--out", ""], "argument --out: must name a path, got ''"),
        (paper, ["--out", ""], "argument --out: must name a path, got ''"),
        (paper, ["--only", ""], "--only: empty item in ''"),
        (paper, ["--envs", ""], "--envs: empty item in ''"),
        (train_rl, ["--out", ""], "argument --out: must name a path, got ''"),
        (sweep, ["--demos", ""], "argument --demos: must name a path"),
    ],
)
def test_empty_strings_are_refused_not_read_as_here_or_everything(program, argv, message, capsys):
    with pytest.raises(SystemExit):
        program.parse_args(argv)
    assert message in capsys.readouterr().err


def test_each_program_refuses_a_directory_it_did_not_make(tmp_path, capsys):
    checkout = tmp_path / "checkout"  # e.g. a checkout's own README.md
    checkout.mkdir()
    (checkout / "README.md").write_text("the project's")
    (checkout / "results.json").write_text("{}")
    with pytest.raises(SystemExit):
        paper.parse_args(["--out", str(checkout)])
    err = capsys.readouterr().err
    assert "is not empty: it holds files it did not make (README.md, results.json)" in err
    metrics = tmp_path / "analysis"
    metrics.mkdir()
    (metrics / "metrics.csv").write_text("mine")
    with pytest.raises(SystemExit):
        sweep.parse_args(["--out", str(metrics)])
    assert "files it did not make (metrics.csv)" in capsys.readouterr().err
    finished_sweep = tmp_path / "sweep-run"
    prepare_output(finished_sweep, "sweep")
    (finished_sweep / "config.json").write_text("{}")
    with pytest.raises(SystemExit):
        train_rl.parse_args(["--out", str(finished_sweep)])
    assert "it holds a run of experiments.sweep" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        sweep.parse_args(["--out", str(finished_sweep)])
    assert f"--resume {finished_sweep} to continue it, pass --overwrite" in (
        capsys.readouterr().err
    )
    assert sweep.parse_args(["--out", str(finished_sweep), "--overwrite"]).out == finished_sweep
    (finished_sweep / "notes.txt").write_text("the user's")  # --overwrite would not remove it
    (finished_sweep / "my-plots").mkdir()
    with pytest.raises(SystemExit):
        sweep.parse_args(["--out", str(finished_sweep), "--overwrite"])
    assert "holds a run of experiments.sweep and files it did not make (my-plots, notes.txt)" in (
        capsys.readouterr().err
    )
    assert (finished_sweep / "notes.txt").read_text() == "the user's"
    paper_run = tmp_path / "paper-run"
    prepare_output(paper_run, "paper")
    with pytest.raises(SystemExit):
        sweep.parse_args(["--resume", str(paper_run)])
    assert "holds a run of experiments.paper, not a sweep" in capsys.readouterr().err
    for name in ("README.md", "results.json"):
        assert (checkout / name).exists()  # untouched
    assert (metrics / "metrics.csv").read_text() == "mine"


def test_the_run_lock_refuses_a_live_holder_and_takes_over_a_dead_ones(tmp_path, capsys):
    import os
    import subprocess
    import sys

    from pngail_jax.outputs import LOCK, RunLocked, run_lock

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

    from pngail_jax.outputs import LOCK, run_lock
    from pngail_jax.programs.cli import signals_stop_at_a_checkpoint

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
    from pngail_jax.run_config import RunConfig

    def missing(backends):
        if "wandb" in backends:
            raise ImportError("the 'wandb' tracking backend needs wandb: pip install wandb")

    monkeypatch.setattr(sweep, "check_backends", missing)
    config = tmp_path / "config.json"
    config.write_text(json.dumps({**RunConfig().to_dict(), "log": ["wandb"]}))
    with pytest.raises(SystemExit):
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
    assert output_owner(folder("demos", {"normalizer.json": "{}"})) == "make_demos"
    assert output_owner(folder("mine", {"config.json": '{"lr": 3}'})) is None  # not ours
    reason = outputs.output_refusal(tmp_path / "mine", "sweep", overwrite=True)
    assert "files it did not make (config.json)" in reason  # --overwrite cannot empty it
