import os
import pathlib
import shutil
import sys
import tempfile

# Test worker processes (pytest-xdist) share a GPU where there is one: none of them may take
# JAX's default 75 % of its memory on its first computation.
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

import jax  # noqa: E402
import pytest  # noqa: E402

import gnc_jax  # noqa: E402, F401  (turns on float64 and host devices before anything else)

# The toy system of tests/toy_system.py is registered from outside the package, as a user's
# would be; the family tests (tests/test_family.py) then cover it like every built-in system.
sys.path.insert(0, str(pathlib.Path(__file__).parent))
import toy_system  # noqa: E402, F401


def pytest_addoption(parser):
    parser.addoption(
        "--paper-scale",
        action="store_true",
        default=False,
        help="run the slow checks at the paper's run counts instead of the reduced CI size",
    )


@pytest.fixture
def paper_scale(request) -> bool:
    return request.config.getoption("--paper-scale")


@pytest.fixture
def key():
    return jax.random.key(20101002)


def pytest_configure(config):
    """One persistent XLA compilation cache for the whole test session: the pytest-xdist
    workers and every ``gnc-jax`` subprocess a test starts inherit its directory, so a program
    one process compiled (a scenario's design, a CLI run of an example) is read, not compiled
    again, by the next. It starts empty in each session (nothing carries over between CI
    runs), unless ``JAX_COMPILATION_CACHE_DIR`` is set by the caller."""
    if "JAX_COMPILATION_CACHE_DIR" not in os.environ:  # the controller (or a plain run)
        path = tempfile.mkdtemp(prefix="gnc-jax-tests-xla-")
        os.environ["JAX_COMPILATION_CACHE_DIR"] = path
        config._gnc_jax_xla_cache = path
    # Programs that compile in 0.1 s or more are kept (JAX keeps those of 1 s or more by
    # default): the tests' many small programs are compiled once for both workers too.
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.1")
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update(
        "jax_persistent_cache_min_compile_time_secs",
        float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]),
    )


def pytest_unconfigure(config):
    path = getattr(config, "_gnc_jax_xla_cache", None)
    if path:
        shutil.rmtree(path, ignore_errors=True)
