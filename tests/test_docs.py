"""The docs say what the code does: every module is on the architecture page, every docs page
is in the README's index (every results page in docs/results.md's), every link and anchor
resolves, and every flag of a documented command is one its program knows."""

import importlib
import itertools
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def test_every_module_is_on_the_architecture_page():
    page = (ROOT / "docs" / "architecture.md").read_text()
    modules = [
        path
        for folder in ("pngail_jax",)
        for path in (ROOT / folder).rglob("*.py")
        if path.name != "__init__.py"
    ]
    missing = [str(path.relative_to(ROOT)) for path in modules if path.stem not in page]
    assert not missing, f"docs/architecture.md does not name {missing}"


def test_every_docs_page_is_in_the_readmes_index():
    """The README's "Documentation" section links every page of docs/."""
    readme = (ROOT / "README.md").read_text()
    index = readme.split("\n## Documentation\n", 1)[1].split("\n## ", 1)[0]
    pages = sorted(path.name for path in (ROOT / "docs").glob("*.md"))
    missing = [name for name in pages if f"](docs/{name})" not in index]
    assert not missing, f"the README's docs index lacks {missing}"


def test_every_results_page_is_in_the_results_index():
    """docs/results.md is the index of the results pages: it links each page of docs/results/,
    so a page added there is found from it."""
    index = (ROOT / "docs" / "results.md").read_text()
    pages = sorted(path.name for path in (ROOT / "docs" / "results").glob("*.md"))
    assert len(pages) >= 5, pages
    missing = [name for name in pages if f"](results/{name}" not in index]
    assert not missing, f"docs/results.md does not link {missing}"


