"""The examples in the docstrings of the lower and middle stages run, so they cannot rot."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

STAGES = (
    "geo",
    "mavlink",
    "zones",
    "fencefiles",
    "sources",
    "fencing",
    "flights",
    "onboard",
    "route",
    "awareness",
)


def _modules():
    for stage in STAGES:
        package = importlib.import_module(f"alphafence.{stage}")
        yield package.__name__
        for info in pkgutil.iter_modules(package.__path__, prefix=f"{package.__name__}."):
            yield info.name


MODULES = sorted(_modules())


def _run(name):
    """(examples attempted, failures) of one module's docstrings, and the failure report."""
    module = importlib.import_module(name)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    report = []
    for test in doctest.DocTestFinder().find(module, name):
        runner.run(test, out=report.append)
    result = runner.summarize(verbose=False)
    return result.attempted, result.failed, "".join(report)


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    _, failed, report = _run(name)
    assert not failed, f"{name}: {failed} example(s) failed\n{report}"


@pytest.mark.parametrize(
    "name",
    [
        "alphafence.geo.frame",
        "alphafence.geo.alpha",
        "alphafence.geo.outward",
        "alphafence.geo.coords",
        "alphafence.fencing.sites",
        "alphafence.fencing.pipeline",
        "alphafence.onboard.compile",
        "alphafence.onboard.options",
        "alphafence.route.roadmap",
        "alphafence.route.planner",
    ],
)
def test_the_main_entry_points_have_examples(name):
    assert name in MODULES
    attempted, _, _ = _run(name)
    assert attempted > 0, f"{name} has no examples in its docstrings"
