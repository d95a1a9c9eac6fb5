"""Cold start: where a sweep's time goes from process start to its first timed chunk.

Each case is a ``python -m experiments.sweep`` command line. For each, this script starts a
fresh Python (so imports count) on the CPUs ``--cpus`` (default one: ``taskset -c 0``; XLA
sizes its thread pools by the process's affinity), which runs the sweep job's own steps one
at a time (``pngail_jax.programs.sweep`` parses the flags and turns on the compilation cache;
``pngail_jax.jobs.build`` makes the cells, environment, demonstrations and the compiled
``Grid``; ``pngail_jax.jobs.chunks.start`` runs the grid's init; then one chunk) and stamps the
wall clock between them:

- ``imports``: from the parent's launch (interpreter start included) to the program's modules
  and JAX imported, the flags parsed and the cache on;
- ``demonstrations``: the cells, the environment and the demonstrations read (and checked);
- ``build``: the trainer and the grid's two compiles, ``init`` and ``chunk``, each split by
  JAX's own compile events (``jax.monitoring``: tracing, lowering to StableHLO, XLA's
  compile or the persistent cache's retrieval, and the cache's hits); the grid compiles the
  two side by side (``grid.compile_side_by_side``), so their seconds may overlap;
- ``init``: the grid's init program run (the split, the confidence classifier, the method's
  set-up phases);
- ``first_chunk``: the first chunk of ``chunk_iterations`` iterations (ending in an
  evaluation), as the program runs it.

It does not write the run's outputs (config.json, checkpoints): the program does between the
stages above, in well under a second. Each case runs ``--repeats`` times, each time ``cold``
(an empty compilation cache in a fresh temporary folder) and then ``warm`` (the same cache,
a new process). After the timed stages the child measures each program's size (not timed):
the StableHLO it lowers to (characters, lines), XLA's optimised HLO (instructions, while loops,
fusions) and the instructions' sources (file and function of the library code that traced
them), the largest first.

    python benchmarks/cold_start.py --json cold_start.json             # both cases, twice
    python benchmarks/cold_start.py --cases pendulum --repeats 1
    python benchmarks/cold_start.py --trees before=/tmp/old,after=.    # two checkouts

``--trees`` measures each case with each checkout's ``pngail_jax`` (the child's
``PYTHONPATH``; e.g. ``git archive COMMIT pngail_jax | tar -x -C /tmp/old``), the trees one
after the other within each repeat, so a before and after share the machine's minute.

Row schema: ``{name, case, tree, repeat, cache, cpus, total_seconds, stages: {...}, programs:
{init|chunk: {compile_seconds, cache_hits, trace_seconds, lower_seconds, backend_seconds,
cache_seconds, stablehlo_chars, stablehlo_lines, hlo_instructions, while_loops, fusions,
flops, sources}}, command, device, jax_version}``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RELEASED = Path("data/released")
GAIL_ALL = "gail,2iwil,icgail,wgail,pngail,pngail-no-bsc,pngail-no-pn"
CASES = {
    # The issue's command: the authors' Pendulum file, GAIL, one seed, 100 iterations.
    "pendulum": (
        f"--demos {RELEASED}/Pendulum-v1_mixture.npy --methods gail --seeds 1 --iterations 100"
    ),
    # The paper's seven methods on Hopper-v4 on MuJoCo's C engine, one seed each; ten
    # iterations with an evaluation at their end (compiles do not depend on the count).
    "hopper": (
        f"--demos {RELEASED}/Hopper-v2_mixture.npy --methods {GAIL_ALL} --seeds 1 "
        "--iterations 10 --eval-every 10 --chunk-iterations 10 --physics c"
    ),
}
STAGES = ("imports", "demonstrations", "build", "init", "first_chunk")


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default="pendulum,hopper", help=f"of {', '.join(CASES)}")
    parser.add_argument("--repeats", type=int, default=2, help="cold + warm pairs per case")
    parser.add_argument("--cpus", default="0", help="CPU ids to pin to ('': no pinning)")
    parser.add_argument(
        "--extra", default="", help="flags added to every case's sweep command (a smaller run)"
    )
    parser.add_argument(
        "--trees",
        default="",
        help="LABEL=PATH,...: measure each case with each checkout's pngail_jax (the child's "
        "PYTHONPATH), one after the other per repeat ('': this checkout's)",
    )
    parser.add_argument("--json", help="write the rows here")
    parser.add_argument("--dump", help="write each case's programs' HLO texts under this folder")
    parser.add_argument(
        "--parts", action="store_true", help="the first cold run also compiles parts alone"
    )
    parser.add_argument("--child", help=argparse.SUPPRESS)  # JSON: the child's instructions
    return parser.parse_args(argv)


# -- the child: one sweep's stages in this process ----------------------------------------------


class CompileEvents:
    """JAX's compile-duration events (``jax.monitoring``), each with its wall-clock end and
    the grid program it belongs to: ``init`` or ``chunk`` by the traced function's name
    (``trainer.init``, ``trainer.run_blocks``), the cache's reads (which carry no name) by
    the thread (``grid.compile_side_by_side`` compiles init in its own), else ``other``."""

    NAMES = {
        "cache_hits": "cache_hits",
        "/jax/core/compile/jaxpr_trace_duration": "trace_seconds",
        "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower_seconds",
        "/jax/core/compile/backend_compile_duration": "backend_seconds",
        "/jax/compilation_cache/cache_retrieval_time_sec": "cache_seconds",
    }

    def __init__(self):
        import jax

        self.events: list[tuple[float, str, float, str]] = []
        jax.monitoring.register_event_duration_secs_listener(self._record)
        jax.monitoring.register_event_listener(self._count)

    def _count(self, event: str, **_) -> None:
        """A read of the persistent cache that found the program (a count, no duration)."""
        if event == "/jax/compilation_cache/cache_hits":
            self._record("cache_hits", 1.0)

    def _record(self, event: str, duration: float, fun_name: str | None = None, **_) -> None:
        import threading

        from pngail_jax import grid

        if event not in self.NAMES:
            return
        if fun_name is None:  # a tree before the side-by-side compiles has no such thread
            thread = getattr(grid, "COMPILE_THREAD", None)
            own = thread is not None and threading.current_thread().name.startswith(thread)
            program = "init" if own else "chunk"
        else:
            name = fun_name.removeprefix("jit(").removesuffix(")")
            program = {"init": "init", "run_blocks": "chunk"}.get(name, "other")
        self.events.append((time.time(), self.NAMES[event], duration, program))

    def between(self, start: float, end: float, program: str | None = None) -> dict[str, float]:
        """Seconds per kind of the events of ``program`` (None: every one) that ended in
        ``[start, end)``."""
        totals = dict.fromkeys(self.NAMES.values(), 0.0)
        for stamp, kind, duration, of in self.events:
            if start <= stamp < end and program in (None, of):
                totals[kind] += duration
        return totals


def run_stages(argv: list[str], out: Path) -> tuple[dict, dict, object]:
    """The sweep of ``argv``, a stage at a time: ``(wall-clock stamps, compile events per
    program, the built run)``."""
    stamps = {}
    import jax

    from pngail_jax.jobs import build, chunks
    from pngail_jax.jobs.demonstrations import prepare
    from pngail_jax.programs import sweep as sweep_program

    events = CompileEvents()
    invocation = sweep_program.parse_args([*argv, "--out", str(out)])
    config, _ = sweep_program.start(invocation)
    stamps["imports"] = time.time()
    cells = build.run_cells(config)
    env = build.make_run_env(config, cells)
    demonstrations = prepare(config, env, None)
    stamps["demonstrations"] = time.time()
    built = build.build(config, env, cells, demonstrations)
    stamps["build"] = time.time()
    state, _ = chunks.start(built.grid, None)
    jax.block_until_ready(state)
    stamps["init"] = time.time()
    state, metrics = built.grid.run_chunk(state)
    jax.block_until_ready((state, metrics))
    stamps["first_chunk"] = time.time()
    build_window = stamps["demonstrations"], stamps["build"]
    programs = {
        "init": {
            "compile_seconds": built.grid.init_compile_seconds,
            **events.between(*build_window, "init"),
        },
        "chunk": {
            "compile_seconds": built.grid.chunk_compile_seconds,
            **events.between(*build_window, "chunk"),
        },
    }
    programs["other"] = events.between(stamps["build"], stamps["first_chunk"])
    return stamps, programs, built


def program_sizes(built, dump: str | None = None) -> dict[str, dict]:
    """Each compiled program's size: its StableHLO (lowered again here), XLA's optimised
    HLO and where its instructions come from (``dump``: a folder to write both texts to)."""
    import functools

    import jax

    grid, trainer = built.grid, built.trainer
    inputs = (*grid.cell_inputs, grid.keys)
    init = jax.jit(jax.vmap(trainer.init))
    state_shape, _ = jax.eval_shape(init, *inputs)
    chunk = jax.jit(
        jax.vmap(functools.partial(trainer.run_blocks, num_blocks=grid.blocks_per_chunk))
    )
    lowered = {
        "init": init.lower(*inputs),
        "chunk": chunk.lower(*grid.cell_inputs, state_shape),
    }
    compiled = {"init": grid.init_program, "chunk": grid.chunk_program}
    sizes = {}
    for name, program in compiled.items():
        text, optimised = lowered[name].as_text(), program.as_text()
        if dump:
            Path(dump).mkdir(parents=True, exist_ok=True)
            (Path(dump) / f"{name}.stablehlo.mlir").write_text(text)
            (Path(dump) / f"{name}.hlo.txt").write_text(optimised)
        sizes[name] = {
            "stablehlo_chars": len(text),
            "stablehlo_lines": text.count("\n"),
            **hlo_counts(optimised),
            "flops": _flops(program),
        }
    return sizes


def _flops(program) -> float | None:
    analysis = program.cost_analysis()
    if isinstance(analysis, list):
        analysis = analysis[0] if analysis else None
    return None if not analysis else float(analysis.get("flops", 0.0))


def hlo_counts(text: str) -> dict:
    """Instructions, while loops and fusions of an optimised HLO module's text, and the
    instructions per source: the innermost frame of the library's code (``file:function``)
    in the stack the instruction was traced from (its metadata's ``stack_frame_id``)."""
    import re

    instruction = re.compile(r"^\s+(ROOT )?%\S+ = ")
    frame_id = re.compile(r"stack_frame_id=(\d+)")
    source_of = _frame_sources(text)
    counts = {"hlo_instructions": 0, "while_loops": 0, "fusions": 0}
    by_source: dict[str, int] = {}
    for line in text.splitlines():
        if not instruction.match(line):
            continue
        counts["hlo_instructions"] += 1
        counts["while_loops"] += " while(" in line
        counts["fusions"] += " fusion(" in line
        found = frame_id.search(line)
        key = source_of.get(int(found.group(1)), "(none)") if found else "(none)"
        by_source[key] = by_source.get(key, 0) + 1
    top = sorted(by_source.items(), key=lambda item: -item[1])[:25]
    return {**counts, "sources": dict(top)}


def _frame_sources(text: str) -> dict[int, str]:
    """``{stack frame id: "file:function"}`` from an HLO module's frame tables: the innermost
    frame in ``pngail_jax/`` (else the innermost frame), its path from ``pngail_jax/``."""
    import re

    tables: dict[str, dict[int, str]] = {}
    section = None
    for line in text.splitlines():
        if line in ("FileNames", "FunctionNames", "FileLocations", "StackFrames"):
            section = line
            tables[section] = {}
        elif section and re.match(r"^\d+ ", line):
            number, rest = line.split(" ", 1)
            tables[section][int(number)] = rest.strip().strip('"')
        elif line.startswith(("%", "ENTRY", "HloModule")):
            section = None

    def field(entry: str, name: str) -> int:
        return int(re.search(rf"\b{name}=(\d+)", entry).group(1))

    def frame(number: int) -> tuple[str, str, int]:
        location = tables["FileLocations"][field(tables["StackFrames"][number], "file_location_id")]
        return (
            tables["FileNames"][field(location, "file_name_id")],
            tables["FunctionNames"][field(location, "function_name_id")],
            # The printed parent is one above the parent frame's id (1: no parent).
            field(tables["StackFrames"][number], "parent_frame_id") - 1,
        )

    sources = {}
    for number in tables.get("StackFrames", {}):
        chain, current, seen = [], number, set()
        while current and current not in seen and current in tables["StackFrames"]:
            seen.add(current)
            path, function, parent = frame(current)
            chain.append((path, function))
            current = parent
        ours = [(p, f) for p, f in chain if "pngail_jax/" in p]
        path, function = (ours or chain or [("?", "?")])[0]
        sources[number] = (
            f"{path[path.find('pngail_jax/') :] if 'pngail_jax/' in path else path}:{function}"
        )
    return sources


def part_compiles(built) -> dict[str, float]:
    """Compile seconds of the two programs again and of their parts, each alone, with the
    persistent cache off (shares of a program's compile, measured side by side): ``init``
    with its classifier branch left out (the trainer module's ``split_confidences`` replaced
    by the branch a method without a classifier takes), ``chunk`` with its evaluations left
    out (the learner's ``evaluate`` replaced by a constant), one training iteration, and one
    evaluation."""
    import functools

    import jax
    import jax.numpy as jnp

    from pngail_jax.adversarial import trainer as trainer_module

    jax.config.update("jax_enable_compilation_cache", False)
    grid, trainer = built.grid, built.trainer
    inputs = (*grid.cell_inputs, grid.keys)
    state_shape, _ = jax.eval_shape(jax.vmap(trainer.init), *inputs)

    def seconds(function, *args) -> float:
        start = time.perf_counter()
        jax.jit(function).lower(*args).compile()
        return time.perf_counter() - start

    def chunk(*args):
        run = functools.partial(trainer.run_blocks, num_blocks=grid.blocks_per_chunk)
        return jax.vmap(run)(*args)

    def without_classifier(config, spec, coef, inputs, split, key, compiled=True):
        mean = jnp.where(split.labelled, split.confidence, 0.0).sum()
        mean = mean / jnp.maximum(split.labelled.sum(), 1)
        return jnp.where(split.labelled, split.confidence, mean), mean

    times = {
        "init": seconds(jax.vmap(trainer.init), *inputs),
        "chunk": seconds(chunk, *grid.cell_inputs, state_shape),
        "iteration": seconds(jax.vmap(trainer.iteration), *grid.cell_inputs, state_shape),
        "evaluation": seconds(
            jax.vmap(trainer.learner.evaluate), state_shape.learner, state_shape.eval_keys
        ),
    }
    original = trainer_module.split_confidences
    trainer_module.split_confidences = without_classifier
    try:
        times["init_without_classifier"] = seconds(jax.vmap(trainer.init), *inputs)
    finally:
        trainer_module.split_confidences = original
    trainer.learner.evaluate = lambda state, keys: jnp.zeros((), jnp.float32)
    try:
        chunk_again = functools.partial(chunk)  # another function: traced afresh
        times["chunk_without_evaluation"] = seconds(chunk_again, *grid.cell_inputs, state_shape)
    finally:
        del trainer.learner.evaluate
    return times


def child(instructions: dict) -> dict:
    """The child's measurement of one case (``instructions``: argv, launch stamp, cache)."""
    os.environ["PNGAIL_JAX_COMPILATION_CACHE"] = instructions["cache"]
    launched = instructions["launched"]
    with tempfile.TemporaryDirectory() as scratch:
        stamps, programs, built = run_stages(instructions["argv"], Path(scratch) / "run")
    stages, previous = {}, launched
    for stage in STAGES:
        stages[stage] = stamps[stage] - previous
        previous = stamps[stage]
    for name, size in program_sizes(built, instructions.get("dump")).items():
        programs[name].update(size)
    parts = part_compiles(built) if instructions.get("parts") else None
    return {"total_seconds": stamps["first_chunk"] - launched, "stages": stages,
            "programs": programs, "part_compiles": parts}  # fmt: skip


# -- the parent: a fresh process per measurement ------------------------------------------------


def measure(argv: list[str], cache: Path, cpus: set[int] | None, dump: str | None,
            parts: bool = False, tree: str | None = None) -> dict:  # fmt: skip
    """One child process measuring the sweep of ``argv`` with the compilation cache ``cache``
    (its row, or an ``error`` with the child's last output; ``dump``: see ``--dump``;
    ``parts``: compile the programs' parts alone too, ``part_compiles``; ``tree``: a
    checkout whose ``pngail_jax`` the child imports, None: this one's)."""
    instructions = {"argv": argv, "cache": str(cache), "launched": time.time(), "dump": dump,
                    "parts": parts}  # fmt: skip
    pin = ["taskset", "-c", ",".join(map(str, sorted(cpus)))] if cpus else []
    done = subprocess.run(
        [*pin, sys.executable, __file__, "--child", json.dumps(instructions)],
        capture_output=True,
        text=True,
        check=False,
        env={
            **os.environ,
            "PNGAIL_JAX_COMPILATION_CACHE": str(cache),
            **({"PYTHONPATH": str(Path(tree).resolve())} if tree else {}),
        },
    )
    results = [line for line in done.stdout.splitlines() if line.startswith("RESULT ")]
    if done.returncode != 0 or not results:
        return {"error": (done.stdout + done.stderr)[-3000:]}
    return json.loads(results[-1].removeprefix("RESULT "))


def case_rows(name: str, args, cpus: set[int] | None) -> list[dict]:
    """``args.repeats`` cold-then-warm pairs of case ``name`` for each tree of ``--trees``
    (the trees one after the other within a repeat), each cold one on an empty cache."""
    from common import context

    argv = [*CASES[name].split(), *args.extra.split()]
    trees = [tuple(pair.split("=", 1)) for pair in args.trees.split(",") if pair] or [("", None)]
    rows = []
    for repeat in range(args.repeats):
        for label, tree in trees:
            with tempfile.TemporaryDirectory(prefix="cold-start-cache-") as cache:
                for kind in ("cold", "warm"):
                    dump = args.dump and f"{args.dump}/{name}{label}" if kind == "cold" else None
                    parts = args.parts and kind == "cold" and repeat == 0
                    row = measure(argv, Path(cache), cpus, dump, parts, tree)
                    if "error" in row:
                        raise SystemExit(f"{name} {label} ({kind}) failed:\n{row['error']}")
                    rows.append({
                        "name": f"{name}/{kind}", "case": name, "tree": label, "repeat": repeat,
                        "cache": kind, "cpus": sorted(cpus) if cpus else None, **row,
                        "command": "python -m experiments.sweep " + " ".join(argv), **context(),
                    })  # fmt: skip
                    total = row["total_seconds"]
                    print(f"{name} {label} {kind} #{repeat + 1}: {total:.1f} s", flush=True)
    return rows


def program_seconds(program: dict) -> float:
    """A program's compile seconds by JAX's events (tracing, lowering, XLA, cache reads),
    which mean the same in every tree; with the compiles side by side, the two programs'
    seconds overlap in time."""
    kinds = ("trace_seconds", "lower_seconds", "backend_seconds", "cache_seconds")
    return sum(program[kind] for kind in kinds)


def stage_table(rows: list[dict]) -> str:
    """One line per measurement: each stage's seconds and each program's compile."""
    from common import markdown_table

    header = ["case", "tree", "cache", "#", *STAGES, "init compile", "chunk compile", "total"]
    lines = []
    for row in rows:
        stages, programs = row["stages"], row["programs"]
        lines.append([
            row["case"], row.get("tree", ""), row["cache"], row["repeat"] + 1,
            *(f"{stages[stage]:.1f}" for stage in STAGES),
            *(f"{program_seconds(programs[name]):.1f}" for name in ("init", "chunk")),
            f"{row['total_seconds']:.1f}",
        ])  # fmt: skip
    return markdown_table(header, lines, "lllr" + "r" * (len(header) - 4))


def program_table(rows: list[dict]) -> str:
    """Each case's programs (its first cold measurement): compile split and size."""
    from common import markdown_table

    header = ["case", "tree", "program", "trace s", "lower s", "XLA s", "StableHLO lines",
              "HLO instructions", "while loops", "fusions", "GFLOP"]  # fmt: skip
    lines = []
    for row in rows:
        if row["cache"] != "cold" or row["repeat"] != 0:
            continue
        for name in ("init", "chunk"):
            p = row["programs"][name]
            lines.append([
                row["case"], row.get("tree", ""), name, f"{p['trace_seconds']:.1f}",
                f"{p['lower_seconds']:.1f}", f"{p['backend_seconds']:.1f}",
                f"{p['stablehlo_lines']:,}",
                f"{p['hlo_instructions']:,}", p["while_loops"], p["fusions"],
                "-" if p["flops"] is None else f"{p['flops'] / 1e9:.2f}",
            ])  # fmt: skip
    return markdown_table(header, lines, "lll" + "r" * 8)


def main(argv=None) -> list[dict]:
    args = parse_args(argv)
    if args.child is not None:
        print("RESULT " + json.dumps(child(json.loads(args.child))), flush=True)
        return []
    from common import write_rows

    unknown = [name for name in args.cases.split(",") if name not in CASES]
    if unknown:
        raise SystemExit(f"--cases: unknown {unknown}; known: {', '.join(CASES)}")
    cpus = {int(cpu) for cpu in args.cpus.split(",")} if args.cpus else None
    rows = [row for name in args.cases.split(",") for row in case_rows(name, args, cpus)]
    print(stage_table(rows))
    print()
    print(program_table(rows))
    for row in rows:
        case = f"{row['case']} {row.get('tree', '')}".strip()
        if row.get("part_compiles"):
            parts = ", ".join(f"{k} {v:.1f} s" for k, v in row["part_compiles"].items())
            print(f"\n{case}: compiles alone, no cache: {parts}")
        if row["cache"] == "cold" and row["repeat"] == 0:
            print(f"\n{case}: the chunk program's instructions by source")
            for source, count in list(row["programs"]["chunk"]["sources"].items())[:12]:
                print(f"  {count:6,}  {source}")
    write_rows(args.json, rows)
    return rows


if __name__ == "__main__":
    main()
