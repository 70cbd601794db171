import jax
import pytest

import gnc_jax  # noqa: F401  (turns on float64 and host devices before anything else)


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
