"""A compiled or read fence checked against the rules of the autopilot that will hold it.

- Any autopilot: a fence with no polygon or circle is refused (:func:`require_fence`):
  uploaded, it would leave the vehicle without a fence.
- PX4 (``navigator/geofence.cpp``) reads several inclusions as their intersection, always,
  and keeps no return point (:func:`check_for_autopilot`). When the fence loads, it discards,
  one by one and without refusing the upload, every area that home breaches: an inclusion
  that does not hold home, an exclusion that does (``checkHomeRequirementsForGeofence``;
  "Geofence invalid, doesn't contain Home position" in its log). In the air, with a
  ``GF_ACTION``, it also discards an area the vehicle's own position breaches. The vehicle
  then flies without that area while the uploader believes it holds it:
  :func:`areas_breached_at` finds them before anything is sent.
"""

from __future__ import annotations

from alphafence.errors import InputError
from alphafence.mavlink.autopilots import NAMES, inclusion_union_possible, keeps_return_point
from alphafence.mavlink.inclusions import inclusion_count
from alphafence.mavlink.items import RETURN_POINT


def require_fence(result, path, where) -> None:
    """Refuse a compilation that holds no polygon or circle, as an onboard file without one
    is refused: uploaded, it would leave the vehicle without a fence.

    Parameters
    ----------
    result : alphafence.onboard.compile.CompileResult
    path : str or Path
        The fence file compiled, for the message.
    where : str
        The area compiled for (``"the box 7.41,43.72,7.44,43.75"``), for the message.

    Raises
    ------
    InputError
        ``f.geojson: no keep-out or keep-in fence within 2000 m of the box ...: the onboard
        fence would hold no polygon or circle, leaving the vehicle without a fence``.
    """
    from alphafence.onboard.decode import decode_fence

    if decode_fence(result.items, source=str(path)):
        return
    reach = result.corridor.distance_m if result.corridor is not None else 0.0
    raise InputError(
        path,
        f"no keep-out or keep-in fence within {reach:g} m of {where}: the onboard fence would "
        "hold no polygon or circle, leaving the vehicle without a fence",
    )


def check_for_autopilot(items, autopilot: str, source: str = "compile") -> None:
    """Refuse fence items the autopilot would not read as meant.

    Parameters
    ----------
    items : list of FenceItem
    autopilot : str
        ``"ardupilot"`` or ``"px4"``.
    source : str
        The file or step, for the message.

    Raises
    ------
    InputError
        For PX4: a return point (it keeps none), or two or more inclusions (it reads them as
        their intersection: the vehicle must stay inside all of them).

    Examples
    --------
    >>> from alphafence.mavlink.items import FenceItem
    >>> two = [FenceItem(5003, 50.0, 0, 0), FenceItem(5003, 50.0, 1, 1)]
    >>> check_for_autopilot(two, "ardupilot")
    >>> check_for_autopilot(two, "px4")
    Traceback (most recent call last):
    ...
    alphafence.errors.InputError: compile: 2 inclusion areas: PX4 reads them as their intersection (the vehicle must stay inside all of them); keep one keep-in area for PX4 (drop --keep-in, or the keep-in fences, or narrow the area)
    """
    name = NAMES.get(autopilot, autopilot)
    if not keeps_return_point(autopilot) and any(i.command == RETURN_POINT for i in items):
        raise InputError(
            source, f"a fence return point: {name} keeps none (leave out --return-point)"
        )
    n = inclusion_count(items)
    if n > 1 and not inclusion_union_possible(autopilot):
        raise InputError(
            source,
            f"{n} inclusion areas: {name} reads them as their intersection (the vehicle must "
            f"stay inside all of them); keep one keep-in area for {name} (drop --keep-in, or "
            "the keep-in fences, or narrow the area)",
        )


HOME_SLACK_DEG = 2e-7  # a polygon's edge this near home (degrees) counts as breached by it
HOME_SLACK_M = 0.05  # and a circle's rim this near (metres)


