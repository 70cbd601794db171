"""Typed, range-checked scenario fields.

A scenario kind declares its fields once (name, type, default, allowed range, units, meaning);
loading a TOML file or applying ``--set`` overrides validates against that declaration before
anything is compiled, and every error is one line naming the field and what is allowed.
"""

import dataclasses
import datetime
import math
import tomllib
from typing import Any


class ScenarioError(ValueError):
    """Invalid scenario input. The message is one line naming the field and the allowed values."""


@dataclasses.dataclass(frozen=True)
class Field:
    """Declaration of one scenario field.

    Attributes:
        kind: "float", "int", "bool", "str" or "floats" (a list of floats).
        default: value used when the file does not set the field.
        lo, hi: inclusive bounds for numbers (and for every element of "floats").
        lo_open: the lower bound itself is excluded (e.g. a mass must be > 0).
        length: required length of a "floats" list (None: any length >= min_length).
        choices: allowed strings for "str".
        units, doc: shown by ``gnc-jax list --fields`` and in error messages.
    """

    kind: str
    default: Any
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    length: int | None = None
    min_length: int = 0
    choices: tuple[str, ...] | None = None
    units: str = ""
    doc: str = ""

    def allowed(self) -> str:
        if self.kind == "bool":
            return "true or false"
        if self.kind == "str":
            if not self.choices:
                return "text" + (f" ({self.doc})" if self.doc else "")
            return "one of " + ", ".join(repr(c) for c in self.choices)
        # An unbounded end is open: every number is finite (``check`` refuses inf and nan).
        lo = "(-inf" if self.lo is None else f"{'(' if self.lo_open else '['}{self.lo:g}"
        hi = "inf)" if self.hi is None else f"{self.hi:g}]"
        rng = f"{lo}, {hi}"
        unit = f" {self.units}" if self.units else ""
        if self.kind == "floats":
            n = _numbers(self.length) if self.length else "a list of numbers"
            return f"{n}, each in {rng}{unit}"
        return f"{'an integer' if self.kind == 'int' else 'a number'} in {rng}{unit}"

    def check(self, name: str, value: Any) -> Any:
        """Return the validated (and normalised) value or raise :class:`ScenarioError`."""

        def fail(why: str):
            raise ScenarioError(f"{name}: {why}; allowed: {self.allowed()}")

        def number(v, integer: bool):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                fail(f"expected {'an integer' if integer else 'a number'}, got {v!r}")
            if integer and not isinstance(v, int):
                fail(f"expected an integer, got {v!r}")
            if not math.isfinite(v):
                fail(f"got {v!r}")
            too_low = self.lo is not None and (v <= self.lo if self.lo_open else v < self.lo)
            if too_low or (self.hi is not None and v > self.hi):
                fail(f"{v!r} is out of range")
            return int(v) if integer else float(v)

        if self.kind == "float":
            return number(value, False)
        if self.kind == "int":
            return number(value, True)
        if self.kind == "bool":
            if not isinstance(value, bool):
                fail(f"expected true or false, got {value!r}")
            return value
        if self.kind == "str":
            if isinstance(value, (datetime.date, datetime.time)):
                value = value.isoformat()  # an unquoted TOML date in a text field
            if not isinstance(value, str) or (self.choices and value not in self.choices):
                fail(f"got {value!r}")
            return value
        if self.kind == "floats":
            if not isinstance(value, (list, tuple)):
                fail(f"expected a list, got {value!r}")
            if self.length is not None and len(value) != self.length:
                fail(f"expected {_numbers(self.length)}, got {len(value)}")
            if len(value) < self.min_length:
                fail(f"expected at least {_numbers(self.min_length)}, got {len(value)}")
            return [number(v, False) for v in value]
        raise AssertionError(self.kind)


def _numbers(n: int) -> str:
    return f"{n} number" + ("" if n == 1 else "s")


Schema = dict[str, dict[str, Field]]  # section -> field name -> Field
"""A section name may be dotted, ``"guidance.los"``: a sub-table ``[guidance.los]`` of the file."""


def _lookup(config: dict, section: str) -> Any:
    value: Any = config
    for part in section.split("."):
        value = value.get(part, {}) if isinstance(value, dict) else {}
    return value


def _moved_hint(schema: Schema, section: str, name: str) -> str:
    """Where a field now lives when a sub-table of ``section`` declares it (old flat keys)."""
    homes = [s for s, fields in schema.items() if s.startswith(section + ".") and name in fields]
    if not homes:
        return ""
    return f"; it moved to [{homes[0]}]; allowed: {homes[0]}.{name}"


def validate(config: dict, schema: Schema, where: str = "", optional=frozenset()) -> dict:
    """Fill defaults and check every field of ``config`` against ``schema``.

    Sections named in ``optional`` (e.g. the sub-tables of the laws a scenario does not fly) are
    checked and kept when the file gives them and left out otherwise; every other section is
    filled with its defaults. Returns a new nested dict ``{section: {field: value}}`` (dotted
    sections nested: ``out["guidance"]["los"]``).
    """
    tops = {s.split(".")[0] for s in schema}
    for section, value in config.items():
        if section not in tops:
            raise ScenarioError(
                f"{where}{section}: unknown section; allowed: {', '.join(sorted(tops))}"
            )
        if not isinstance(value, dict):
            raise ScenarioError(f"{where}{section}: expected a table of fields, got {value!r}")
        for name, item in value.items():
            if f"{section}.{name}" in schema:
                if not isinstance(item, dict):
                    raise ScenarioError(
                        f"{where}{section}.{name}: expected a table [{section}.{name}], "
                        f"got {item!r}"
                    )
                for sub in item:
                    if sub not in schema[f"{section}.{name}"]:
                        raise ScenarioError(
                            f"{where}{section}.{name}.{sub}: unknown field; allowed in "
                            f"[{section}.{name}]: " + ", ".join(schema[f"{section}.{name}"])
                        )
            elif name not in schema.get(section, {}):
                subs = sorted(s for s in schema if s.startswith(section + "."))
                extra = f"; sub-tables: {', '.join(f'[{s}]' for s in subs)}" if subs else ""
                raise ScenarioError(
                    f"{where}{section}.{name}: unknown field"
                    + (
                        _moved_hint(schema, section, name)
                        or f"; allowed in [{section}]: "
                        + ", ".join(sorted(schema.get(section, {})))
                        + extra
                    )
                )
    out: dict[str, dict[str, Any]] = {}
    for section, fields in schema.items():
        given = _lookup(config, section)
        if section in optional and not given:
            continue
        checked = {
            name: field.check(f"{where}{section}.{name}", given.get(name, field.default))
            for name, field in fields.items()
        }
        head, _, sub = section.partition(".")
        if sub:
            out.setdefault(head, {})[sub] = checked
        else:
            out.setdefault(head, {}).update(checked)
    return out


def parse_override(text: str) -> tuple[str, str, Any]:
    """Parse ``section[.table].field=value`` into ``(section, field, value)`` (value in TOML
    syntax; a bare word is a string); ``section`` may be dotted (``guidance.los``)."""

    if "=" not in text:
        raise ScenarioError(f"--set {text}: expected section.field=value")
    key, raw = text.split("=", 1)
    key = key.strip()
    if key.count(".") not in (1, 2) or not all(key.split(".")):
        raise ScenarioError(
            f"--set {text}: the key must be section.field or section.table.field, "
            "e.g. guidance.los.k1=4"
        )
    section, name = key.rsplit(".", 1)
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return section, name, value
