"""The kit's errors: one base, and one class per kind of fault an operator must act on.

Every message is a complete line for the operator: the command line prints ``str(err)`` after
``alphafence VERB: error:`` and exits with the class's ``exit_code``. Library code names files,
features and vehicles in its messages, never command-line options.

===================  =========  ==============================================================
class                exit code  raised when
===================  =========  ==============================================================
``AlphaFenceError``  1          (base; catch this to catch them all)
``InputError``       2          a file, a feature or a value is malformed or out of range
``InputErrors``      2          several such faults in one input: every one listed, a line each
``VehicleError``     3          the vehicle or the link to it failed, refused or disagreed
``SitlError``        1          an ArduPilot SITL binary is missing or did not start
``RoutingError``     1          no route exists (the message says what blocks it)
``SourceError``      4          a live source of zones failed: unreachable, refused, not GeoJSON
``MissingDependency``  2        a package this work needs is not installed (:func:`need`)
===================  =========  ==============================================================

The base install (numpy, shapely, pyproj, rich, cryptography) reads and writes every fence
file and compiles; the packages in :data:`OPTIONAL` come with the extras named there, and a
module imports them only where its work needs them. :func:`need` checks them and names, in
one line, what to install.
"""

from __future__ import annotations

import importlib


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


class InputErrors(InputError):
    """Every fault found in an input, reported at once: ``str(err)`` is a line that counts
    them, then each fault's own line (an :class:`InputError`'s, naming file and feature).

    Parameters
    ----------
    path : str or Path or None
        The input (or inputs) at fault.
    errors : list of InputError
        The faults, in the order found (at least one).
    footer : str, optional
        A last line: what to do about them.

    Attributes
    ----------
    errors : list of InputError

    Examples
    --------
    >>> faults = [InputError("a.txt", "bad", "line 2"), InputError("a.txt", "worse", "line 9")]
    >>> print(InputErrors("a.txt", faults))
    a.txt: 2 problems:
      a.txt: line 2: bad
      a.txt: line 9: worse
    """

    def __init__(self, path, errors, footer=None):
        self.errors = list(errors)
        self.footer = footer
        super().__init__(path, f"{len(self.errors)} problem{'s' * (len(self.errors) != 1)}:")
        lines = [Exception.__str__(self), *(f"  {e}" for e in self.errors)]
        if footer:
            lines.append(" ".join(str(footer).split()))
        self.args = ("\n".join(lines),)


class VehicleError(AlphaFenceError, RuntimeError):
    """The vehicle, or the link to it, failed: no connection, a refused or unverified
    transfer, a parameter that did not stick, a signing setup that was not confirmed."""

    exit_code = 3


class SitlError(AlphaFenceError, RuntimeError):
    """ArduPilot SITL could not be found or started, or did not become ready."""


class SourceError(AlphaFenceError):
    """A live source of zones (an OGC API - Features collection) failed: ``str(err)`` is one
    line naming the source and what went wrong (name resolution, refused, HTTP status,
    timeout, not GeoJSON, too large).

    Parameters
    ----------
    url : str
        The source.
    message : str
        What went wrong, for the operator.
    retry : bool
        Whether asking again may help (a timeout, a refused connection, a 5xx).

    Examples
    --------
    >>> str(SourceError("https://zones.example/collections/uas", "HTTP 404: no such collection"))
    'https://zones.example/collections/uas: HTTP 404: no such collection'
    """

    exit_code = 4

    def __init__(self, url, message, retry: bool = False):
        self.url, self.retry = " ".join(str(url).split())[:300], retry  # a server's link too
        self.message = " ".join(str(message).split())[:300]
        super().__init__(f"{self.url}: {self.message}")


class RoutingError(AlphaFenceError):
    """No route: the message names what blocks it (a start inside a fence, an enclosed goal)."""


# the optional packages, by import name: (what PyPI and pip call it, the extra that brings it,
# Debian's package or None, the oldest version the kit works with)
OPTIONAL = {
    "osmium": ("osmium", "build", "python3-pyosmium", "4.0"),
    "scipy": ("scipy", "build", "python3-scipy", None),
    "matplotlib": ("matplotlib", "build", "python3-matplotlib", None),
    "ijson": ("ijson", "build", "python3-ijson", None),
    "distributed": ("distributed", "dask", "python3-distributed", None),
    "pymavlink": ("pymavlink", "companion", None, None),
    "serial": ("pyserial", "companion", "python3-serial", None),
    "mavsdk": ("mavsdk", "vehicle", None, None),
    "pyarrow": ("pyarrow", "parquet", None, "17.0"),
    "lxml": ("lxml", "kml", "python3-lxml", None),
    "aiohttp": ("aiohttp", "map", "python3-aiohttp", None),
    "psycopg": ("psycopg", "postgis", "python3-psycopg", None),
    "pyulog": ("pyulog", "ulog", None, None),
}


