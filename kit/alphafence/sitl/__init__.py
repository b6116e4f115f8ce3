"""Finding and running ArduPilot SITL, bottom up:

=============  ================================================================================
``find``       the user's arducopter binary (AlphaFence ships no ArduPilot code)
``homes``      named start positions and the kit's SITL data files
``ports``      instance numbers and UDP ports, reserved across processes
``cmdline``    the SITL argument vector, its defaults files, a parameter file
``readiness``  when the vehicle is ready, and the MAVLink listener that hears it
``instance``   one SITL process: start, wait until ready, stop
=============  ================================================================================

The names most callers need are here, loaded on first use (so that finding the binary loads
nothing else)::

    from alphafence.sitl import launch_sitl
"""

_EXPORTS = {
    "DEFAULT_HOME": "alphafence.sitl.homes",
    "Home": "alphafence.sitl.homes",
    "load_homes": "alphafence.sitl.homes",
    "resolve_home": "alphafence.sitl.homes",
    "NOT_FOUND_HELP": "alphafence.sitl.find",
    "find_sitl_binary": "alphafence.sitl.find",
    "ReadyState": "alphafence.sitl.readiness",
    "SitlInstance": "alphafence.sitl.instance",
    "launch_sitl": "alphafence.sitl.instance",
}

__all__ = list(_EXPORTS)


def __getattr__(name):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'alphafence.sitl' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)
