"""``run_paper(options, out)``: the paper's plan as one job: its options (``paper.json``,
sealed), the demonstrations of every grid, the grids (each a sweep, resumed or kept) and the
results page. ``python -m experiments.paper`` is its flags and one call of it.

    from pngail_jax.paper.run import paper_options, run_paper

    run_paper(paper_options(budget="check", only=["fig2"], envs=["Pendulum-v1"]), "results/p")
"""

from __future__ import annotations

import shlex
from pathlib import Path

from pngail_jax.analysis.runs import UntrustedRun, changed_inputs_refusal, sealed_document
from pngail_jax.demos import released_confidence_path
from pngail_jax.jobs.errors import RunError, refusals
from pngail_jax.paper.adopt import adopt_grids, finished_sweep
from pngail_jax.paper.estimate import estimate_table, read_throughput
from pngail_jax.paper.grids import (
    demo_paths,
    grid_complete,
    made_demos_path,
    planned_configs,
    released_files,
    run_grids,
)
from pngail_jax.paper.page import write_page
from pngail_jax.paper.plan import BUDGETS, FIGURES, PAPER_TASKS, RENAMED_BUDGETS, plan
from pngail_jax.storage.integrity import (
    IntegrityError,
    changed_inputs,
    file_record,
    read_json,
    write_sealed,
)
from pngail_jax.storage.outputs import claimed

PROGRAM = "paper"


def paper_options(
    budget: str = "check",
    only=None,
    envs=None,
    released_demos=None,
    physics: str | None = None,
    command: str = "python -m experiments.paper",
    learner: str = "trpo",
    demo_learner: str | None = None,
) -> dict:
    """A new plan's options (paper.json): the preset, the figures (None: all), the tasks
    (None: the paper's six), a folder of the authors' files, the physics engine, the command
    line the page says it was made with, the policy learner (TRPO, the paper's, or PPO) and
    that of the made demonstrations' experts (None: the same)."""
    if budget not in BUDGETS:
        raise RunError(f"unknown preset {budget!r} (known: {', '.join(BUDGETS)})")
    return {
        "budget": budget,
        "only": list(FIGURES) if only is None else list(only),
        "envs": list(PAPER_TASKS) if envs is None else list(envs),
        "released_demos": None if released_demos is None else str(released_demos),
        "physics": physics,
        "command": command,
        "learner": learner,
        "demo_learner": demo_learner or learner,
    }


def _plan_or_refuse(options: dict, released) -> tuple:
    """``plan``'s figures and grids for the options, or RunError when no figure asked for has
    a panel on the tasks asked for."""
    figures, grids = plan(options["only"], options["envs"], set(released))
    if not figures:
        raise RunError(
            f"none of {', '.join(options['only'])} has a panel on "
            f"{', '.join(options['envs'])} (Fig. 4: Ant, Hopper, Pendulum-v1; Fig. 5 / "
            "Table 4: Pendulum-v1, Ant; Fig. 6 and 7: Pendulum-v1; Fig. 8 and 10: Ant; "
            "Fig. 9: Ant, Pendulum-v1)"
        )
    return figures, grids


