"""What the benchmarks share: the context every row records, timing, the environment-only
ceiling, memory, Markdown tables and JSON rows. Imported by the scripts beside it (a script's
folder is first on its import path) and by tests/test_benchmarks.py."""

from __future__ import annotations

import json
import os
import statistics
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

NUM_REPEATS = 3  # timed calls per measurement; their median is reported


def device_description() -> str:
    """``cpu (N cores)`` or ``gpu: <kind>``."""
    device = jax.devices()[0]
    if device.platform == "cpu":
        return f"cpu ({os.cpu_count()} cores)"
    return f"{device.platform}: {device.device_kind}"


def context() -> dict:
    """The fields every benchmark row carries: where and with which JAX it was measured."""
    return {"device": device_description(), "jax_version": jax.__version__}


def median_seconds(program, *args, repeats: int = NUM_REPEATS) -> float:
    """Median wall time of ``repeats`` calls of ``program(*args)``, after one warm-up call."""
    jax.block_until_ready(program(*args))
    timings = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(program(*args))
        timings.append(time.perf_counter() - start)
    return statistics.median(timings)


def time_grid_chunks(grid, repeats: int = NUM_REPEATS):
    """``(state, metrics, init seconds, median chunk seconds)`` of a compiled
    ``pngail_jax.grid.Grid``: its init, one warm-up chunk, then ``repeats`` timed chunks
    (run_chunk donates its state: each call keeps the new one)."""
    start = time.perf_counter()
    state, _ = grid.init()
    jax.block_until_ready(state)
    init_seconds = time.perf_counter() - start
    state, metrics = grid.run_chunk(state)
    jax.block_until_ready((state, metrics))
    timings = []
    for _ in range(repeats):
        start = time.perf_counter()
        state, metrics = grid.run_chunk(state)
        jax.block_until_ready((state, metrics))
        timings.append(time.perf_counter() - start)
    return state, metrics, init_seconds, statistics.median(timings)


def compile_and_run(function, *args):
    """``(result, compile seconds, run seconds)`` of one call of ``jit(function)``."""
    start = time.perf_counter()
    compiled = jax.jit(function).lower(*args).compile()
    compile_seconds = time.perf_counter() - start
    start = time.perf_counter()
    result = jax.block_until_ready(compiled(*args))
    return result, compile_seconds, time.perf_counter() - start


def peak_memory_bytes(compiled) -> int | None:
    """XLA's estimate of a compiled program's device buffers: args + outputs + temps - aliases."""
    memory = compiled.memory_analysis()
    if memory is None:
        return None
    return int(
        memory.argument_size_in_bytes
        + memory.output_size_in_bytes
        + memory.temp_size_in_bytes
        - memory.alias_size_in_bytes
    )


def mebibytes(num_bytes: int | None) -> str:
    return "-" if num_bytes is None else f"{num_bytes / 2**20:.1f}"


def scan_length(env_name: str, width: int, quick: bool) -> int:
    """Steps per timed call: long enough to dwarf dispatch, short enough for a slow CPU."""
    if env_name == "Pendulum-v1":
        return 2000
    steps = 100 if width <= 64 else 40
    return steps // 2 if quick else steps


def env_ceiling(env, width: int, num_steps: int, key: jax.Array) -> dict:
    """The environment-only ceiling: compiles and times ``num_steps`` vmapped steps of
    ``width`` parallel copies of ``env`` under uniform random actions."""
    reset_key, action_key = jax.random.split(key)
    states = jax.jit(jax.vmap(env.reset))(jax.random.split(reset_key, width))
    actions = jax.random.uniform(
        action_key,
        (num_steps, width, env.action_size),
        minval=env.action_low,
        maxval=env.action_high,
    )
    step = jax.vmap(env.step)

    def rollout(states, actions):
        def body(states, action):
            states = step(states, action)
            return states, ~jnp.isfinite(states.reward)

        states, non_finite = jax.lax.scan(body, states, actions)
        return states, non_finite.any(axis=0)

    start = time.perf_counter()
    compiled = jax.jit(rollout).lower(states, actions).compile()
    compile_seconds = time.perf_counter() - start
    timings = []
    diverged = np.zeros(width, bool)
    for _ in range(NUM_REPEATS):
        start = time.perf_counter()
        states, non_finite = compiled(states, actions)
        jax.block_until_ready(non_finite)
        timings.append(time.perf_counter() - start)
        diverged |= np.asarray(non_finite)
    # A slot whose physics diverged (NaN) keeps stepping at the same cost, so the timing
    # stands; the fraction is reported because it is part of a solver setting's cost.
    return {
        "steps_per_second": width * num_steps / statistics.median(timings),
        "compile_seconds": compile_seconds,
        "peak_memory_bytes": peak_memory_bytes(compiled),
        "diverged_fraction": float(diverged.mean()),
    }


def markdown_table(header: Sequence[str], rows: Sequence[Sequence], align: str) -> str:
    """A Markdown table: ``align`` has one letter per column, ``l`` (text) or ``r`` (numbers);
    the cells are already formatted."""
    if len(align) != len(header) or any(len(row) != len(header) for row in rows):
        raise ValueError("markdown_table: every row needs one cell per column")
    rule = "|" + "|".join("---" if a == "l" else "---:" for a in align) + "|"
    lines = ["| " + " | ".join(header) + " |", rule]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines)


def write_rows(path: Path | str | None, rows: list[dict]) -> None:
    """Writes ``rows`` as a JSON list to ``path`` (its folder made), saying so; None: nothing."""
    if path is None:
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(rows, indent=2))
    print(f"wrote {path}", file=sys.stderr)
