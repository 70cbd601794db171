"""Process-wide JAX configuration: float64 everywhere and one XLA host device per core.

XLA runs a CPU computation on one core per device, so a batch is split over as many host
devices as there are cores. The device count must be set before JAX initialises its backend;
this module does that when `gnc_jax` is imported first. Set ``GNC_JAX_HOST_DEVICES`` to
override the count (``1`` disables the split), or set ``XLA_FLAGS`` yourself.
"""

import os
import sys

_FLAG = "--xla_force_host_platform_device_count"


def _configure_host_devices() -> None:
    flags = os.environ.get("XLA_FLAGS", "")
    if _FLAG in flags:
        return
    if "jax" in sys.modules:
        try:  # backend already up: too late to change the device count
            import jax._src.xla_bridge as xb

            if xb.backends_are_initialized():
                return
        except Exception:
            return
    n = int(os.environ.get("GNC_JAX_HOST_DEVICES", os.cpu_count() or 1))
    os.environ["XLA_FLAGS"] = f"{flags} {_FLAG}={max(n, 1)}".strip()


_configure_host_devices()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