def run_paper(
    options: dict | None,
    out,
    *,
    resume: bool = False,
    overwrite: bool = False,
    adopt=(),
    allow_unsealed: bool = False,
    throughput=None,
):
    """Runs the plan of ``options`` (``paper_options``) into ``out`` (new, empty, or with
    ``overwrite`` a paper run), or with ``resume`` continues the plan in ``out`` (``options``
    None: its paper.json's); ``adopt``: finished sweep folders to keep as the plan's grids
    they match (``paper.adopt``); ``allow_unsealed``: adopt sweeps, and resume grids, whose
    config seal is missing; ``throughput``: a benchmark's rows, from which the wall time of
    what is left is estimated before anything runs (``paper.estimate``). Returns the page's
    path. Raises ``RunError`` with one line."""
    out = Path(out)
    if overwrite and not resume:
        _refuse_adopting_from_inside(out, adopt)
    rates = None if throughput is None else (throughput, read_throughput(throughput))
    with refusals(), claimed(out, PROGRAM, overwrite=overwrite, resume=resume) as claim:
        if resume:
            options = saved_options(out)
        budget = BUDGETS[options["budget"]]
        released_dir = Path(options["released_demos"]) if options["released_demos"] else None
        released = released_files(released_dir, options["envs"])
        if not resume:
            options["inputs"] = released_inputs(released)
        else:
            check_paper_inputs(out, options, released)
        for directory in adopt:  # before any demonstrations are made: a typo fails at once
            finished_sweep(Path(directory), allow_unsealed)
        figures, grids = _plan_or_refuse(options, released)
        if not resume:
            claim.prepare()
            write_sealed(out / "paper.json", options, out / PAPER_SEAL)
        print(
            f"{len(figures)} figure(s) from {len(grids)} grid(s) on "
            f"{', '.join(options['envs'])} at the {options['budget']} preset; the authors' "
            f"files for: {', '.join(released) or 'none'} -> {out}",
            flush=True,
        )
        physics = options.get("physics")  # absent from runs begun before the flag existed
        learner = options.get("learner", "trpo")  # absent from runs begun before the flag
        demo_learner = options.get("demo_learner", learner)  # likewise
        _print_estimate(out, options["budget"], grids, physics, rates)
        demos = demo_paths(grids, out, budget, released, physics, demo_learner)
        command = shlex.split(options["command"])
        configs = planned_configs(grids, demos, budget, physics, learner)
        try:
            adopted = adopt_grids(adopt, configs, out, allow_unsealed)
        except RunError as error:
            kept = f"(the plan so far is kept: --resume {out} continues it)"
            raise RunError(f"{error} {kept}") from None
        timings = run_grids(grids, configs, out, command, allow_unsealed)
        page = write_page(out, options, figures, grids, timings, adopted)
    print(f"\nwrote {page}")
    return page


def _print_estimate(out: Path, budget_name: str, grids: dict, physics, rates) -> None:
    """The estimated wall time of the grids (and made demonstrations) not yet finished in
    ``out``, from ``rates`` (the throughput file and its rows); without them, on the gpu
    preset, how to get them."""
    if rates is None:
        if budget_name == "gpu":
            print(
                "no --throughput: for an estimate of the plan's wall time first run "
                "python benchmarks/gpu_check.py --json FILE on this machine",
                flush=True,
            )
        return
    path, rows = rates
    left = {name: grid for name, grid in grids.items()
            if not grid_complete(out / "grids" / name)}  # fmt: skip
    made = [task for task in dict.fromkeys(g.task for g in left.values()
                                           if g.demos.ratio is not None)
            if not made_demos_path(out, task).exists()]  # fmt: skip
    table = estimate_table(left, BUDGETS[budget_name], physics, rows, made)
    print(f"\nEstimated wall time of what is left, at the rates in {path}:\n{table}\n",
          flush=True)  # fmt: skip


def page_so_far(plan_dir, out, *, overwrite: bool = False) -> Path:
    """Writes a results page of the plan in ``plan_dir`` into ``out`` (new, or with
    ``overwrite`` a page of this kind) from what its grids have run so far, running nothing and
    writing nothing in ``plan_dir`` (whose run may go on meanwhile): finished grids as the
    plan's own page shows them, one in progress at the iteration it reached, one not started
    left out, each said. Returns the page's path. Raises ``RunError`` with one line."""
    plan_dir, out = Path(plan_dir), Path(out)
    if not (plan_dir / "paper.json").exists():
        raise RunError(f"--page {plan_dir}: no paper.json there (not a run of experiments.paper)")
    options = saved_options(plan_dir, "--page")
    if "inputs" in options:  # the tasks the plan runs on the authors' files, as recorded
        released = {
            role.rsplit(" ", 1)[0] for role in options["inputs"] if role.endswith(" demonstrations")
        }
    else:  # a plan from before the records: its folder of the authors' files, as --resume
        folder = options.get("released_demos")
        released = set(released_files(Path(folder) if folder else None, options["envs"]))
    figures, grids = plan(options["only"], options["envs"], released)
    progress = {name: grid_progress(plan_dir / "grids" / name) for name in grids}
    progress = {name: state for name, state in progress.items() if state != "complete"}
    if len(progress) == len(grids) and all(state is None for state in progress.values()):
        raise RunError(f"--page {plan_dir}: no grid of the plan has outputs yet")
    from pngail_jax.analysis.runs import UntrustedRun, verify_run

    for name in grids:  # the page shows only numbers the plan's runs wrote
        if progress.get(name, "complete") is not None:
            try:
                verify_run(plan_dir / "grids" / name, f"--page {plan_dir}: its grid {name}",
                           check_inputs=False)  # fmt: skip
            except UntrustedRun as error:
                raise RunError(str(error)) from None
    try:
        timings, adopted = (
            read_json(plan_dir / name, name) if (plan_dir / name).exists() else {}
            for name in ("timings.json", "adopted.json")
        )
    except IntegrityError as error:
        raise RunError(f"--page {plan_dir}: {error}") from None
    if out.resolve().is_relative_to(plan_dir.resolve()):
        raise RunError(f"--out {out} is inside the plan's folder {plan_dir}: give one outside it")
    with refusals(), claimed(out, PAGE_PROGRAM, overwrite=overwrite) as claim:
        claim.prepare()
        try:
            page = write_page(
                out, options, figures, grids, timings, adopted, source=plan_dir, progress=progress
            )
        except (OSError, ValueError, IntegrityError) as error:  # the plan wrote meanwhile
            raise RunError(
                f"--page {plan_dir}: its outputs changed while they were read ({error}); "
                "run --page again"
            ) from None
    print(f"wrote {page} ({len(grids) - len(progress)} of {len(grids)} grids finished)")
    return page


