"""How long a full check holds: the positions a vehicle can reach before it could matter.

After a full check that found the vehicle CLEAR, the monitor knows its room
(:class:`~alphafence.awareness.clearance.Clearance`): how far it can move before any fence's
inside or outside changes, and how far the nearest keep-out is. A vehicle reporting speed
``v0`` whose acceleration is at most ``A`` covers at most ``v0 t + A t^2 / 2`` in ``t``
seconds, and its speed stays under ``v0 + A t``, so the full check's answer, CLEAR, holds
until the time :func:`due_s` at which that reach (with the error of reading it, below) could
eat into the room the check needs: the look-ahead at the higher speed, the stopping margin.
Until then a new position costs :meth:`Reach.holds`: a few multiplications, no projection, no
fence.

The bound on acceleration only says *when* the next full check comes; it is not what the
answer rests on. Every position is still compared with what the bound allows, from the
vehicle's own report: its displacement from the checked position (in the fences' frame, by
the frame's derivative there: :meth:`~alphafence.geo.frame.LocalFrame.jacobian`), its speed,
its altitude where an altitude band could change, its step from the previous position (a GPS
glitch), the time since the previous position. Any of them beyond the bound sends the position
to the full check. So a vehicle that accelerates harder than ``A`` (a gust, a wrong
parameter) is checked in full; it is never missed.

Reading a displacement by the frame's derivative at the checked position errs by at most
:data:`READ_ERROR` of the displacement (times ``1 + tan |lat|``) plus :data:`READ_SLACK_M`
within :data:`REACH_MAX_M` (``tests/test_monitor_reach.py`` proves it on random frames and
latitudes); both are taken off the room. Past :data:`LAT_MAX` degrees every position is
checked in full.
"""

from __future__ import annotations

import math

DEFAULT_ACCEL_MPS2 = 10.0  # about g: a copter at a 45 degree lean, a plane in a 45 degree bank
SPEED_SLACK_MPS = 1.0  # telemetry noise on the reported speed
POSITION_SLACK_M = 3.0  # GPS noise on a position: beyond the kinematic reach by this is a jump
REACH_MAX_M = 5000.0  # a full check at least every this many metres of reach
DUE_MAX_S = 60.0  # and at least this often
READ_ERROR = 0.5 / 6_371_000.0 * REACH_MAX_M  # of the displacement, times 1 + tan |lat|
READ_SLACK_M = 0.05  # and this: rounding, the derivative's finite difference
LAT_MAX = 80.0
GLITCH_SHARE = 0.97  # a step within this share of the glitch limit cannot be a glitch


def due_s(v0, accel, room_m, keep_out_m, needed_m, horizon_s, scale) -> float:
    """Seconds after a full check before the vehicle could use up the room it proved.

    Parameters
    ----------
    v0 : float
        The speed reported at the check, m/s.
    accel : float
        The bound on acceleration, m/s^2.
    room_m : float
        How far the vehicle may move before a fence's inside or outside could change.
    keep_out_m : float
        How far the nearest keep-out in force is (at any altitude).
    needed_m : float
        The room a CLEAR answer needs at any speed (the shortest look-ahead, the stopping
        margin).
    horizon_s : float
        The prediction horizon: at speed ``v`` the look-ahead is ``v * horizon_s``.
    scale : float
        ``1 + `` the reading error's share (see the module).

    Returns
    -------
    float
        0 when even the next position needs a full check.

    Examples
    --------
    >>> round(due_s(0.0, 10.0, 1000.0, 1000.0, 50.0, 15.0, 1.0), 2)
    5.53
    >>> due_s(10.0, 10.0, 1000.0, 60.0, 50.0, 15.0, 1.0)
    0.0
    """

    def room_left(t):
        reach = ((v0 + 0.5 * accel * t) * t + POSITION_SLACK_M) * scale + READ_SLACK_M
        look = max(needed_m, (v0 + accel * t + SPEED_SLACK_MPS) * horizon_s)
        return min(room_m - reach, keep_out_m - reach - look, REACH_MAX_M - reach)

    if not room_left(0.0) > 0.0:
        return 0.0
    lo, hi = 0.0, DUE_MAX_S
    if room_left(hi) > 0.0:
        return hi
    for _ in range(30):  # to a few tens of microseconds
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if room_left(mid) > 0.0 else (lo, mid)
    return lo


