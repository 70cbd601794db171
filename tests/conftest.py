import pathlib
import sys

import jax
import pytest

import gnc_jax  # noqa: F401  (turns on float64 and host devices before anything else)

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