PAGE_PROGRAM = "paper-page"


def _refuse_adopting_from_inside(out: Path, adopt) -> None:
    """RunError for an ``--adopt`` folder inside ``out``, which ``--overwrite`` would empty
    before adopting it."""
    inside = [d for d in map(Path, adopt) if d.resolve().is_relative_to(out.resolve())]
    if inside:
        raise RunError(
            f"--adopt {inside[0]} lies inside --out {out}, which --overwrite empties first: "
            "copy or move it out of there, or give another --out"
        )


def grid_progress(directory: Path):
    """``"complete"``, ``(iterations done, planned)`` or None (no outputs yet) from a grid's
    summary.json (written after each chunk)."""
    path = directory / "summary.json"
    try:
        summary = read_json(path, "grid summary")
    except FileNotFoundError:
        return None
    except (OSError, IntegrityError) as error:
        raise RunError(f"--page: {error}") from None
    if not isinstance(summary, dict):
        raise RunError(f"--page: {path} is not a grid summary")
    if summary.get("complete"):
        return "complete"
    done, planned = summary.get("iterations_done"), summary.get("iterations")
    if not (isinstance(done, int) and isinstance(planned, int)):
        raise RunError(f"--page: {path} does not say how many iterations are done")
    return done, planned


def saved_options(out: Path, flag: str = "--resume") -> dict:
    """A resumed (or with ``flag`` another flag's) plan's options: its paper.json, checked
    against its seal and the presets."""
    path = out / "paper.json"
    try:  # a plan from before paper.json was sealed has no seal: it goes on
        options, _ = sealed_document(
            out, f"{flag} {out}", name="paper.json", what="paper run options", seal_name=PAPER_SEAL,
            part=lambda document: document, allow_unsealed=True,
        )  # fmt: skip
    except UntrustedRun as error:
        raise RunError(str(error)) from None
    if "budget" not in options:
        raise RunError(f"{flag} {out}: {path} is not a paper run's options")
    budget = RENAMED_BUDGETS.get(options["budget"], options["budget"])
    if budget not in BUDGETS:
        raise RunError(
            f"{flag} {out}: {path} names an unknown preset {options['budget']!r} "
            f"(known: {', '.join(BUDGETS)})"
        )
    options["budget"] = budget
    return options


PAPER_SEAL = ".paper.sealed.json"


def released_inputs(released: dict[str, Path]) -> dict[str, dict]:
    """``{role: integrity.file_record}`` of the authors' files (and their confidence files)
    a plan reads, which ``--resume`` checks."""
    records = {}
    for task, path in released.items():
        records[f"{task} demonstrations"] = file_record(path)
        records[f"{task} confidences"] = file_record(released_confidence_path(path))
    return records


def check_paper_inputs(out: Path, options: dict, released: dict[str, Path]) -> None:
    """Refuses a resume whose authors' files are gone, changed or no longer found (a moved
    folder would otherwise make demonstrations and label the page as before)."""
    recorded = options.get("inputs")
    if recorded is None:  # a run from before inputs were recorded
        return
    changes = changed_inputs(recorded)
    missing = sorted(
        role.removesuffix(" demonstrations")
        for role in recorded
        if role.endswith(" demonstrations") and role.removesuffix(" demonstrations") not in released
    )
    if missing and not changes:
        changes = [f"the authors' files for {', '.join(missing)} are no longer found"]
    if changes:
        remedy = "restore the files (the folder in paper.json's released_demos), or start a new run"
        raise RunError(changed_inputs_refusal(changes, f"--resume {out}", "plan", remedy))
