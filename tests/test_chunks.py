"""The chunk step's start and checkpoints (``pngail_jax.jobs.chunks``) on a toy trainer: a
start saved before the first chunk, and a resume that restores the grid's initial metrics from
its checkpoint instead of running the init again (ILID's discriminators run an hour there)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax.grid import Grid
from pngail_jax.jobs import chunks
from pngail_jax.storage.integrity import write_manifest


class RandomWalk:
    """A trainer of the grid's interface: each cell walks by ``scale``-sized Gaussian steps;
    its init measures ``start`` (a draw, so a re-run init is told apart only by running)."""

    eval_every = 2

    def init(self, scale, key):
        key, first = jax.random.split(key)
        start = jax.random.normal(first) * scale
        return {"position": start, "key": key}, {"start": start}

    def run_blocks(self, scale, state, num_blocks):
        key, steps = jax.random.split(state["key"])
        moves = jax.random.normal(steps, (num_blocks * self.eval_every,)) * scale
        path = state["position"] + jnp.cumsum(moves)
        return {"position": path[-1], "key": key}, {"eval/return": path}


def make_grid():
    inputs = (jnp.array([1.0, 0.5, 2.0]), jax.random.split(jax.random.key(3), 3))
    return Grid(RandomWalk(), inputs, blocks_per_chunk=1)


def run(grid, state, progress, checkpoints, num_chunks=3):
    chunks.run_chunks(grid, state, progress, num_chunks, steps_per_chunk=6,
                      line=lambda *_: "", checkpoints=checkpoints)  # fmt: skip
    return progress


def test_a_saved_start_resumes_without_running_the_init_again(tmp_path, monkeypatch):
    """``start(save_to=...)`` writes chunk_0000 (no chunk metrics, the init's metrics) before
    the first chunk; a resume from it, or from a later chunk, restores the state and the
    init's metrics without calling the grid's init, and runs to the uninterrupted run's
    metrics bit for bit."""
    grid = make_grid()
    state, progress = chunks.start(grid, None, save_to=tmp_path / "saved")
    start_checkpoint = tmp_path / "saved" / "chunk_0000"
    assert chunks.intact_checkpoint(tmp_path / "saved") == start_checkpoint
    whole = run(grid, state, progress, tmp_path / "whole")

    def no_init():
        raise AssertionError("the init ran again")

    monkeypatch.setattr(grid, "init", no_init)
    for checkpoint in (start_checkpoint, tmp_path / "whole" / "chunk_0002"):
        state, resumed = chunks.start(grid, checkpoint)
        assert resumed.chunks_done == int(checkpoint.name[-1])
        resumed = run(grid, state, resumed, tmp_path / f"from-{checkpoint.name}")
        np.testing.assert_array_equal(resumed.init_metrics["start"], whole.init_metrics["start"])
        np.testing.assert_array_equal(resumed.metrics["eval/return"], whole.metrics["eval/return"])
        assert resumed.metrics["eval/return"].shape == (3, 6)


def test_a_checkpoint_without_the_init_metrics_runs_the_init_for_them(tmp_path):
    """A checkpoint written before its files kept the init's metrics (this version's older
    ones) resumes as it did: the init runs for its metrics, the state comes from the file."""
    grid = make_grid()
    state, progress = chunks.start(grid, None)
    whole = run(grid, state, progress, tmp_path / "whole")
    older = tmp_path / "whole" / "chunk_0002"
    (older / chunks.INIT_METRICS).unlink()
    write_manifest(older)
    calls = []
    original = grid.init

    def counted():
        calls.append(1)
        return original()

    grid.init = counted
    state, resumed = chunks.start(grid, older)
    assert calls == [1]
    resumed = run(grid, state, resumed, tmp_path / "resumed")
    np.testing.assert_array_equal(resumed.init_metrics["start"], whole.init_metrics["start"])
    np.testing.assert_array_equal(resumed.metrics["eval/return"], whole.metrics["eval/return"])


def test_a_checkpoint_of_another_grid_is_refused_in_one_line(tmp_path):
    grid = make_grid()
    chunks.start(grid, None, save_to=tmp_path)
    other = Grid(RandomWalk(), (jnp.ones(2), jax.random.split(jax.random.key(0), 2)), 1)
    with pytest.raises(chunks.RunError, match="^cannot resume from .*chunk_0000: "):
        chunks.start(other, tmp_path / "chunk_0000")
