"""The kit's errors: one base, and one class per kind of fault an operator must act on.

Every message is a complete line for the operator: the command line prints ``str(err)`` after
``alphafence VERB: error:`` and exits with the class's ``exit_code``. Library code names files,
features and vehicles in its messages, never command-line options.

===================  =========  ==============================================================
class                exit code  raised when
===================  =========  ==============================================================
``AlphaFenceError``  1          (base; catch this to catch them all)
``InputError``       2          a file, a feature or a value is malformed or out of range
``VehicleError``     3          the vehicle or the link to it failed, refused or disagreed
``SitlError``        1          an ArduPilot SITL binary is missing or did not start
``RoutingError``     1          no route exists (the message says what blocks it)
===================  =========  ==============================================================
"""

from __future__ import annotations


class AlphaFenceError(Exception):
    """Base of every error the kit raises on purpose.

    Attributes
    ----------
    exit_code : int
        The command line's exit status for this error.
    """

    exit_code = 1


class InputError(AlphaFenceError):
    """Bad input: ``str(err)`` is one line naming the file, the feature and the fault.

    Parameters
    ----------
    path : str or Path or None
        The file (or the value's name) at fault; ``None`` prints ``<input>``.
    message : str
        What is wrong. Whitespace is collapsed to one line and long texts are cut.
    feature : str, optional
        The feature within the file (``"line 4"``, ``"feature 12 (osm way 42)"``).

    Examples
    --------
    >>> str(InputError("zones.json", "radius must be positive", "feature 3"))
    'zones.json: feature 3: radius must be positive'
    """

    exit_code = 2

    def __init__(self, path, message, feature=None):
        self.path = str(path) if path is not None else None
        # one line, whatever a library or a hostile file put in the text
        self.feature = None if feature is None else " ".join(str(feature).split())
        message = " ".join(str(message).split())
        if len(message) > 300:
            message = message[:297] + "..."
        self.message = message
        where = self.path or "<input>"
        if self.feature is not None:
            where = f"{where}: {self.feature[:120]}"
        super().__init__(f"{where}: {message}")


class VehicleError(AlphaFenceError, RuntimeError):
    """The vehicle, or the link to it, failed: no connection, a refused or unverified
    transfer, a parameter that did not stick, a signing setup that was not confirmed."""

    exit_code = 3


class SitlError(AlphaFenceError, RuntimeError):
    """ArduPilot SITL could not be found or started, or did not become ready."""


class RoutingError(AlphaFenceError):
    """No route: the message names what blocks it (a start inside a fence, an enclosed goal)."""