class Reach:
    """What a full check proved, for the positions that follow it (see the module).

    Parameters
    ----------
    t, lat, lon, alt : float
        The checked position: monotonic seconds, degrees, metres above home.
    v0 : float
        Its reported speed, m/s.
    accel : float
        The bound on acceleration, m/s^2.
    jacobian : tuple of float
        ``(dx/dlon, dx/dlat, dy/dlon, dy/dlat)``: the fences' frame's metres per degree there.
    due : float
        Seconds the answer holds (:func:`due_s`).
    scale : float
        The displacement's reading error, as ``1 + share`` (:func:`due_s`).
    gap_s : float
        A position later than this after the previous one is checked in full.
    vertical_m : float
        How far the altitude may move before an altitude band could change what holds the
        position (infinite when no banded fence holds it).
    glitch : tuple of float
        ``(max_speed_mps, slack_m)``: a step longer than ``max_speed * dt + slack`` between
        two positions is a GPS glitch, for the full check to say.
    version : int
        The fences' ``version`` it was measured at.
    stamp : tuple
        What else must not change (the mode, armed state and GPS fix at the check).
    """

    __slots__ = (
        *("t0", "lat0", "lon0", "alt0", "v0", "accel", "j", "end", "scale", "gap_s"),
        *("vertical_m", "glitch", "version", "stamp", "t_prev", "x_prev", "y_prev"),
    )

    def __init__(self, t, lat, lon, alt, v0, accel, jacobian, due, scale, gap_s,
                 vertical_m, glitch, version, stamp):  # fmt: skip
        self.t0, self.lat0, self.lon0, self.alt0 = t, lat, lon, alt
        self.v0, self.accel, self.j, self.end = v0, accel, jacobian, t + due
        self.scale, self.gap_s, self.vertical_m = scale, gap_s, vertical_m
        self.glitch, self.version, self.stamp = glitch, version, stamp
        self.t_prev, self.x_prev, self.y_prev = t, 0.0, 0.0

    def holds(self, t, lat, lon, alt, vn, ve) -> bool:
        """Whether the position reported at ``t`` is within what the check proved; when it
        is, it becomes the previous position (for the next one's step and time gap).

        Parameters
        ----------
        t : float
            Monotonic seconds.
        lat, lon : float
            Degrees.
        alt : float
            Metres above home.
        vn, ve : float
            Velocity north and east, m/s.

        Returns
        -------
        bool
            False sends the position to the full check.
        """
        # every test is written so that a NaN fails it
        dt = t - self.t0
        if not (0.0 <= t - self.t_prev <= self.gap_s and t <= self.end):
            return False
        v = self.v0 + self.accel * dt + SPEED_SLACK_MPS
        if not vn * vn + ve * ve <= v * v:
            return False
        dlon, dlat = lon - self.lon0, lat - self.lat0
        j = self.j
        x, y = j[0] * dlon + j[1] * dlat, j[2] * dlon + j[3] * dlat
        r = (self.v0 + 0.5 * self.accel * dt) * dt + POSITION_SLACK_M
        if not x * x + y * y <= r * r:
            return False
        sx, sy = x - self.x_prev, y - self.y_prev
        g = (self.glitch[0] * (t - self.t_prev) + self.glitch[1]) * GLITCH_SHARE / self.scale
        if not (sx * sx + sy * sy <= g * g and abs(alt - self.alt0) < self.vertical_m):
            return False
        self.t_prev, self.x_prev, self.y_prev = t, x, y
        return True


def read_scale(lat: float) -> float | None:
    """``1 +`` the share a displacement read by the frame's derivative may be short of the
    true one, at latitude ``lat``; None past :data:`LAT_MAX` (no lazy check there).

    Examples
    --------
    >>> round(read_scale(35.9), 6), read_scale(85.0)
    (1.000676, None)
    """
    if not abs(lat) <= LAT_MAX:
        return None
    return 1.0 + READ_ERROR * (1.0 + math.tan(math.radians(abs(lat))))
