"""``python -m gnc_jax.cli``: the same as ``gnc-jax``."""

import sys

from . import main

sys.exit(main())