def areas_breached_at(items, lon: float, lat: float) -> list:
    """The areas of a fence that a position breaches, as PX4 reads each one alone, or comes
    within a reading's error of breaching: the inclusions it lies outside, the exclusions it
    lies inside. PX4 discards these when the fence loads with home there.

    A polygon is read as PX4 reads it (straight lat/lon edges, the position moved by
    :data:`HOME_SLACK_DEG` each way); a circle by PX4's projected distance, the projection's
    reference anywhere within :data:`~alphafence.geo.vehicle_distance.PX4_REACH_M`.

    Parameters
    ----------
    items : list of FenceItem
    lon, lat : float
        Home (or the vehicle's position), degrees.

    Returns
    -------
    list of OnboardFence
        Each such area, as :func:`~alphafence.onboard.decode.decode_fence` reads it.

    Examples
    --------
    >>> from alphafence.mavlink.items import FenceItem
    >>> keep_in = FenceItem(5003, 500.0, 14.5, 35.9)
    >>> keep_out = FenceItem(5004, 100.0, 14.51, 35.9)
    >>> [a.name for a in areas_breached_at([keep_in, keep_out], 14.5, 35.9)]
    []
    >>> [a.name for a in areas_breached_at([keep_in, keep_out], 14.51, 35.9)]
    ['onboard inclusion circle 1 (item 0)', 'onboard exclusion circle 1 (item 1)']
    """
    import numpy as np

    from alphafence.geo.vehicle_distance import great_circle_m, polygon_outside, px4_stretch
    from alphafence.onboard.decode import decode_fence

    s = HOME_SLACK_DEG
    plon = lon + np.array([0.0, s, -s, 0.0, 0.0])
    plat = lat + np.array([0.0, 0.0, 0.0, s, -s])
    out = []
    for f in decode_fence(items):
        if f.shape == "circle":
            d = float(great_circle_m(lon, lat, *f.lonlat[0]))
            if f.inclusion:  # PX4's distance is d to d * stretch: outside once that reaches r
                hit = d * px4_stretch() >= f.radius_m - HOME_SLACK_M
            else:
                hit = d < f.radius_m + HOME_SLACK_M
        else:
            ring = np.asarray(f.lonlat, float)
            outside = polygon_outside(plon, plat, ring[:, 0], ring[:, 1])
            hit = bool(outside.any()) if f.inclusion else not bool(outside.all())
        if hit:
            out.append(f)
    return out


def check_items(path, items, profile, max_items=None):
    """Check fence items read from a file as ArduPilot's loader checks them and against the
    storage they are for, as a compilation fits its items to it.

    Parameters
    ----------
    path : str
        The file, for messages.
    items : list of FenceItem
    profile : Profile
        The vehicle's fence storage.
    max_items : int, optional
        ``--items``: at most this many.

    Returns
    -------
    list of OnboardFence
        The polygons and circles the items make.

    Raises
    ------
    InputError
        One line: an item ArduPilot refuses, no polygon or circle at all (the upload would
        leave the vehicle without a fence), or more items or bytes than the storage holds.
    """
    from alphafence.mavlink.storage import storage_bytes
    from alphafence.onboard.decode import decode_fence

    fences = decode_fence(items, source=path)
    if not fences:
        raise InputError(
            path, "no polygon or circle: uploading it would leave the vehicle without a fence"
        )
    used = storage_bytes(items)
    if max_items is not None and len(items) > max_items:
        raise InputError(
            path, f"{len(items)} fence items: --items allows at most {max_items} items"
        )
    if len(items) > profile.items or used > profile.bytes:
        raise InputError(
            path,
            f"{len(items)} fence items, {used} bytes: the {profile.name} profile holds "
            f"{profile.items} items and {profile.bytes} bytes (choose its --profile, or compile "
            "the fences for it)",
        )
    return fences
