"""Load scenarios: packaged TOML files by name, or a user's TOML file by path."""

import copy
import dataclasses
import importlib.resources
import pathlib
import tomllib
from typing import Any

import tomli_w

from ..schema import ScenarioError, parse_override
from ..systems.base import get_system

_META_FIELDS = {"name", "kind", "description", "reference", "runs", "seed"}
MAX_RUNS = 10**9
"""Largest run count a scenario may name (the cost estimate refuses long studies anyway)."""


@dataclasses.dataclass(frozen=True)
class Scenario:
    """A validated scenario.

    Attributes:
        name: scenario name; kind: which simulator runs it (``impactor``, ...).
        description, reference: what it is and which paper/table it reproduces.
        runs: the paper's number of Monte Carlo runs (what ``reproduce`` uses).
        seed: default root seed.
        config: ``{section: {field: value}}`` with every field of the kind's schema.
        paper: the published results to compare with (``{metric: value}``).
        source: where it was loaded from.
    """

    name: str
    kind: str
    description: str
    reference: str
    runs: int
    seed: int
    config: dict
    paper: dict
    source: str

    def __getitem__(self, dotted: str) -> Any:
        """``scenario["guidance.los.k1"]``: a field by its dotted name."""
        value: Any = self.config
        for part in dotted.split("."):
            value = value[part]
        return value

    @property
    def system(self):
        """The registered system (:class:`~gnc_jax.systems.AbstractSystem`) of this kind."""
        return get_system(self.kind)

    def with_overrides(self, overrides) -> "Scenario":
        """A copy with ``section.field=value`` overrides applied: a list of such strings (or
        ``(section.field, value)`` pairs) or a mapping ``{section.field: value}``."""
        if isinstance(overrides, (str, bytes)):
            raise ScenarioError(
                f"overrides: the single string {overrides!r}; allowed: a list of "
                "section.field=value strings (e.g. ['guidance.los.k1=3']) or a mapping "
                "{section.field: value}"
            )
        raw = copy.deepcopy(self.config)
        items = overrides.items() if isinstance(overrides, dict) else overrides
        for item in items:
            if isinstance(item, str):
                section, field, value = parse_override(item)
            else:
                if not isinstance(item, (tuple, list)) or len(item) != 2:
                    raise ScenarioError(
                        f"overrides: {item!r}; allowed: section.field=value strings or "
                        "(section.field, value) pairs"
                    )
                key, value = item
                if not isinstance(key, str) or key.count(".") not in (1, 2):
                    raise ScenarioError(
                        f"{key}: the key must be section.field or section.table.field"
                    )
                section, field = key.rsplit(".", 1)
            table = raw
            for part in section.split("."):
                table = table.setdefault(part, {})
                if not isinstance(table, dict):
                    raise ScenarioError(f"{section}.{field}: {section} is not a table")
            table[field] = value
        return _build(self._meta(), raw, self.paper, self.source)

    def _meta(self) -> dict:
        return dict(
            name=self.name,
            kind=self.kind,
            description=self.description,
            reference=self.reference,
            runs=self.runs,
            seed=self.seed,
        )

    def to_dict(self) -> dict:
        return {"scenario": self._meta(), **self.config, "paper": dict(self.paper)}

    def to_toml(self) -> str:
        return tomli_w.dumps(self.to_dict())


def _build(meta: dict, raw: dict, paper: dict, source: str) -> Scenario:
    unknown = set(meta) - _META_FIELDS
    if unknown:
        raise ScenarioError(
            f"scenario.{sorted(unknown)[0]}: unknown field; "
            f"allowed: {', '.join(sorted(_META_FIELDS))}"
        )
    kind = meta.get("kind")
    system = get_system(kind) if isinstance(kind, str) else get_system(repr(kind))
    runs = meta.get("runs", 100)
    if isinstance(runs, bool) or not isinstance(runs, int) or not 0 < runs <= MAX_RUNS:
        raise ScenarioError(f"scenario.runs: {runs!r}; allowed: an integer in [1, {MAX_RUNS:g}]")
    seed = meta.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise ScenarioError(f"scenario.seed: {seed!r}; allowed: an integer in [0, 2^32)")
    for k, v in paper.items():
        if isinstance(v, bool) or not isinstance(v, (int, float, str)):
            raise ScenarioError(f"paper.{k}: expected a number or text, got {v!r}")
    config = system.validate(raw)
    return Scenario(
        name=str(meta.get("name", "unnamed")),
        kind=kind,
        description=str(meta.get("description", "")),
        reference=str(meta.get("reference", "")),
        runs=runs,
        seed=seed,
        config=config,
        paper=dict(paper),
        source=source,
    )


def _files():
    return importlib.resources.files("gnc_jax.scenario") / "files"


def packaged_names() -> list[str]:
    return sorted(p.name[:-5] for p in _files().iterdir() if p.name.endswith(".toml"))


def load_scenario(name_or_path: str | pathlib.Path, overrides=()) -> Scenario:
    """Load a packaged scenario by name (``gnc-jax list``) or a TOML file by path.

    Args:
        name_or_path: e.g. ``"deep-impact-los"`` or ``"my_case.toml"``.
        overrides: ``["guidance.k1=3", ...]`` or ``{"guidance.k1": 3}`` (a single string is
            refused: it is not a list of overrides).

    Raises:
        ScenarioError: unknown scenario, unknown field, wrong type or out-of-range value.
    """
    text = str(name_or_path)
    path = pathlib.Path(text)
    if text.endswith(".toml") or path.exists():
        if not path.is_file():
            raise ScenarioError(
                f"scenario: no such file {text!r}; allowed: a packaged name "
                f"({', '.join(packaged_names())}) or an existing .toml file"
            )
        try:
            data, source = path.read_bytes(), str(path)
        except OSError as e:
            raise ScenarioError(
                f"scenario: cannot read {text!r} ({e.strerror or e}); allowed: a readable "
                ".toml file"
            ) from None
    else:
        if text not in packaged_names():
            raise ScenarioError(
                f"scenario: unknown scenario {text!r}; allowed: {', '.join(packaged_names())} "
                "or a path to a .toml file"
            )
        data, source = (_files() / f"{text}.toml").read_bytes(), f"packaged:{text}"
    try:
        raw = tomllib.loads(data.decode())
    except UnicodeDecodeError as e:
        raise ScenarioError(
            f"scenario {source}: not UTF-8 text (byte {e.start}: {e.reason}); allowed: a TOML "
            "file encoded in UTF-8"
        ) from None
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"scenario {source}: not valid TOML ({e})") from None
    meta = raw.pop("scenario", {})
    paper = raw.pop("paper", {})
    for table, value in (("scenario", meta), ("paper", paper)):
        if not isinstance(value, dict):
            raise ScenarioError(
                f"{table}: expected a table [{table}], got {value!r}; allowed: a [{table}] "
                "table of fields"
            )
    scenario = _build(meta, raw, paper, source)
    return scenario.with_overrides(overrides) if overrides else scenario


def list_scenarios() -> list[Scenario]:
    """Every packaged scenario."""
    return [load_scenario(n) for n in packaged_names()]