def heading_anchor(heading: str) -> str:
    """The anchor GitHub gives a Markdown heading: its text (a link's label, no backticks) in
    lower case, every character but letters, digits, '_', '-' and spaces dropped, spaces
    turned into '-'."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip().lower()).replace("`", "")
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """The anchors of a page's headings (outside code fences); a repeated heading's later
    anchors get -1, -2, ..., as on GitHub."""
    found, seen, fenced = set(), {}, False
    for line in page.read_text().split("\n"):
        fenced ^= line.startswith("```")
        heading = re.match(r"#{1,6} (.+)", line)
        if heading and not fenced:
            anchor = heading_anchor(heading.group(1))
            count = seen.get(anchor, 0)
            found.add(f"{anchor}-{count}" if count else anchor)
            seen[anchor] = count + 1
    return found


def test_a_heading_gets_githubs_anchor():
    title = (
        "Fig. 2 / 3 on the authors' Hopper and HalfCheetah files (MuJoCo's C engine, a CPU budget)"
    )
    assert heading_anchor(title) == (
        "fig-2--3-on-the-authors-hopper-and-halfcheetah-files-mujocos-c-engine-a-cpu-budget"
    )
    assert heading_anchor("What PN-GAIL\\BSC needs: `--docs`") == "what-pn-gailbsc-needs---docs"
    assert heading_anchor("See [the index](results.md)") == "see-the-index"


def test_every_relative_link_and_anchor_of_the_docs_resolves(tmp_path):
    """Each link of README.md and docs/**/*.md to a file of the repository names one that
    exists, and its #anchor (or a same-page #anchor) one of that page's headings: a section
    moved to another page leaves no link behind."""
    broken = []
    for page in PAGES:
        text = re.sub(r"```.*?```", "", page.read_text(), flags=re.DOTALL)
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if "://" in target or target.startswith("mailto:"):
                continue
            path, _, anchor = target.partition("#")
            linked = (page.parent / path).resolve() if path else page
            name = f"{page.relative_to(ROOT)}: {target}"
            if not linked.exists():
                broken.append(f"{name} (no such file)")
            elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
                broken.append(f"{name} (no such heading)")
    assert not broken, f"broken links: {broken}"
    # the check itself: a moved section's anchor is found broken
    page = tmp_path / "page.md"
    page.write_text("# Title\n\n## A section\n\n```\n# not a heading\n```\n\n## A section\n")
    assert anchors(page) == {"title", "a-section", "a-section-1"}


def documented_commands():
    """(page, program, flags) of every `python -m experiments.X ...` in the README and docs,
    in code blocks and inline (continuation lines joined; a comment or a closing backtick
    ends the command)."""
    found = []
    for page in PAGES:
        text = re.sub(r"\\\n\s*", " ", page.read_text())
        for match in re.finditer(r"python -m experiments\.(\w+)([^`\n]*)", text):
            command = match.group(2).split("#")[0]
            flags = re.findall(r"(?<!\S)(--[a-z][a-z0-9-]*)", command)
            found.append((page.name, match.group(1), flags))
    return found


COMMANDS = documented_commands()


def test_the_docs_document_commands_at_all():
    programs = {program for _, program, _ in COMMANDS}
    assert {"sweep", "paper", "classify", "make_demos", "train_rl"} <= programs, programs


@pytest.mark.parametrize("program", sorted({program for _, program, _ in COMMANDS}))
def test_every_documented_flag_exists(program, capsys):
    module = importlib.import_module(f"pngail_jax.programs.{program}")
    with pytest.raises(SystemExit, match="^0$"):  # --help exits 0, its text on stdout
        module.parse_args(["--help"])
    help_text = capsys.readouterr().out
    assert help_text.startswith(f"usage: python -m experiments.{program} "), help_text[:80]
    known = set(re.findall(r"--[a-z][a-z0-9-]*", help_text))
    unknown = sorted(
        {
            (page, flag)
            for page, name, flags in COMMANDS
            if name == program
            for flag in flags
            if flag not in known
        }
    )
    assert not unknown, f"documented flags that experiments.{program} does not know: {unknown}"


def test_every_program_runs_from_a_checkout_and_as_an_installed_command():
    """Each program has its one-line ``python -m experiments.<program>`` entry point (the
    checkout's) and its console script (pyproject.toml); the documented ones are among them."""
    import tomllib

    from pngail_jax.programs import commands

    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    for program in commands.PROGRAMS:
        entry = (ROOT / "experiments" / f"{program}.py").read_text()
        assert f"from pngail_jax.programs.{program} import main" in entry, program
        name = f"pngail-{program.replace('_', '-')}"
        assert scripts[name] == f"pngail_jax.programs.commands:{program}", name
        assert callable(getattr(commands, program))
    assert {program for _, program, _ in COMMANDS} <= set(commands.PROGRAMS)
    entries = {path.stem for path in (ROOT / "experiments").glob("*.py")} - {"__init__"}
    assert entries == set(commands.PROGRAMS)


def test_every_local_image_and_link_of_the_docs_is_in_git():
    """A figure the README shows must be committed (``*.png`` is ignored by default, so a new
    one needs ``git add -f``); a link to a missing page is a broken door."""
    import subprocess

    try:
        listed = subprocess.run(
            ["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    tracked = set(listed)
    missing = []
    for page in PAGES:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text()):
            if "://" in target or target.startswith("mailto:"):
                continue
            path = (page.parent / target).resolve()
            if path.is_relative_to(ROOT) and str(path.relative_to(ROOT)) not in tracked:
                if not any(name.startswith(f"{path.relative_to(ROOT)}/") for name in tracked):
                    missing.append(f"{page.name}: {target}")
    assert not missing, f"linked but not in git: {missing}"


def test_the_readmes_status_cells_are_short():
    """The README's status table says what each piece is and where to read more, in at most
    25 words a cell; the measured detail lives in docs/."""
    lines = (ROOT / "README.md").read_text().split("\n")
    start = lines.index("| piece | state |") + 2
    rows = list(itertools.takewhile(lambda line: line.startswith("|"), lines[start:]))
    assert len(rows) >= 5
    for row in rows:
        for cell in row.strip().strip("|").split("|"):
            words = len(re.sub(r"\]\([^)]*\)", "]", cell).split())  # a link's target is no word
            assert words <= 25, f"{words} words in the status cell {cell.strip()[:60]!r}..."
