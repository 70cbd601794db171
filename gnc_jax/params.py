"""Parameters declared once: a Module field in SI units that also declares its scenario field.

A tunable gain, an error source or any other scenario value is declared once, on the
``equinox.Module`` that uses it, with :func:`param`::

    class LOSSwitchingCurveGuidance(AbstractImpactorGuidance):
        k1: Scalar = param(4.0, lo=0.0, lo_open=True, hi=100.0, doc="miss tolerance gain")
        image_sigma_rad: Scalar = param(10.0, toml="image_sigma_urad", scale=1e-6, units="urad")

The declaration holds the default in the scenario file's units (the papers' units: km, urad,
deg, ...), the factor ``scale`` to SI (SI value = file value x scale), the allowed range and the
meaning. From it:

* the Module's own default is the SI value (``default x scale``);
* :func:`schema_of` derives the scenario schema of the Module (one :class:`Field` per declared
  field, keyed by its file name);
* :func:`from_config` builds the Module from a validated scenario section, converting each
  value to SI exactly as ``value * scale`` (so a build is bit-identical to writing it out).

Nothing else holds a default or a unit of these fields.
"""

import dataclasses
from typing import Any

import equinox as eqx
import jax.numpy as jnp

from .schema import Field

_KEY = "gnc_jax.param"


@dataclasses.dataclass(frozen=True)
class ParamSpec:
    """What :func:`param` attaches to a Module field (in ``field.metadata``)."""

    field: Field  # the scenario-file declaration (file units)
    toml: str  # file name of the field ("" = the attribute's name)
    scale: float  # SI = file value x scale
    derived: bool = False  # SI value depends on other fields: the owner's from_config converts
    convert: Any = None  # file value -> SI value, when not a plain factor
    static: bool = False  # a static field (ints, strings, and floats declared static)
    section: str = ""  # the scenario section of the field ("": the owner's own table)
    tunable: bool = False  # a gain users tune (``gnc-jax tune``, the family gradient tests)

    def to_si(self, value):
        kind = self.field.kind
        if self.convert is not None:
            value = self.convert(value)
            return float(value) if self.static else jnp.asarray(value, dtype=jnp.float64)
        if kind == "float" and self.static:
            return float(value * self.scale)
        if kind == "floats":
            return jnp.asarray(value, dtype=jnp.float64) * self.scale
        if kind == "float":
            return jnp.asarray(value * self.scale, dtype=jnp.float64)
        if kind == "bool":
            return jnp.asarray(1.0 if value else 0.0, dtype=jnp.float64)
        return value  # int and str fields are static: shapes, loop sizes, choices


def _kind_of(default) -> str:
    if isinstance(default, bool):
        return "bool"
    if isinstance(default, int):
        return "int"
    if isinstance(default, float):
        return "float"
    if isinstance(default, str):
        return "str"
    if isinstance(default, (list, tuple)):
        return "floats"
    raise TypeError(f"param default {default!r}: expected a number, bool, text or a list")


def param(
    default,
    *,
    scale: float = 1.0,
    units: str = "",
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    doc: str = "",
    toml: str = "",
    choices: tuple[str, ...] | None = None,
    length: int | None = None,
    min_length: int = 0,
    kind: str | None = None,
    si_default=None,
    convert=None,
    static: bool = False,
    section: str = "",
    tunable: bool = False,
):
    """A Module field declared with its scenario field (see the module docstring).

    Args:
        default: default in the file's units.
        scale: SI value = file value x scale (floats only).
        units, doc: file units and meaning (``gnc-jax list --fields``, error messages).
        lo, hi, lo_open: allowed range in file units (inclusive, ``lo`` open if ``lo_open``).
        toml: the field's name in the file when it differs from the attribute name (e.g.
            ``delivery_position_km`` for ``delivery_position_m``).
        choices: allowed strings; length, min_length: of a list of numbers.
        kind: "float", "int", "bool", "str" or "floats" (default: from ``default``). Ints and
            strings are static fields (they decide shapes or branches); bools become 0/1 floats.
        si_default: the Module's SI default when the conversion is not a constant factor
            (it depends on other scenario fields; the owner converts in its ``from_config``).
        convert: ``file value -> SI value`` when a single factor would not reproduce the
            arithmetic of the unit conversion exactly (e.g. ``x * 1e3 / 1e6``).
        static: keep a float as a static Python float (a step size that shapes a loop).
        section: the scenario section that holds the field, for a Module whose fields come
            from several sections (:func:`from_scenario`); "" for a law's own table.
        tunable: a gain users tune: a differentiable leaf the system lists among its tunable
            leaves (``AbstractSystem.tunable_names``).
    """
    kind = kind or _kind_of(default)
    if kind == "float":
        default = float(default)
    spec = ParamSpec(
        Field(kind, default, lo, hi, lo_open, length, min_length, choices, units, doc),
        toml,
        scale,
        si_default is not None,
        convert,
        static or kind in ("int", "str"),
        section,
        tunable,
    )
    meta = {_KEY: spec}
    static = spec.static
    si = spec.to_si(default) if si_default is None else jnp.asarray(si_default, jnp.float64)
    if kind == "floats":
        return eqx.field(default_factory=lambda: spec.to_si(default), metadata=meta)
    if static:
        return eqx.field(default=si, metadata=meta, static=True)
    return eqx.field(default_factory=lambda: si, metadata=meta)


def declared_params(cls) -> dict[str, ParamSpec]:
    """``{attribute name: ParamSpec}`` of the fields of ``cls`` declared with :func:`param`."""
    return {f.name: f.metadata[_KEY] for f in dataclasses.fields(cls) if _KEY in (f.metadata or {})}


def file_name(attribute: str, spec: ParamSpec) -> str:
    return spec.toml or attribute


def schema_of(cls, section: str | None = None) -> dict[str, Field]:
    """The scenario fields of ``cls``: ``{file name: Field}`` in declaration order (only those
    of ``section`` when given)."""
    return {
        file_name(a, s): s.field
        for a, s in declared_params(cls).items()
        if section is None or s.section == section
    }


def from_config(cls, section: dict[str, Any], **fixed):
    """``cls(**SI values of section, **fixed)``: build a Module from a validated section.

    ``fixed`` supplies the fields that are not scenario fields (or overrides converted ones).
    """
    kwargs = {
        a: s.to_si(section[file_name(a, s)])
        for a, s in declared_params(cls).items()
        if a not in fixed
    }
    return cls(**kwargs, **fixed)


def from_scenario(cls, config: dict[str, Any], **fixed):
    """``cls`` built from a validated scenario configuration, each declared field read from
    its own ``section`` (:func:`param`); ``fixed`` as in :func:`from_config`."""
    kwargs = {
        a: s.to_si(config[s.section][file_name(a, s)])
        for a, s in declared_params(cls).items()
        if a not in fixed
    }
    return cls(**kwargs, **fixed)


def si_value(cls, attribute: str, value):
    """The SI value of ``value`` (file units) of the declared field ``attribute`` of ``cls``."""
    return declared_params(cls)[attribute].to_si(value)


__all__ = [
    "ParamSpec",
    "param",
    "declared_params",
    "schema_of",
    "from_config",
    "from_scenario",
    "si_value",
]
