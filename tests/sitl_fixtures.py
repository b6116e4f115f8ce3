"""Fixtures that drive a real ArduPilot SITL binary (registered from conftest.py).

- ``sitl_binary``: the arducopter binary, or a skip with a one-line reason.
- ``sitl``: one SITL instance, started and ready (position estimate), stopped after the test.
  Defaults: home ``egham``, speedup ``$ALPHAFENCE_SITL_SPEEDUP`` or 5, ready within 60 s.
  Override per test with indirect parametrization::

      @pytest.mark.parametrize("sitl", [{"home": "malta_airport", "speedup": 1}], indirect=True)

  Any keyword of ``alphafence.sitl.SitlInstance`` works, plus ``ready_timeout``.
- ``sitl_factory``: ``await sitl_factory(**options)`` launches more instances (ready unless
  ``ready_timeout=None``); all are stopped after the test.

Mark tests that use them ``@pytest.mark.sitl``. ``ALPHAFENCE_SITL_KEEP=1`` keeps each
instance's temporary working directory (its ``sitl.log``) for a post-mortem.
"""

import contextlib
import os

import pytest

from alphafence.sitl.find import NOT_FOUND_HELP, find_sitl_binary

DEFAULTS = {"home": "egham", "ready_timeout": 60.0}


def _defaults():
    options = dict(DEFAULTS)
    options["speedup"] = float(os.environ.get("ALPHAFENCE_SITL_SPEEDUP", "5"))
    options["keep_dir"] = os.environ.get("ALPHAFENCE_SITL_KEEP", "") not in ("", "0")
    return options


@pytest.fixture(scope="session")
def sitl_binary():
    binary = find_sitl_binary()
    if binary is None:
        pytest.skip(NOT_FOUND_HELP)
    return binary


@contextlib.asynccontextmanager
async def _instances(cls, defaults):
    """``launch(**options)``: an instance of ``cls`` started (and ready, unless
    ``ready_timeout=None``); every one stopped at the end, the last first."""
    started = []

    async def launch(**options):
        options = {**defaults, **options}
        ready_timeout = options.pop("ready_timeout")
        instance = cls(**options)
        started.append(instance)
        await instance.start()
        if ready_timeout is not None:
            await instance.wait_ready(ready_timeout)
        return instance

    try:
        yield launch
    finally:
        for instance in reversed(started):
            await instance.stop()


@pytest.fixture
async def sitl_factory(sitl_binary):
    from alphafence.sitl.instance import SitlInstance

    async with _instances(SitlInstance, {**_defaults(), "binary": sitl_binary}) as launch:
        yield launch


@pytest.fixture
async def sitl(request, sitl_factory):
    return await sitl_factory(**getattr(request, "param", {}))


# -- PX4 SITL (SIH quadrotor) ------------------------------------------------------------
PX4_DEFAULTS = {"home": (35.8660, 14.4775, 80.0), "ready_timeout": 120.0}  # malta_airport


@pytest.fixture(scope="session")
def px4_root():
    from alphafence.sitl.px4 import PX4_NOT_FOUND_HELP, find_px4

    root = find_px4()
    if root is None:
        pytest.skip(PX4_NOT_FOUND_HELP)
    return root


@pytest.fixture
async def px4_factory(px4_root):
    """``await px4_factory(**options)``: a PX4 SITL ready for takeoff (options: those of
    ``alphafence.sitl.px4.Px4Instance``, and ``ready_timeout``); all stopped after the test."""
    from alphafence.sitl.px4 import Px4Instance

    async with _instances(Px4Instance, {**PX4_DEFAULTS, "root": px4_root}) as launch:
        yield launch


@pytest.fixture
async def px4(request, px4_factory):
    """One PX4 SITL, ready (override options with indirect parametrization, as ``sitl``)."""
    return await px4_factory(**getattr(request, "param", {}))
