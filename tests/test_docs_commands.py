"""The shell commands of README.md and docs/ run exactly as written, and their links resolve.

A command block is an indented block whose first line is a command (COMMAND: `hpcwedge`,
`.venv/bin/...`, `mpirun`, `jobs/...`, `sbatch`, `make`, a `$ ` prompt, `. .venv/bin/activate`).
Without a prompt every line is a command; with one, the lines after a `$ ` line are what it
prints (compared line for line, the timings line aside). An HTML comment just before a block
says what to do with it instead (MARKER): `skip (why)` (a SLURM cluster, minutes, a run
stopped midway), `synopsis (why)` (a usage form with placeholders, not a command), or, before
a ```toml block, `file PATH`: the block is saved as PATH (or, when the repository has PATH,
must be that file, byte for byte).

A page's commands run in order in one scratch folder that stands for the repository root
(symlinks to the package, .venv, scripts/ and jobs/), as this machine's user (root here), with
no Open MPI settings from the environment (OMPI_*, PRTE_*: the docs' own flags must do) and
PYTHONPATH at this checkout (a fresh clone's editable install does the same). Environment
lines (`. FILE`, `source FILE`, `export ...`) carry over to the later commands.
"""
from __future__ import annotations

import glob
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, field

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: the pages of docs/ itself (not those its symlinks show: jobs/README.md, results/) and the README
PAGES = sorted(os.path.relpath(p, ROOT) for p in glob.glob(os.path.join(ROOT, "docs", "**", "*.md"), recursive=True)
               if os.path.realpath(p) == os.path.join(os.path.realpath(ROOT), os.path.relpath(p, ROOT))) + ["README.md"]
#: pages whose commands this test does not run yet, and why
NOT_YET: dict[str, str] = {}
COMMAND = re.compile(r"^(\$ |\. \S|source |export |hpcwedge |\.venv/bin/|mpirun |jobs/|sbatch |make |srun "
                     r"|PYTHONPATH=|python )")
MARKER = re.compile(r"^<!-- commands: (skip|synopsis|file) ?(.*?) ?-->$")
ENVIRONMENT = re.compile(r"^(\. |source |export )")
#: the slowest command of a page (mpirun with 4 ranks on 2 shared cores)
TIMEOUT = 600


@dataclass
class Block:
    """One block of a page: its first line (1-based), marker (None, "skip", "synopsis",
    "file"), the marker's text, and its lines (commands, or the file's text)."""

    line: int
    marker: str | None
    why: str
    lines: list[str] = field(default_factory=list)
    fenced: bool = False


def blocks(text: str) -> list[Block]:
    """The command blocks and marked blocks of a Markdown page, in order."""
    out, marker, why, lines = [], None, "", text.splitlines()
    i = 0
    while i < len(lines):
        ln = lines[i]
        if m := MARKER.match(ln.strip()):
            marker, why = m.group(1), m.group(2).strip()
        elif ln.startswith("```"):
            j = next(k for k in range(i + 1, len(lines)) if lines[k].startswith("```"))
            if marker:
                out.append(Block(i + 1, marker, why, lines[i + 1:j], fenced=True))
            marker, i = None, j
        elif ln.startswith("    ") and (i == 0 or not lines[i - 1].strip()):
            j = i
            while j < len(lines) and lines[j].startswith("    "):
                j += 1
            body = [x[4:] for x in lines[i:j]]
            if marker or COMMAND.match(body[0]):
                out.append(Block(i + 1, marker, why, body))
            marker, i = None, j - 1
        elif ln.strip():
            marker = None if not ln.startswith("<!--") else marker
        i += 1
    return out


def commands(block: Block) -> list[tuple[str, list[str] | None]]:
    """(command, the output shown or None) of a command block."""
    if not any(ln.startswith("$ ") for ln in block.lines):
        return [(ln, None) for ln in block.lines if ln.strip()]
    out = []
    for ln in block.lines:
        if ln.startswith("$ "):
            out.append((ln[2:], []))
        elif out:
            out[-1][1].append(ln)
    return out


def scratch(tmp_path) -> str:
    """A folder that stands for the repository root: the package, .venv, scripts/, jobs/."""
    venv = os.path.dirname(os.path.dirname(sys.executable))
    for name, target in (("hpcwedge", os.path.join(ROOT, "hpcwedge")), (".venv", venv),
                         ("scripts", os.path.join(ROOT, "scripts")), ("jobs", os.path.join(ROOT, "jobs"))):
        (tmp_path / name).symlink_to(target)
    return str(tmp_path)


