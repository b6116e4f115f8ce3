"""Fences' vertical references: which limits are AMSL, which above the ground, and where a
fence keeps them (on the fence itself, or in its ED-269 ``zone``)."""

from __future__ import annotations

# references compared with the altitude AMSL, and what each comparison approximates
AMSL_REFERENCES = {"AMSL": "", "MSL": "", "ALT": ""}
AMSL_REFERENCES.update(
    WGS84="heights above the WGS84 ellipsoid compared with the altitude AMSL (the geoid's "
    "separation, up to 100 m, not applied)",
    STD="flight levels compared with the altitude AMSL (no pressure altitude)",
)
GROUND_REFERENCES = ("AGL", "SFC", "GND", "ASFC")  # limits above the ground below


def reference(record, which: str):
    """A fence's vertical reference for its ``"lower"`` or ``"upper"`` limit, upper case, or
    None: kept on the fence itself (KML, OpenAir) or in its ED-269 ``zone``.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.fencefiles.fence_geojson import FenceRecord
    >>> r = FenceRecord("z", "keep_out", shapely.box(0, 0, 1, 1), properties={"zone": {
    ...     "lower_reference": "agl", "upper_reference": "AMSL"}})
    >>> reference(r, "lower"), reference(r, "upper"), reference(FenceRecord("y", "keep_out",
    ...     shapely.box(0, 0, 1, 1)), "upper")
    ('AGL', 'AMSL', None)
    """
    props = record.properties or {}
    ref = props.get(f"{which}_reference") or (props.get("zone") or {}).get(f"{which}_reference")
    return str(ref).upper() if ref else None
