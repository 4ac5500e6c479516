"""generator/shape_tables.py: written by `tensormass generate`, verified by `generate --check`."""
from __future__ import annotations

import json

import pytest

from tensormass.apps.cli import committed_dir, main
from tensormass.generator import shape_tables

SMALL = ["--element", "triangle", "--law", "hooke", "--quadrature", "gauss1", "--backend", "numba"]


@pytest.fixture(scope="module")
def rendered():
    """The tables' text, built once (3 s of sympy integration) for the commands below."""
    return shape_tables.render()


@pytest.fixture
def render_once(rendered, monkeypatch):
    monkeypatch.setattr(shape_tables, "render", lambda: rendered)


def test_generate_writes_the_tables(tmp_path, capsys, render_once):
    assert main(["generate", *SMALL, "--no-compile", "--out", str(tmp_path)]) == 0
    written = (tmp_path / shape_tables.FILE).read_bytes()
    assert written == (committed_dir() / shape_tables.FILE).read_bytes()
    types = json.loads(written)["types"]
    assert {"line", "line3", "triangle", "triangle6", "quad"} <= set(types)      # every face type


def test_check_reports_stale_tables(monkeypatch, capsys, render_once):
    entry = SMALL[:6]                          # every backend: the manifest records both
    assert main(["generate", "--check", *entry]) == 0
    capsys.readouterr()
    monkeypatch.setattr(shape_tables, "render", lambda: "{}\n")
    assert main(["generate", "--check", *entry]) == 1
    assert shape_tables.FILE in capsys.readouterr().err


def test_rules_are_exact_for_the_mass_integrand_degree():
    for name in ("tetra10", "triangle6", "line3", "tetra", "triangle", "line"):
        t = shape_tables.type_of(name)
        r = shape_tables.rule_for(t)
        assert r.degree >= 2 * t.order + t.dim * (t.order - 1)
