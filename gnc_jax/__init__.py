"""gnc_jax: JAX-vectorised batch simulator for spacecraft GNC."""
from . import _config  # noqa: F401  (float64, host devices)

