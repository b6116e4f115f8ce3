"""``alphafence --help`` lists the verbs in the order of the workflow, each with a one-line
summary, and points to the docs; every option of every verb says what it does and shows its
default."""

import argparse

import pytest

from alphafence.cli import VERBS, main, parser

# get data -> build -> compile / upload --dry-run -> upload -> monitor -> check-flight, then
# the planning, signing and trying-out verbs
WORKFLOW = (
    "build",
    "update",
    "compare",
    "compile",
    "upload",
    "download",
    "monitor",
    "check-flight",
    "route",
    "check-mission",
    "bundle",
    "signing",
    "sitl",
    "demo",
)
SILENT_DEFAULTS = (None, False, [], argparse.SUPPRESS)


def _subparsers(p, path=("alphafence",)):
    """Every (path, parser) below ``p``, sub-sub-parsers included (bundle sign, signing setup)."""
    for action in p._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sp in action.choices.items():
                yield (*path, name), sp
                yield from _subparsers(sp, (*path, name))


def _options():
    for path, sp in _subparsers(parser()):
        for action in sp._actions:
            if action.option_strings and not isinstance(action, argparse._HelpAction):
                yield " ".join(path), sp, action


def _entry(text, option):
    """An option's entry in a help text: its line and the lines that continue it."""
    lines = text.splitlines()
    start = next(k for k, line in enumerate(lines) if line.strip().startswith(option + " "))
    end = start + 1
    while end < len(lines) and lines[end].startswith("    ") and not lines[end].strip()[:1] == "-":
        end += 1
    return "\n".join(lines[start:end])


def test_the_verbs_are_in_workflow_order_with_a_summary_each(capsys):
    assert VERBS == WORKFLOW
    with pytest.raises(SystemExit) as done:
        main(["--help"])
    assert done.value.code == 0
    out = capsys.readouterr().out
    lines = [line.split() for line in out.splitlines()]
    listed = [w[0] for w in lines if w and w[0] in WORKFLOW and len(w) > 1]
    assert listed == list(WORKFLOW)  # each on its line, with its summary after it
    assert "docs/index.md" in out and "mkdocs serve" in out


def test_every_option_has_help_and_shows_its_default():
    missing, hidden = [], []
    for where, sp, action in _options():
        name = f"{where} {action.option_strings[-1]}"
        if not action.help or action.help == argparse.SUPPRESS:
            missing.append(name)
            continue
        if action.default in SILENT_DEFAULTS:
            continue
        shown = sp._get_formatter()._expand_help(action)
        if "default" not in shown:
            hidden.append(f"{name}: {shown!r}")
    assert not missing, "options without help: " + ", ".join(missing)
    assert not hidden, "defaults not shown:\n" + "\n".join(hidden)


@pytest.mark.parametrize(
    "verb, option, default",
    [("monitor", "--breach-action", "rtl"), ("monitor", "--on-glitch", "none"),
     ("signing setup", "--timeout", "10.0"), ("upload", "--profile", "copter")],
)  # fmt: skip
def test_a_default_is_shown_in_the_verbs_help(capsys, verb, option, default):
    with pytest.raises(SystemExit):
        main([*verb.split(), "--help"])
    said = " ".join(_entry(capsys.readouterr().out, option).split())
    assert (
        f"default: {default})" in said
        or f"default {default}" in said
        or (f"{default} (default)" in said)
    ), said


def test_both_keys_are_told_apart_in_both_helps(capsys):
    for verb in ("bundle", "signing"):
        with pytest.raises(SystemExit):
            main([verb, "--help"])
        out = " ".join(capsys.readouterr().out.split())
        assert "who made the fences" in out and "who may talk to the vehicle" in out
        assert "--trusted-key" in out and "--signing-key" in out
    with pytest.raises(SystemExit):
        main(["upload", "--help"])
    out = capsys.readouterr().out
    trusted = " ".join(_entry(out, "--trusted-key").split())
    signing = " ".join(_entry(out, "--signing-key").split())
    assert "bundle keygen" in trusted and "who made the fences" in trusted
    assert "signing keygen" in signing and "who may talk to the vehicle" in signing
