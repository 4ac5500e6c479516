"""A cold start: the command line's help starts without sympy, numba or jinja2, the deferred
commands' stubs say what the full parsers say, and a run writes nothing into the package folder."""
import os
import subprocess
import sys

import pytest

from tensormass.apps import cli

HEAVY = ("numba", "sympy", "jinja2")


def _imported_by(args, env=None):
    """The top-level modules `python -X importtime -m tensormass ARGS` imports."""
    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "tensormass", *args],
                          capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "usage: tensormass" in done.stdout
    return {line.split("|")[-1].strip().split(".")[0]
            for line in done.stderr.splitlines() if line.startswith("import time:")}


@pytest.mark.parametrize("args", [["--help"], ["run", "--help"], ["demo", "--help"]])
def test_help_imports_no_heavy_module(args):
    imported = _imported_by(args)
    assert "tensormass" in imported                 # the report did list the package's imports
    assert not imported & set(HEAVY), sorted(imported & set(HEAVY))


def _choices(parser):
    action = next(a for a in parser._actions if a.dest == "command")
    return {c.dest: c.help for c in action._choices_actions}, action.choices


def test_stubs_say_what_the_full_commands_say():
    full_help, full = _choices(cli.build_parser())
    stub_help, stubs = _choices(cli.build_parser(full=set()))
    assert stub_help == full_help
    assert list(stubs) == list(full)                 # the same commands, in the same order
    for name in cli.DEFERRED:
        assert stubs[name]._actions == []            # a stub: nothing parsed, nothing imported
        assert full[name]._actions                   # the real parser, with its options


def test_a_named_deferred_command_is_built_in_full():
    _, choices = _choices(cli.build_parser(full={cli.named_command(["generate", "--check"])}))
    assert any(a.dest == "check" for a in choices["generate"]._actions)
    assert cli.named_command(["--version"]) is None
