"""How the suite reads ``CI``, in one place (conftest's skip rule, hypothesis' profile, the live
servers' fallback).

``CI`` is on for ``1``, ``true``, ``yes`` or ``on`` in any case and with spaces round it (what
CI services set), and off for anything else, ``false`` and ``0`` included: a value the suite
does not know never turns on half of CI's rules.

``ALPHAFENCE_HYPOTHESIS_PROFILE=ci`` loads CI's hypothesis profile (a fixed seed, no deadline)
without the rest of CI's rules: ``make navio2-test`` runs the companion's install, which has
no browser or MAVSDK by design, under qemu, where the deadline would fail everything.
"""

from __future__ import annotations

import os

ON = ("1", "true", "yes", "on")


def under_ci(environ=None) -> bool:
    """Whether ``CI`` is on in ``environ`` (default ``os.environ``)."""
    value = (os.environ if environ is None else environ).get("CI", "")
    return value.strip().lower() in ON


def hypothesis_profile(environ=None) -> str | None:
    """The hypothesis profile to load: ``"ci"`` under CI or when asked for, else None."""
    env = os.environ if environ is None else environ
    if under_ci(env) or env.get("ALPHAFENCE_HYPOTHESIS_PROFILE", "").strip().lower() == "ci":
        return "ci"
    return None