class MissingDependency(AlphaFenceError, ImportError):
    """A package that the work asked for needs is not installed, does not import, or is too
    old: ``str(err)`` is one line naming it, the extra and the Debian package that bring it
    (:func:`install_hint`).

    It is an ``ImportError`` too, so ``except ImportError`` still catches it.

    Parameters
    ----------
    wants : list of (str, str, str or None)
        ``(package, purpose, fault)`` per missing package, with the package's import name
        (a key of :data:`OPTIONAL`) and ``fault`` None for "not installed".
    exit_code : int, optional
        The command line's exit status (default 2; a vehicle link that is missing: 3).

    Examples
    --------
    >>> print(MissingDependency([("osmium", "reading malta.osm.pbf", None)]))
    reading malta.osm.pbf needs pyosmium 4.0 or later: in the AlphaFence checkout: pip install '.[build]' (or everything: pip install -e '.[all]'; Debian: apt install python3-pyosmium)
    """

    exit_code = 2

    def __init__(self, wants, exit_code=None):
        self.packages = [w[0] for w in wants]
        if exit_code is not None:
            self.exit_code = exit_code
        needs = {}
        for package, purpose, fault in wants:
            what = _display(package) + (f" ({fault})" if fault else "")
            needs.setdefault(purpose, []).append(what)
        said = "; ".join(f"{purpose} needs {' and '.join(w)}" for purpose, w in needs.items())
        super().__init__(" ".join(f"{said}: {install_hint(self.packages)}".split()))


def install_hint(packages):
    """How to install the optional ``packages`` (import names, keys of :data:`OPTIONAL`):
    the extras that bring them, installed from the AlphaFence checkout (the kit is not on
    PyPI), and Debian's packages where there are.

    Examples
    --------
    >>> install_hint(["scipy"])
    "in the AlphaFence checkout: pip install '.[build]' (or everything: pip install -e '.[all]'; Debian: apt install python3-scipy)"
    """
    extras = sorted({OPTIONAL[p][1] for p in packages})
    debian = [OPTIONAL[p][2] for p in packages if OPTIONAL[p][2]]
    how = f"in the AlphaFence checkout: pip install '.[{','.join(extras)}]'"
    how += " (or everything: pip install -e '.[all]'"
    return how + (f"; Debian: apt install {' '.join(debian)})" if debian else ")")


def _display(package):
    name = {"osmium": "pyosmium", "serial": "pyserial"}.get(package, package)
    oldest = OPTIONAL[package][3]
    return f"{name} {oldest} or later" if oldest else name


def need(*wants, exit_code=None):
    """Import optional packages now, or say in one line which are missing and how to get them.

    Parameters
    ----------
    *wants : (str, str)
        ``(module, purpose)``: a module of a package in :data:`OPTIONAL` (``"osmium.filter"``
        also checks that pyosmium is new enough to have it) and what needs it, as the
        operator would say it (``"reading malta.osm.pbf"``).
    exit_code : int, optional
        The :class:`MissingDependency`'s exit status (default 2).

    Raises
    ------
    MissingDependency
        Naming every package that is missing, too old or broken.

    Examples
    --------
    >>> need(("json", "reading JSON"))  # a module that imports: nothing happens
    """
    missing = []
    for module, purpose in wants:
        package = module.split(".")[0]
        try:
            importlib.import_module(module)
        except ImportError as exc:
            fault = _fault(package, module, exc) if _installed(package) else None
            missing.append((package, purpose, fault))
    if missing:
        raise MissingDependency(missing, exit_code)


def _installed(package):
    import importlib.util

    try:
        return importlib.util.find_spec(package) is not None
    except (ImportError, ValueError):  # blocked, or a None in sys.modules
        return False


def _fault(package, module, exc):
    """Why an installed package did not import: too old to have ``module``, or broken."""
    from importlib import metadata

    try:
        version = metadata.version(OPTIONAL[package][0])
    except (metadata.PackageNotFoundError, KeyError):
        version = "?"
    if exc.name == module:
        return f"{version} is installed, without {module}"
    return f"{version} is installed but does not import: {exc}"[:200]


def missing_dependency(exc, purpose):
    """The :class:`MissingDependency` for an ``ImportError`` of an optional package, else None.

    Parameters
    ----------
    exc : ImportError
    purpose : str
        What needed it, for the message.

    Examples
    --------
    >>> str(missing_dependency(ModuleNotFoundError(name="scipy"), "re-routing"))[:24]
    're-routing needs scipy: '
    >>> missing_dependency(ModuleNotFoundError(name="yaml"), "x") is None
    True
    """
    if isinstance(exc, MissingDependency):
        return exc
    package = (exc.name or "").split(".")[0]
    if package not in OPTIONAL:
        return None
    return MissingDependency([(package, purpose, None)])
