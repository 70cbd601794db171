"""The documentation cannot rot: the site builds with warnings as errors, and every
Python block of every page runs.

A page's ```python blocks run in order in one namespace, each page in a fresh interpreter in a
temporary directory, with run counts reduced (``runs=N`` becomes ``runs=min(N, 300)``) so the
suite stays small; a block that only shows a file (a ``--8<--`` include) is not run. A page
opts a block out with an HTML comment ``<!-- no-run -->`` on the line before it.
"""

import os
import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
BLOCK = re.compile(r"(<!-- no-run -->\s*\n)?```python\n(.*?)```", re.S)
# A deep-impact-los study of 300 runs is the one tests/test_peer_numba.py and the impactor's
# paper-scale test compile (read from the session's XLA cache); 300 runs take a fraction of a
# second next to a compilation.
MAX_RUNS = 300


def python_blocks(page: pathlib.Path) -> list[str]:
    blocks = []
    for skip, code in BLOCK.findall(page.read_text()):
        if skip or "--8<--" in code:
            continue
        reduce = lambda m: f"runs={min(int(m.group(1)), MAX_RUNS)}"  # noqa: E731
        blocks.append(re.sub(r"runs=(\d+)", reduce, code))
    return blocks


PAGES = sorted(p for p in DOCS.rglob("*.md") if python_blocks(p))


def test_the_pages_with_code_are_found():
    names = {p.relative_to(DOCS).as_posix() for p in PAGES}
    assert {"getting-started.md", "howto/add-a-law.md", "howto/add-a-measurement.md"} <= names


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(DOCS).as_posix())
def test_every_python_block_runs(page, tmp_path):
    code = "\n\n".join(python_blocks(page))
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert proc.returncode == 0, f"{page.name}:\n{proc.stderr[-3000:]}"


def test_the_site_builds_without_warnings(tmp_path):
    pytest.importorskip("mkdocs")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert (tmp_path / "site" / "howto" / "add-a-law" / "index.html").is_file()


def test_the_readme_headlines_quote_the_reproduction_table():
    """Each README headline "miss RMS|mean paper → gnc_jax m" is the reproduction table's row
    of that scenario, to the headline's one decimal."""
    table = (DOCS / "explanation" / "reproduction.md").read_text()
    rows, scenario = {}, None
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 5 and cells[0].startswith("`"):
            scenario = cells[0].strip("`")
        if len(cells) == 5 and scenario:
            rows[(scenario, cells[2])] = cells[4]
    headline = re.compile(r"^\| `([\w-]+)`.*?\| (miss (?:RMS|mean)) [\d.]+ → ([\d.]+) m", re.M)
    found = headline.findall((ROOT / "README.md").read_text())
    assert len(found) >= 4
    for name, metric, value in found:
        assert float(value) == round(float(rows[(name, f"{metric} (m)")]), 1), (name, metric)
