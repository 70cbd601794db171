"""The devices a study runs on, and the optional parts of the package.

:func:`select` answers ``device="cpu" | "gpu" | "auto"`` with a :class:`Backend`: the platform,
its devices, their kind and one device's memory limit. ``"auto"`` is JAX's default backend (a
GPU where JAX finds one, else the CPU's host devices); asking for a GPU where JAX finds none is
refused in one line naming the extra that installs JAX's GPU build. :func:`describe` is what
``summary.json``, the CLI's result line and the benchmarks record of the machine.

:func:`require` imports an optional dependency or refuses in one line naming its extra
(``cluster`` for Dask, ``bench`` for the benchmark peers, ``cuda12``/``cuda13`` for a GPU).
"""

import contextlib
import dataclasses
import importlib
import os
import platform as _platform

import jax

from .scenario import ScenarioError

DEVICES = ("auto", "cpu", "gpu")
"""Allowed values of ``run_study(device=...)`` and the CLI's ``--device``."""
GPU_EXTRA = "pip install 'gnc_jax[cuda12]' (or [cuda13]; NVIDIA GPUs, Linux)"
"""How to get JAX's GPU build, named by every refusal of a missing GPU."""


@dataclasses.dataclass(frozen=True)
class Backend:
    """A platform and the devices of it a study shards over.

    Attributes:
        platform: ``"cpu"`` or ``"gpu"``; device_kind: the devices' name (``"cpu"``,
        ``"NVIDIA H100 80GB HBM3"``); devices: the JAX devices (for a fake backend in tests,
        anything with a length); memory_bytes: the memory one device may allocate (a GPU's
        allocator limit; for the CPU the machine's physical memory, which its host devices
        share); default: whether this is JAX's default backend (its computations need no
        placement).
    """

    platform: str
    device_kind: str
    devices: tuple
    memory_bytes: int | None
    default: bool = True

    @property
    def count(self) -> int:
        return len(self.devices)


def physical_memory() -> int:
    """The machine's physical memory in bytes (8 GiB where the OS does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 8 << 30


def _platform_devices(name: str) -> list:
    try:
        return list(jax.devices(name))
    except RuntimeError:  # JAX has no backend of that platform
        return []


def _memory_limit(device) -> int | None:
    if device.platform == "cpu":
        return physical_memory()
    try:
        stats = device.memory_stats() or {}
    except Exception:  # a backend without memory statistics
        return None
    return stats.get("bytes_limit")


def select(device: str | None = "auto") -> Backend:
    """The :class:`Backend` for ``device`` (``None`` is ``"auto"``); a :class:`ScenarioError`
    naming the extra when a GPU is asked for and JAX finds none."""
    device = "auto" if device is None else device
    if device not in DEVICES:
        raise ScenarioError(f"device: {device!r}; allowed: {', '.join(DEVICES)}")
    default = jax.devices()
    if device == "auto" or default[0].platform == device:
        devices = default
    elif device == "gpu":
        devices = _platform_devices("gpu")
        if not devices:
            present = ", ".join(sorted({d.platform for d in default}))
            raise ScenarioError(
                f"device: gpu, but JAX finds no GPU (platforms here: {present}); allowed: "
                f"cpu or auto, or install JAX's GPU build: {GPU_EXTRA}"
            )
    else:
        devices = _platform_devices("cpu")
    first = devices[0]
    return Backend(
        platform="cpu" if first.platform == "cpu" else "gpu",
        device_kind=first.device_kind,
        devices=tuple(devices),
        memory_bytes=_memory_limit(first),
        default=first.platform == default[0].platform,
    )


def placement(backend: Backend):
    """A context in which JAX creates arrays and runs computations on ``backend`` (nothing to
    do for JAX's default backend)."""
    if backend.default:
        return contextlib.nullcontext()
    return jax.default_device(backend.devices[0])


def versions() -> dict[str, str]:
    """jax, jaxlib and, where JAX runs on CUDA, the CUDA runtime's version as JAX reports it."""
    import jaxlib

    out = {"jax": jax.__version__, "jaxlib": jaxlib.__version__}
    if _platform_devices("gpu"):
        try:
            from jax.extend.backend import get_backend

            text = " ".join(str(get_backend("gpu").platform_version).split())
            out["cuda"] = text[:80]
        except Exception:  # a JAX without that attribute: versions still recorded
            pass
    return out


def describe(backend: Backend, n_devices: int | None = None) -> dict:
    """What a study records of where it ran (``summary.json``'s ``device``)."""
    count = min(n_devices or backend.count, backend.count)
    out = dict(
        platform=backend.platform,
        device_kind=backend.device_kind,
        device_count=count,
        memory_gb=round(backend.memory_bytes / 1e9, 2) if backend.memory_bytes else None,
        cpu_cores=os.cpu_count(),
        python=f"{_platform.python_implementation()} {_platform.python_version()}",
    )
    out.update(versions())
    return out


def describe_line(info: dict) -> str:
    """One line of :func:`describe`'s record: the machine line of the CLI and benchmarks."""
    if info["platform"] == "cpu":
        where = f"{info['device_count']} CPU host devices ({info['cpu_cores']} cores)"
    else:
        memory = f", {info['memory_gb']:g} GB" if info.get("memory_gb") else ""
        where = f"{info['device_count']} x {info['device_kind']}{memory}"
    cuda = f", CUDA {info['cuda']}" if info.get("cuda") else ""
    return (
        f"{where}; {_platform.machine()}, jax {info['jax']}, jaxlib {info['jaxlib']}{cuda}, "
        f"{info['python']}"
    )


EXTRAS = {
    "dask": "cluster",
    "dask.distributed": "cluster",
    "numba": "bench",
    "psutil": "bench",
}
"""The extra that installs each optional module."""


def require(module: str, option: str):
    """``importlib.import_module(module)``, or a :class:`ScenarioError` in one line naming
    ``option`` (what asked for it) and the extra that installs it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        extra = EXTRAS.get(module, EXTRAS.get(module.split(".")[0], ""))
        raise ScenarioError(
            f"{option}: needs {module}, which is not installed; allowed: "
            f"pip install 'gnc_jax[{extra}]'"
        ) from None