def user_environment() -> dict:
    """This process's environment without any Open MPI or hpcwedge settings, PYTHONPATH at
    this checkout."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PRTE_", "PMIX_", "HPCWEDGE_"))}
    env["PYTHONPATH"] = ROOT
    return env


def page_blocks(page: str) -> list[Block]:
    return blocks(open(os.path.join(ROOT, page)).read())


RUN_PAGES = [p for p in PAGES if any(b.marker is None and not b.fenced for b in page_blocks(p))]


def test_every_command_page_is_run_or_says_why():
    """The README, the tutorial, the guide and the parallel page's commands are run below;
    every skip and synopsis gives its reason."""
    assert {"README.md", "docs/tutorial.md", "docs/guide/scenes.md", "docs/parallel.md"} <= set(RUN_PAGES)
    for page in PAGES:
        for b in page_blocks(page):
            if b.marker in ("skip", "synopsis"):
                assert b.why.startswith("(") and len(b.why) > 10, f"{page}:{b.line}: a {b.marker} without a reason"


def test_blocks_reads_markers_prompts_and_plain_lines():
    """The block reader on a page with each kind (the reading the page test relies on)."""
    text = ("Intro\n\n    hpcwedge run a.toml -o a.h5   # solve\n    hpcwedge show a.h5\n\n"
            "<!-- commands: skip (needs SLURM) -->\n\n    sbatch x\n\n"
            "Output:\n\n    $ hpcwedge show a.h5\n    a: dim 2\n    timings: 1 s\n\n"
            "<!-- commands: file a.toml -->\n```toml\nname = 1\n```\n\n    x = 1 + 2   (a formula)\n")
    got = blocks(text)
    assert [(b.line, b.marker, b.fenced) for b in got] == [(3, None, False), (8, "skip", False),
                                                          (12, None, False), (17, "file", True)]
    assert commands(got[0]) == [("hpcwedge run a.toml -o a.h5   # solve", None), ("hpcwedge show a.h5", None)]
    assert commands(got[2]) == [("hpcwedge show a.h5", ["a: dim 2", "timings: 1 s"])]
    assert got[3].why == "a.toml" and got[3].lines == ["name = 1"]


@pytest.mark.mpi
@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun: make setup installs Open MPI")
@pytest.mark.parametrize("page", RUN_PAGES)
def test_page_commands_run_as_written(page, tmp_path):
    """Every command of the page exits 0 as written, in order, and prints what the page
    shows after a `$ ` prompt (timings aside); files the page names are written or, when
    the repository has them, are what the page shows."""
    if page in NOT_YET:
        pytest.skip(NOT_YET[page])
    cwd, env, prefix = scratch(tmp_path), user_environment(), []
    for b in page_blocks(page):
        where = f"{page}:{b.line}"
        if b.marker == "file":
            text = "\n".join(b.lines) + "\n"
            if os.path.exists(os.path.join(ROOT, b.why)):
                assert open(os.path.join(ROOT, b.why)).read() == text, f"{where}: not the file {b.why}"
            else:
                with open(os.path.join(cwd, b.why), "w") as f:
                    f.write(text)
            continue
        if b.marker or b.fenced:
            continue
        for cmd, shown in commands(b):
            p = subprocess.run(["bash", "-c", "\n".join(prefix + [cmd])], cwd=cwd, env=env, capture_output=True,
                               text=True, timeout=TIMEOUT)
            assert p.returncode == 0, f"{where}: `{cmd}` exit {p.returncode}: {p.stderr[-2000:]}"
            if shown is not None:
                got = [ln for ln in p.stdout.splitlines() if not ln.startswith("timings:")]
                assert got == [ln for ln in shown if not ln.startswith("timings:")], f"{where}: `{cmd}` printed"
            if ENVIRONMENT.match(cmd):
                prefix.append(cmd)


# ---- links -------------------------------------------------------------------------------

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def links(page: str) -> list[str]:
    """The relative links and images of a page outside code (no scheme, no bare #anchor)."""
    text = re.sub(r"^```.*?^```", "", open(os.path.join(ROOT, page)).read(), flags=re.S | re.M)
    text = re.sub(r"`[^`\n]*`", "", text)
    return [t for t in LINK.findall(text) if "://" not in t and not t.startswith(("#", "mailto:"))]


@pytest.mark.parametrize("page", PAGES)
def test_links_resolve_in_the_repository(page):
    """Every relative link or image of README.md and docs/ names a file of the checkout, as
    GitHub and an editor resolve it (the site build, test_docs.test_site_builds_strict, checks
    the built site's view: mkdocs --strict fails on a link it cannot resolve)."""
    broken = [t for t in links(page)
              if not os.path.exists(os.path.normpath(os.path.join(ROOT, os.path.dirname(page), t.split("#")[0])))]
    assert broken == []


def test_generated_pages_are_committed_and_current():
    """The pages the docs link to exist in the checkout: the scene reference is the one the
    parser's key table renders, guide/jobs.md is jobs/README.md and docs/results the figures."""
    sys.path.insert(0, os.path.join(ROOT, "scripts"))
    import docs_pages
    assert docs_pages.stale_scene_reference() == ""
    assert os.path.samefile(os.path.join(ROOT, "docs", "guide", "jobs.md"), os.path.join(ROOT, "jobs", "README.md"))
    assert os.path.samefile(os.path.join(ROOT, "docs", "results"), os.path.join(ROOT, "results"))


def test_tutorial_cork_scene_is_the_file_it_names():
    """The tutorial's cork scene is scripts/examples/cork2d.toml byte for byte (before: the
    tutorial's copy left out `thickness` and `[compute]`)."""
    text = open(os.path.join(ROOT, "docs", "tutorial.md")).read()
    shown = [b for b in blocks(text) if b.fenced and b.why == "scripts/examples/cork2d.toml"]
    assert len(shown) == 1
    assert "\n".join(shown[0].lines) + "\n" == open(os.path.join(ROOT, "scripts", "examples", "cork2d.toml")).read()
