"""gnc_jax: JAX-vectorised batch simulator for spacecraft guidance, navigation and control.

Typical use::

    import gnc_jax as gj
    scenario = gj.load_scenario("deep-impact-los", overrides=["guidance.k1=3"])
    study = gj.run_study(scenario, runs=2000, seed=0)
    print(study.summary()["miss_rms_m"])
    study.save("results/los")
    gj.report("results/los")

Importing gnc_jax turns on float64 and splits the CPU into one XLA device per core
(``GNC_JAX_HOST_DEVICES`` overrides the count, ``GNC_JAX_ENABLE_X64=0`` leaves JAX's precision
alone; see ``gnc_jax._config``); import it before anything runs a JAX computation.
"""

from . import _config  # noqa: F401  (float64, host devices: must run before jax is used)
from ._random import stream_key, stream_normal, stream_uniform
from ._status import Status
from ._version import __version__
from .budget import Budget, budget
from .cells import run_cells
from .montecarlo import CostEstimate, build, estimate_cost, run_key, simulate_one
from .operating_envelope import Envelope, envelope
from .report import report
from .reproduction import reproduce
from .results import ResultsError, load_results
from .scenario import Scenario, ScenarioError, list_scenarios, load_scenario
from .study import Study, run_study
from .systems import AbstractSystem, ErrorSource, get_system, register_system, systems
from .tuning import TuneResult, tune

__all__ = [
    "__version__",
    "Status",
    "Envelope",
    "envelope",
    "Study",
    "Budget",
    "budget",
    "ErrorSource",
    "stream_key",
    "stream_normal",
    "stream_uniform",
    "build",
    "AbstractSystem",
    "get_system",
    "register_system",
    "systems",
    "run_key",
    "run_cells",
    "run_study",
    "estimate_cost",
    "CostEstimate",
    "simulate_one",
    "reproduce",
    "report",
    "load_results",
    "ResultsError",
    "Scenario",
    "ScenarioError",
    "list_scenarios",
    "load_scenario",
    "tune",
    "TuneResult",
]
