"""Zone volumes read as the fences they are (no rules, no margin): KML and KMZ placemarks and
OpenAir airspaces given where a fence file is expected (``upload``, ``monitor``, ``compile``).
The zone readers (:mod:`alphafence.zones.kml`, :mod:`alphafence.zones.openair`) give the
volumes; this makes them :class:`~alphafence.fencefiles.fence_geojson.FenceRecord` lists."""

from __future__ import annotations

import numpy as np

from alphafence.errors import InputError
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.zones import kml, openair
from alphafence.zones.airspace import held_reading, polygonal
from alphafence.zones.features import check_coordinates, make_valid_polygonal

FENCE_KINDS = ("keep_out", "keep_in", "warning")


def read_kml_fences(path):
    """The placemarks of a KML or KMZ file as fences: keep-out unless ExtendedData
    ``alphafence:kind`` says ``keep_in`` or ``warning``; bands and long edges as the zone
    reader reads them.

    Returns
    -------
    list of FenceRecord
    """
    volumes, readings = kml.read_volumes(path)
    return fences_from_volumes(path, volumes, "kml", readings)


def read_openair_fences(path, notes=None):
    """The airspaces of an OpenAir file as keep-out fences (their bands kept, widened where
    a limit has no numeric meaning; ``notes`` collects what was widened).

    Returns
    -------
    list of FenceRecord
    """
    return fences_from_volumes(path, openair.read_volumes(path, notes=notes), "openair")


def fences_from_volumes(path, volumes, what, readings=None):
    """The volumes as fences read as they are (no rules, no margin): ``keep_out`` unless a
    volume's ``alphafence:kind`` tag says ``keep_in`` or ``warning``.

    Parameters
    ----------
    path : str or Path
    volumes : list of tuple
        As for :func:`~alphafence.zones.airspace.features_from_volumes`; points need a ``circle`` property.
    what : str
        The format, for messages and site ids (``"kml"``).
    readings : list, optional
        As for :func:`~alphafence.zones.airspace.features_from_volumes`.

    Returns
    -------
    list of FenceRecord
        ``site_id`` ``"<what>/<source>"``; invalid polygons made valid (all their area kept).

    Raises
    ------
    InputError
        A point without a radius, a line, a coordinate out of range, naming the volume; a
        keep-in zone whose readings share no area.
    """
    if not volumes:
        raise InputError(path, f"no fences in this {what} file")
    geoms = np.array([v[0] for v in volumes], dtype=object)
    check_coordinates(path, geoms, lambda k: f"{what} {volumes[k][2]}")
    geoms = make_valid_polygonal(geoms)
    out = []
    for k, (g, (_, tags, source, lower, upper, props)) in enumerate(zip(geoms, volumes)):
        label = f"{source} ({tags['name']})" if tags.get("name") else source
        g = polygonal(g)
        if g is None:
            raise InputError(
                path, "a fence must be an area (a polygon, or a point with a radius)", label
            )
        kind = tags.get("alphafence:kind", "keep_out")
        if kind not in FENCE_KINDS:
            raise InputError(
                path,
                f"alphafence:kind must be one of {', '.join(FENCE_KINDS)}, not {kind!r}",
                label,
            )
        g = held_reading(path, g, readings, k, kind, label)
        circle = tuple(props["circle"]) if "circle" in props else None
        name = tags.get("name")
        fprops = {
            "site_id": f"airspace/{source}",
            "kind": kind,
            "name": name,
            "category": "airspace",
            "alt_min_m": lower,
            "alt_max_m": upper,
            **{k: v for k, v in props.items() if k != "circle"},
        }
        if circle is not None:
            fprops.update(center=[circle[0], circle[1]], radius_m=circle[2])
        out.append(
            FenceRecord(
                fprops["site_id"], kind, g, 0.0, name, "airspace", lower, upper, circle, fprops
            )
        )
    return out
