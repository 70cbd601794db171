"""Process-wide JAX configuration: float64 and one XLA host device per core.

On a machine with a GPU and JAX's GPU build, JAX's default backend is the GPU and the host
devices below serve ``device="cpu"`` studies (:mod:`gnc_jax.backend`).

Set when ``gnc_jax`` is imported, through public settings only, and overridable:

* **float64** (``jax_enable_x64``): every gnc_jax computation needs it (7e7 m ranges with
  metre-level misses). ``GNC_JAX_ENABLE_X64=0`` leaves JAX's setting alone (at your own risk;
  the test suite assumes float64).
* **host devices**: XLA runs a CPU computation on one core per device, so a batch is split over
  as many host devices as there are cores (``--xla_force_host_platform_device_count`` in
  ``XLA_FLAGS``). ``GNC_JAX_HOST_DEVICES=n`` chooses the count (``1`` disables the split); an
  ``XLA_FLAGS`` that already names the flag is left as it is. The flag is put first: XLA
  ignores whatever follows a bare token such as ``intra_op_parallelism_threads=1``. It only
  takes effect if JAX's backend has not started yet, so import ``gnc_jax`` before anything
  runs a JAX computation; otherwise the study runs on the devices JAX already has.
"""

import os

_FLAG = "--xla_force_host_platform_device_count"


def _configure_host_devices() -> None:
    flags = os.environ.get("XLA_FLAGS", "")
    if _FLAG in flags:
        return
    n = int(os.environ.get("GNC_JAX_HOST_DEVICES", os.cpu_count() or 1))
    os.environ["XLA_FLAGS"] = f"{_FLAG}={max(n, 1)} {flags}".strip()


_configure_host_devices()

import jax  # noqa: E402  (after XLA_FLAGS: the backend reads them when it starts)

if os.environ.get("GNC_JAX_ENABLE_X64", "1") != "0":
    jax.config.update("jax_enable_x64", True)
