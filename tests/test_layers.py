"""The package's imports run one way: the import-linter contracts of ``pyproject.toml`` (layers
top to bottom, systems independent of each other, guidance families independent of each other)
hold, so an upward import fails the build; and no module imports itself through others, inside
a layer either (a cycle, found with grimp, import-linter's own graph)."""

import pathlib
import shutil
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _lint_imports() -> subprocess.CompletedProcess:
    exe = shutil.which("lint-imports") or str(
        pathlib.Path(sys.executable).with_name("lint-imports")
    )
    return subprocess.run(
        [exe, "--config", str(ROOT / "pyproject.toml"), "--no-cache"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_every_import_contract_is_kept():
    result = _lint_imports()
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    assert "Contracts: 3 kept, 0 broken." in result.stdout


def test_an_upward_import_breaks_the_contract(tmp_path):
    """The check can fail: a copy of the package in which the geometry layer imports the
    Monte Carlo layer is refused."""
    copy = tmp_path / "gnc_jax"
    shutil.copytree(ROOT / "gnc_jax", copy, ignore=shutil.ignore_patterns("__pycache__", "*.npz"))
    with open(copy / "geometry" / "los.py", "a") as f:
        f.write("\nfrom .. import montecarlo  # noqa: E402, F401\n")
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    exe = shutil.which("lint-imports") or str(
        pathlib.Path(sys.executable).with_name("lint-imports")
    )
    result = subprocess.run(
        [exe, "--config", str(tmp_path / "pyproject.toml"), "--no-cache"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        env={"PYTHONPATH": str(tmp_path), "PATH": "/usr/bin:/bin"},
    )
    assert result.returncode != 0
    assert "gnc_jax.geometry.los -> gnc_jax.montecarlo" in result.stdout


_CYCLES = """
import sys, grimp
g = grimp.build_graph("gnc_jax")
found = sorted(
    (m, d)
    for m in g.modules
    for d in g.find_modules_directly_imported_by(m)
    if g.find_shortest_chain(importer=d, imported=m)
)
print(found)
"""


def _cycles(path: pathlib.Path) -> list:
    result = subprocess.run(
        [sys.executable, "-c", _CYCLES],
        cwd=path,
        capture_output=True,
        text=True,
        timeout=300,
        env={"PYTHONPATH": str(path), "PATH": "/usr/bin:/bin"},
    )
    assert result.returncode == 0, result.stderr[-2000:]
    return eval(result.stdout)  # a list of (importer, imported) pairs


def test_no_module_imports_itself_through_others():
    assert _cycles(ROOT) == []


def test_a_cycle_inside_a_layer_is_found(tmp_path):
    """The check can fail: in a copy where the entry family's base imports the reference
    trajectory (which imports the base), the cycle is reported."""
    copy = tmp_path / "gnc_jax"
    shutil.copytree(ROOT / "gnc_jax", copy, ignore=shutil.ignore_patterns("__pycache__", "*.npz"))
    with open(copy / "guidance" / "entry" / "base.py", "a") as f:
        f.write("\nfrom . import reference  # noqa: E402, F401\n")
    found = _cycles(tmp_path)
    assert ("gnc_jax.guidance.entry.base", "gnc_jax.guidance.entry.reference") in found


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__]))
