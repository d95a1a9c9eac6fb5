"""The house's shape, read from the code's own imports (every import, those inside functions
too): no import circle inside pngail_jax, no module importing a higher layer, the jobs in
their order, demos/ reading and writing data only, analysis/ importing no JAX (in a fresh
interpreter per module), no private name imported across files, no module too long, at most
eight modules at the package's root and at most eleven floors. The layers are drawn in
docs/architecture.md."""

from __future__ import annotations

import ast
from fnmatch import fnmatch
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "pngail_jax"

# Bottom to top: a module may import modules of its own layer or of the layers below. A room
# (a folder) may span layers: config/'s parts are plain data, its run config (the sweep's
# RunConfig, the per-environment settings) reads the environments' names just above them.
LAYERS = [
    (
        "plain data",  # no JAX: field checks, the method and released-file tables, files
        (
            "config", "config.validation", "config.presets", "config.released_files",
            "config.learner", "config.budget", "config.grid_axes", "config.output",
            "config.classifier", "config.methods", "config.demonstrations",
            "storage", "storage.integrity", "storage.outputs", "storage.compilation",
            "analysis.stats",
        ),
    ),
    ("reading", ("analysis", "analysis.*")),  # run folders and records; no JAX
    ("arrays", ("envs", "envs.*", "networks", "fitting", "rl.gae")),
    (
        "run config",
        (
            "config.task", "config.settings", "config.training", "config.run_config",
            "config.run_config_checks", "config.saved",
        ),
    ),
    ("demonstrations", ("demos", "demos.*")),
    (
        "learners",
        (
            "rl", "rl.*", "confidence", "storage.checkpoint",
        ),
    ),
    (
        "method parts",
        (
            "adversarial", "adversarial.methods", "adversarial.losses", "adversarial.phase",
            "adversarial.bc", "adversarial.cail", "adversarial.firl", "adversarial.ranking",
            "adversarial.method_checks", "offline", "offline.losses", "offline.ilid",
        ),
    ),
    (
        "trainers",
        (
            "adversarial.trainer", "offline.trainer", "grid", "train", "adversarial.family",
            "offline.family",
        ),
    ),
    ("jobs", ("jobs", "jobs.*", "runner")),
    ("paper", ("paper", "paper.*")),
    ("programs", ("programs", "programs.*")),
    ("package", ("",)),  # pngail_jax/__init__.py: the user's names, loaded on first use
]  # fmt: skip

# The jobs in their dependency order: each imports only those before it.
JOB_ORDER = [
    "errors", "trainer_configs", "classify", "chunks", "early_rewards", "train_seeds",
    "make_demos_run", "make_demos", "demonstrations", "train_rl", "compare_settings",
    "comparison_record", "build", "record", "results", "sweep", "offline_config", "offline",
]  # fmt: skip
LONGEST_MODULE = 700
LONGEST_JOB = 400


def _modules() -> dict[str, Path]:
    found = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


MODULES = _modules()


