"""Rules: which tagged features are restricted, as what, with which margin and altitudes."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from alphafence.errors import InputError

KINDS = ("keep_out", "warning", "keep_in")
GEOMETRIES = ("point", "line", "area")


@dataclass(frozen=True)
class Rule:
    """One rule: the features it matches and what they become.

    Attributes
    ----------
    index : int
        Its place in the file (the first matching rule wins).
    category : str
        E.g. ``"hospital"``; fences are grouped and named by it.
    kind : str
        ``"keep_out"``, ``"warning"`` or ``"keep_in"``.
    tags : tuple
        ``((key, frozenset(values) | None), ...)``; None matches any value.
    margin_m : float
        Metres the fence keeps around the feature.
    geometry : frozenset
        The geometry types it applies to: ``"point"``, ``"line"``, ``"area"``.
    alt_min_m, alt_max_m : float, optional
        The altitude band its fences apply to.
    """

    index: int
    category: str
    kind: str
    tags: tuple  # ((key, frozenset(values) | None), ...); None = any value
    margin_m: float
    geometry: frozenset = frozenset(GEOMETRIES)
    alt_min_m: float | None = None
    alt_max_m: float | None = None

    def matches(self, get, geomtype: str) -> bool:
        """Whether a feature of ``geomtype`` whose tag values ``get(key)`` returns (None when
        absent) has every tag this rule asks for."""
        if geomtype not in self.geometry:
            return False
        for key, values in self.tags:
            value = get(key)
            if value is None or (values is not None and value not in values):
                return False
        return True


@dataclass
class Rules:
    """The rules in force, in order, with the widths given to points and lines.

    Attributes
    ----------
    rules : list of Rule
    point_radius_m : float
        Radius of the disc a point feature stands for.
    line_width_m : float
        Width of the strip a line feature stands for.
    source : str
        ``"default"`` or the file they came from.
    keys : tuple of str
        Every tag key some rule looks at.

    Examples
    --------
    >>> rules = parse_rules({"rule": [{"category": "hospital", "kind": "keep_out",
    ...                                "tags": {"amenity": ["hospital", "clinic"]}}]})
    >>> rules.match({"amenity": "clinic"}.get, "area").category
    'hospital'
    >>> rules.match({"amenity": "school"}.get, "area") is None
    True
    """

    rules: list
    point_radius_m: float = 30.0
    line_width_m: float = 10.0
    source: str = "default"
    keys: tuple = field(init=False)

    def __post_init__(self):
        self.keys = tuple(sorted({k for r in self.rules for k, _ in r.tags}))

    def match(self, get, geomtype: str) -> Rule | None:
        """First rule matching a feature; ``get(key)`` returns a tag value or None."""
        for rule in self.rules:
            if rule.matches(get, geomtype):
                return rule
        return None


def _number(path, where, value, name, minimum=None):
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(path, f"{name} must be a number, not {value!r}", where)
    if minimum is not None and value < minimum:
        raise InputError(path, f"{name} must be >= {minimum}, not {value}", where)
    return float(value)


def parse_rules(doc: dict, path="rules") -> Rules:
    """Rules from a parsed TOML document (``[[rule]]`` entries and ``[defaults]``).

    Parameters
    ----------
    doc : dict
        The parsed TOML.
    path : str or Path
        Where it came from, for messages and ``Rules.source``.

    Returns
    -------
    Rules

    Raises
    ------
    InputError
        A one-line message naming the rule that is wrong.
    """
    defaults = doc.get("defaults", {})
    raw = doc.get("rule")
    if not isinstance(raw, list) or not raw:
        raise InputError(path, "no [[rule]] entries")
    rules = []
    for i, entry in enumerate(raw):
        where = f"rule {i + 1}"
        if not isinstance(entry, dict):
            raise InputError(path, "must be a table", where)
        unknown = set(entry) - {
            "category",
            "kind",
            "tags",
            "margin_m",
            "geometry",
            "alt_min_m",
            "alt_max_m",
        }
        if unknown:
            raise InputError(path, f"unknown field(s) {', '.join(sorted(unknown))}", where)
        category = entry.get("category")
        if not isinstance(category, str) or not category:
            raise InputError(path, "needs a category name", where)
        where = f"rule {i + 1} ({category})"
        kind = entry.get("kind")
        if kind not in KINDS:
            raise InputError(path, f"kind must be one of {', '.join(KINDS)}, not {kind!r}", where)
        tags = entry.get("tags")
        if not isinstance(tags, dict) or not tags:
            raise InputError(path, 'needs tags = { key = [values] | "*" }', where)
        parsed = []
        for key, values in tags.items():
            if values == "*":
                parsed.append((key, None))
            elif isinstance(values, str):
                parsed.append((key, frozenset([values])))
            elif isinstance(values, list) and values and all(isinstance(v, str) for v in values):
                parsed.append((key, frozenset(values)))
            else:
                raise InputError(path, f'tag {key!r} needs a list of strings or "*"', where)
        geometry = entry.get("geometry", list(GEOMETRIES))
        if not isinstance(geometry, list) or not set(geometry) <= set(GEOMETRIES) or not geometry:
            raise InputError(path, f"geometry must list some of {', '.join(GEOMETRIES)}", where)
        margin = _number(path, where, entry.get("margin_m", 0.0), "margin_m", minimum=0.0)
        alt_min = _number(path, where, entry.get("alt_min_m"), "alt_min_m")
        alt_max = _number(path, where, entry.get("alt_max_m"), "alt_max_m")
        if alt_min is not None and alt_max is not None and alt_max <= alt_min:
            raise InputError(path, "alt_max_m must be above alt_min_m", where)
        rules.append(
            Rule(i, category, kind, tuple(parsed), margin, frozenset(geometry), alt_min, alt_max)
        )
    point_radius = _number(
        path, "[defaults]", defaults.get("point_radius_m", 30.0), "point_radius_m", 0.1
    )
    line_width = _number(
        path, "[defaults]", defaults.get("line_width_m", 10.0), "line_width_m", 0.1
    )
    return Rules(rules, point_radius, line_width, str(path))


def load_rules(path: str | Path | None = None) -> Rules:
    """The shipped default rules, or a user's TOML file.

    Raises
    ------
    InputError
        The file cannot be read, is not UTF-8 or TOML, or a rule is wrong.

    Examples
    --------
    >>> load_rules().source
    'default'
    """
    if path is None:
        text = resources.files("alphafence").joinpath("data/rules.toml").read_text(encoding="utf-8")
        source = "default"
    else:
        try:
            text = Path(path).read_text(encoding="utf-8")
        except OSError as exc:
            raise InputError(path, f"cannot read rules: {exc.strerror}") from None
        except UnicodeDecodeError as exc:
            raise InputError(path, f"not UTF-8 text (byte {exc.start})") from None
        source = str(path)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(source, f"invalid TOML: {exc}") from None
    return parse_rules(doc, source)
