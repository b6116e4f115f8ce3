"""OpenAir altitude limits (``AL`` floors, ``AH`` ceilings) as gliding tools write them.

A limit is a number with an optional unit (``FT``, ``F``, ``M``, ``MTR``...; feet when none)
and an optional reference (``AMSL``, ``MSL``, ``ALT``: above sea level, the default; ``AGL``,
``GND``, ``SFC``, ``ASFC``: above the ground; ``STD``: pressure altitude), spaces anywhere
and the unit and reference in either order (``2900AMSL FT``, ``2900 FT AMSL``, ``2900ft MSL``,
``1500 AGL``); or a flight level (``FL65``, ``FL 65``); or a word: the ground (``SFC``,
``GND``), sea level (``MSL``) or unlimited (``UNL``, ``UNLTD``..., a unit word after it
allowed: ``UNL FT``). Anything after ``*`` is a comment.

Words without a numeric meaning (``NOTAM``: the limit is published by NOTAM; a class name
such as ``BCTA FT``; anything else) are :class:`Unreadable`; the reader decides what to do
with them (:mod:`alphafence.zones.openair` widens a keep-out's band).
"""

from __future__ import annotations

import math
import re

from alphafence.errors import InputError

FT = 0.3048
_NUMBER = r"[0-9]+(?:\.[0-9]+)?|\.[0-9]+"
_TOKEN = re.compile(rf"[A-Z]+|{_NUMBER}|\S")
_IS_NUMBER = re.compile(_NUMBER)
_FEET = {"FT", "F", "FEET", "FOOT"}
_METRES = {"M", "MTR", "MTRS", "METER", "METERS", "METRE", "METRES"}
_REFERENCE = {"AGL": "AGL", "GND": "AGL", "SFC": "AGL", "ASFC": "AGL", "AGND": "AGL"}
_REFERENCE.update({"GROUND": "AGL", "AMSL": "AMSL", "MSL": "AMSL", "ASL": "AMSL"})
_REFERENCE.update({"ALT": "AMSL", "STD": "STD"})
_GROUND = {"SFC", "GND", "GROUND", "AGL", "ASFC"}
_SEA = {"MSL", "AMSL", "ASL"}
_UNLIMITED = {"UNL", "UNLIM", "UNLIMITED", "UNLTD"}


class Unreadable(ValueError):
    """A limit with no numeric meaning; ``str(err)`` says why (``"the limit is set by
    NOTAM"``)."""


def read_altitude(text: str):
    """An OpenAir limit -> ``(metres or None, reference)``: None for unlimited, the reference
    ``"AGL"``, ``"AMSL"`` or ``"STD"`` (flight levels, pressure altitude).

    Parameters
    ----------
    text : str
        The ``AL`` or ``AH`` record's argument.

    Raises
    ------
    Unreadable
        The text names no altitude (``NOTAM``, ``BCTA FT``, ``-5m``, two numbers).

    Examples
    --------
    >>> read_altitude("2900AMSL FT"), read_altitude("1500 AGL"), read_altitude("FL 65")
    ((883.92, 'AMSL'), (457.2, 'AGL'), (1981.2, 'STD'))
    >>> read_altitude("UNL FT"), read_altitude("GND"), read_altitude("600 m MSL")
    ((None, 'AMSL'), (0.0, 'AGL'), (600.0, 'AMSL'))
    >>> read_altitude("NOTAM")
    Traceback (most recent call last):
    ...
    alphafence.zones.openair_alt.Unreadable: the limit is set by NOTAM
    """
    tokens = _TOKEN.findall(text.split("*")[0].upper())
    if any("NOTAM" in t for t in tokens):
        raise Unreadable("the limit is set by NOTAM")
    numbers = [t for t in tokens if _IS_NUMBER.fullmatch(t)]
    words = [t for t in tokens if t not in numbers]
    units = [w for w in words if w in _FEET or w in _METRES]
    refs = [w for w in words if w in _REFERENCE]
    others = [w for w in words if w not in units and w not in refs]
    if not numbers:
        if len(others) == 1 and others[0] in _UNLIMITED and not refs and len(units) <= 1:
            return None, "AMSL"
        if not others and len(refs) == 1 and len(units) <= 1:
            if refs[0] in _GROUND:
                return 0.0, "AGL"
            if refs[0] in _SEA:
                return 0.0, "AMSL"
        raise Unreadable("it names no altitude")
    if len(numbers) > 1 or len(units) > 1 or len(refs) > 1:
        raise Unreadable("it names more than one altitude, unit or reference")
    value = float(numbers[0])
    if not math.isfinite(value):
        raise Unreadable("the number is out of range")
    if others == ["FL"] and not units and refs in ([], ["STD"]) and tokens[0] == "FL":
        return round(value * 100 * FT, 3), "STD"
    if others or tokens[0] != numbers[0]:
        raise Unreadable("it names no altitude")
    unit = 1.0 if units and units[0] in _METRES else FT
    return round(value * unit, 3), _REFERENCE[refs[0]] if refs else "AMSL"


def parse_altitude(path, where, text):
    """:func:`read_altitude`, an unreadable limit raised as an :class:`InputError`.

    Examples
    --------
    >>> parse_altitude("f", "AL", "SFC"), parse_altitude("f", "AH", "FL65")
    ((0.0, 'AGL'), (1981.2, 'STD'))
    """
    try:
        return read_altitude(text)
    except Unreadable as exc:
        raise InputError(path, f"cannot read the altitude {text.strip()!r}: {exc}", where) from None