def _imports(name: str) -> list[tuple[str, list[str], int]]:
    """(module imported, names taken from it, line) for every pngail_jax import of ``name``
    (a ``from package import submodule`` counts as the submodule)."""
    path = MODULES[name]
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [(alias.name, []) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: from the module's package
                package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
                package = package[: len(package) - node.level + 1]
                base = ".".join(["pngail_jax", *package, *([node.module] if node.module else [])])
            else:
                base = node.module or ""
            targets = []
            for alias in node.names:
                full = f"{base}.{alias.name}".removeprefix("pngail_jax.")
                targets.append((base, []) if full not in MODULES else (f"{base}.{alias.name}", []))
                if full not in MODULES:
                    targets[-1][1].append(alias.name)
        else:
            continue
        for target, names in targets:
            if target == "pngail_jax" or target.startswith("pngail_jax."):
                module = target.removeprefix("pngail_jax").removeprefix(".")
                while module and module not in MODULES:
                    module = module.rpartition(".")[0]
                if module != name:
                    found.append((module, names, node.lineno))
    return found


GRAPH = {name: _imports(name) for name in MODULES}


def _layer(name: str) -> int:
    for index, (_, patterns) in enumerate(LAYERS):
        if any(fnmatch(name, pattern) for pattern in patterns):
            return index
    raise AssertionError(f"pngail_jax.{name} is in no layer: add it to LAYERS (and the docs)")


def test_every_module_has_a_layer():
    for name in MODULES:
        _layer(name)


def _upward(graph) -> list[str]:
    return [
        f"pngail_jax.{name} ({LAYERS[_layer(name)][0]}) imports pngail_jax.{target} "
        f"({LAYERS[_layer(target)][0]}), line {line}"
        for name, imports in graph.items()
        for target, _, line in imports
        if _layer(target) > _layer(name)
    ]


def _circles(graph) -> list[list[str]]:
    """Tarjan's strongly connected components of ``graph`` that hold more than one module."""
    index, low, stack, on_stack, circles = {}, {}, [], set(), []

    def visit(name):
        index[name] = low[name] = len(index)
        stack.append(name)
        on_stack.add(name)
        for target, _, _ in graph[name]:
            if target not in index:
                visit(target)
                low[name] = min(low[name], low[target])
            elif target in on_stack:
                low[name] = min(low[name], index[target])
        if low[name] == index[name]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == name:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for name in graph:
        if name not in index:
            visit(name)
    return circles


def test_no_module_imports_a_higher_layer():
    upward = _upward(GRAPH)
    assert not upward, "\n".join(upward)


def test_no_import_circle():
    assert not _circles(GRAPH), f"import circles: {_circles(GRAPH)}"


def test_the_checks_find_a_circle_and_an_upward_import():
    """On a made-up graph: demos.make -> jobs.sweep -> demos.make is both."""
    graph = {"demos.make": [("jobs.sweep", [], 1)], "jobs.sweep": [("demos.make", [], 2)]}
    assert _circles(graph) == [["demos.make", "jobs.sweep"]]
    assert _upward(graph) == [
        "pngail_jax.demos.make (demonstrations) imports pngail_jax.jobs.sweep (jobs), line 1"
    ]


def test_the_graph_holds_every_kind_of_import():
    """A function-body import (the package root's), ``from package import submodule``
    (runner's), a plain ``from module import name`` with the names it takes."""
    assert any(target == "storage.checkpoint" for target, _, _ in GRAPH[""])
    assert any(target == "jobs.sweep" for target, _, _ in GRAPH["runner"])
    assert ("demos.files", ["load_numpy"]) in [(t, n) for t, n, _ in GRAPH["demos.released"]]


def test_the_jobs_import_only_the_jobs_before_them():
    for position, job in enumerate(JOB_ORDER):
        for target, _, line in GRAPH[f"jobs.{job}"]:
            if target.startswith("jobs."):
                assert JOB_ORDER.index(target.removeprefix("jobs.")) < position, (
                    f"jobs.{job} imports {target} (line {line}), which comes after it"
                )
    assert sorted(JOB_ORDER) == sorted(
        name.removeprefix("jobs.") for name in MODULES if name.startswith("jobs.")
    )


def test_demos_reads_and_writes_data_only():
    for name, imports in GRAPH.items():
        if name == "demos" or name.startswith("demos."):
            for target, _, line in imports:
                assert target.split(".")[0] in ("demos", "envs") or target in PLAIN_TABLES, (
                    f"pngail_jax.{name} imports pngail_jax.{target} (line {line}): demos/ "
                    "imports envs and the plain tables alone"
                )
    for table in PLAIN_TABLES:
        assert not GRAPH[table], f"pngail_jax.{table}, a plain table, imports nothing"


# The modules that hold plain data only: they import nothing (demos/ reads the released
# files' table; the trainers and the reading of runs read the methods' table).
PLAIN_TABLES = ("config.released_files", "config.presets")
# What the reading of run folders may import, those inside functions too: itself and modules
# that import no JAX (checked by importing each in a fresh interpreter below).
NO_JAX = (
    "config.validation", "config.presets", "config.released_files", "config.output",
    "config.learner", "storage", "storage.integrity", "storage.outputs", "analysis", "analysis.*",
)  # fmt: skip
ANALYSIS = sorted(name for name in MODULES if name == "analysis" or name.startswith("analysis."))


def test_the_analysis_imports_only_modules_without_jax():
    """Every import of analysis/, those inside functions too, is of a module in NO_JAX: a
    function that imported a trainer would bring JAX in at its first call."""
    found = [
        f"pngail_jax.{name} imports pngail_jax.{target} (line {line})"
        for name in ANALYSIS
        for target, _, line in GRAPH[name]
        if not any(fnmatch(target, pattern) for pattern in NO_JAX)
    ]
    assert not found, "\n".join(found)


# The config's parts at the bottom (issue 74, item 1), each importing no JAX.
CONFIG_PARTS = (
    "config.learner", "config.budget", "config.grid_axes", "config.output", "config.classifier",
    "config.methods", "config.demonstrations",
)  # fmt: skip


@pytest.mark.parametrize(
    "name", ["analysis", *ANALYSIS, "config.presets", "storage.outputs", *CONFIG_PARTS]
)
def test_importing_a_reading_module_imports_no_jax(name):
    """In a fresh interpreter (this one has JAX already): importing the module leaves jax,
    jaxlib, flax and optax out of sys.modules."""
    import subprocess
    import sys

    code = (
        f"import sys, pngail_jax.{name}\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'jax', 'jaxlib', 'flax', 'optax'}))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert result.stdout.strip() == "[]", f"pngail_jax.{name} imports {result.stdout.strip()}"


def _room(name: str) -> str:
    """A module's room: its top folder, or the module itself at the package's root."""
    return name.split(".")[0] if "." in name or MODULES[name].name == "__init__.py" else name


def floors(graph) -> tuple[int, list[str]]:
    """The house's height: the most rooms an import chain passes through (a step within a
    room is no floor; the root's modules are rooms of their own), and that chain."""
    height: dict[str, tuple[int, list[str]]] = {}

    def climb(name):
        if name not in height:
            best = (1, [name])
            for target, _, _ in graph[name]:
                below, chain = climb(target)
                up = below + (_room(target) != _room(name))
                if up > best[0]:
                    best = (up, [name, *chain])
            height[name] = best
        return height[name]

    return max((climb(name) for name in graph), key=lambda found: found[0])


MOST_FLOORS = 11


def test_the_house_has_at_most_eleven_floors():
    height, chain = floors(GRAPH)
    assert height <= MOST_FLOORS, f"{height} floors: " + " -> ".join(chain)


def test_no_circle_between_rooms():
    """Between rooms (folders, and the root's modules) there is no circle either: config/
    imports no room above it (issue 74, item 1: its run config, which imported the trainers,
    now reads plain parts and the environments' names only)."""
    rooms: dict[str, list] = {}
    for name, imports in GRAPH.items():
        targets = rooms.setdefault(_room(name), [])
        targets += [(_room(t), [], line) for t, _, line in imports if _room(t) != _room(name)]
    assert not _circles(rooms), _circles(rooms)


def test_config_imports_only_config_and_the_environments_names():
    """config/ sits at the bottom: besides itself it reads envs/ alone (task names, physics
    engines, the settings' make_env), and envs/ imports nothing of config/."""
    found = [
        f"pngail_jax.{name} imports pngail_jax.{target} (line {line})"
        for name, imports in GRAPH.items()
        if name.split(".")[0] == "config"
        for target, _, line in imports
        if target.split(".")[0] not in ("config", "envs")
    ]
    assert not found, "\n".join(found)
    assert not [t for name in MODULES if name.split(".")[0] == "envs" for t, _, _ in GRAPH[name]
                if t.split(".")[0] == "config"]  # fmt: skip


def test_the_package_root_holds_at_most_eight_modules():
    root = sorted(path.name for path in PACKAGE.glob("*.py"))
    assert len(root) <= 8, root


def test_no_private_name_is_imported_across_files():
    private = [
        f"pngail_jax.{name} imports {target}.{imported} (line {line})"
        for name, imports in GRAPH.items()
        for target, names, line in imports
        for imported in names
        if imported.startswith("_")
    ]
    assert not private, "\n".join(private)


def _private_names_defined(tree: ast.AST) -> set[str]:
    """The private names a module defines: its functions, classes and module-level names,
    and the attributes it sets on ``self``."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            found.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            found.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            found.add(node.attr)
    return {name for name in found if name.startswith("_") and not name.startswith("__")}


def _private_reads(paths: dict[str, Path]) -> list[str]:
    """``obj._name`` read in one module of a private name that only other modules of the
    package define (an object's private part reached from outside its module: an import
    test cannot see that dependency). ``self``, ``cls`` and ``super()`` are the module's own;
    a private name of another library (``data._impl`` of MJX) is defined by none of ours."""
    trees = {name: ast.parse(path.read_text()) for name, path in paths.items()}
    defined = {name: _private_names_defined(tree) for name, tree in trees.items()}
    ours = set().union(*defined.values())
    found = []
    for name, tree in trees.items():
        for node in ast.walk(tree):
            if not isinstance(node, ast.Attribute) or node.attr not in ours:
                continue
            owner = node.value
            if isinstance(owner, ast.Name) and owner.id in ("self", "cls"):
                continue
            if isinstance(owner, ast.Call) and getattr(owner.func, "id", None) == "super":
                continue
            if node.attr not in defined[name]:
                found.append(f"{name}: {ast.unparse(node)} (line {node.lineno})")
    return found


def test_no_module_reads_another_modules_private_parts():
    """Modules of the package, benchmarks and programs reach other modules' objects through
    their public names only (a phase gets an explicit context, not the trainer)."""
    root = PACKAGE.parent
    paths = {f"pngail_jax.{name}": path for name, path in MODULES.items()}
    for folder in ("benchmarks", "experiments"):
        paths |= {f"{folder}/{p.name}": p for p in sorted((root / folder).glob("*.py"))}
    found = _private_reads(paths)
    assert not found, "\n".join(found)


def test_the_private_read_check_finds_a_read_across_modules(tmp_path):
    owner, reader = tmp_path / "owner.py", tmp_path / "reader.py"
    owner.write_text("class Trainer:\n    def __init__(self):\n        self._inputs = 1\n")
    reader.write_text("def step(trainer):\n    return trainer._inputs + trainer.public\n")
    assert _private_reads({"owner": owner, "reader": reader}) == [
        "reader: trainer._inputs (line 2)"
    ]
    reader.write_text("def step(self):\n    return self._inputs\n")
    assert _private_reads({"owner": owner, "reader": reader}) == []


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_module_is_too_long(name):
    lines = len(MODULES[name].read_text().splitlines())
    limit = LONGEST_JOB if name.startswith("jobs.") else LONGEST_MODULE
    assert lines <= limit, f"pngail_jax.{name} has {lines} lines (at most {limit})"
