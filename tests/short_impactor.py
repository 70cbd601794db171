"""The impactor's cheap test scenario with proportionally smaller errors, shared by the tests
that fly it: the system's ``test_overrides`` (a 15-minute approach, 9180 km: the whole chain
in a tenth of the steps) and a 1 km delivery error with 20 km of range knowledge. The errors
are leaves of the compiled program: a study of it in chunks of ``CHUNK`` runs on every device
is the program tests/test_family.py compiles for the impactor, read from the session's cache.
"""

import json

import gnc_jax as gj

SHORT = [f"{k}={json.dumps(v)}" for k, v in gj.get_system("impactor").test_overrides.items()] + [
    "errors.delivery_position_km=1.0",
    "navigation.knowledge_position_km=[20.0, 1.0, 1.0]",
]
CHUNK = 4  # runs per compiled call: tests/test_family.py's chunked study
