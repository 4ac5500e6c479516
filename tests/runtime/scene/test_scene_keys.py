"""runtime.scene.keys describes exactly the keys the scene parser accepts, with its defaults.

The parser is asked, not read: a key it does not know is refused with the list of the keys the
table allows, and that list must be the table's declared keys.  A key added to the parser
without a line in scene_keys (or the other way round) fails here.
"""
from __future__ import annotations

import copy
import dataclasses
import re

import pytest

from tensormass import laws
from tensormass.runtime.contact.base import ContactSpec
from tensormass.runtime.contact.obstacles import Obstacle
from tensormass.runtime.scene import types as scene_module
from tensormass.runtime.base.errors import SceneError
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.scene.keys import KEYS, NO_DEFAULT, REQUIRED, TABLES, allowed_values, keys_of

BOX = [[-1e-9, -1, -1], [1e-9, 1, 1]]
BASE = {
    "mesh": {"generate": "bar", "size": [1.0, 0.2, 0.2], "cells": [2, 1, 1]},
    "material": [{"law": "hooke", "E": 1e6, "nu": 0.3}],
    "fixed": [{"box": BOX, "rotation": {"axis": [1.0, 0, 0], "point": [0, 0, 0], "angle": 1.0},
               "amplitude": "a"}],
    "amplitude": [{"name": "a", "time": [0.0, 1.0], "value": [0.0, 1.0]}],
    "loads": {"force": [{"box": BOX, "value": [0, 0, 1.0]}], "traction": [{"box": BOX, "value": [0, 0, 1.0]}],
              "moment": [{"box": BOX, "value": [0, 0, 1.0]}], "pressure": [{"box": BOX, "value": 1.0}]},
    "solver": {"kind": "implicit_euler", "steps": 2},
    "probe": [{"point": [1.0, 0.1, 0.1]}],
    "output": {},
    "adapt": [{"criterion": "R_L", "threshold": 0.1, "law": "stvk"}],
    "cut": [{"step": 1, "plane": [[0.5, 0, 0], [1.0, 0, 0]]}],
    "remove": [{"step": 1, "box": BOX}],
    "refine": [{"step": 1, "box": BOX}],
}
# contact may not be combined with [[cut]], [[remove]], [[refine]]: its tables are asked on their own
CONTACT = {"contact": {"method": "ipc"},
           "obstacle": [{"shape": "plane", "point": [0, 0, 0], "normal": [0, 0, 1.0], "translation": [0, 0, 0.01],
                         "rotation": {"axis": [1.0, 0, 0], "point": [0, 0, 0], "angle": 1.0}}]}


def _allowed_by_parser(table: str) -> list:
    """The keys the parser lists when `table` holds an unknown key."""
    data = copy.deepcopy(BASE)
    if table in ("cut", "remove", "refine", "adapt"):      # these may not be combined: keep only one
        for other in ("cut", "remove", "refine", "adapt"):
            if other != table:
                data.pop(other)
    if table.split(".")[0] in ("contact", "obstacle"):
        for other in ("cut", "remove", "refine"):
            data.pop(other)
        data.update(copy.deepcopy(CONTACT))
    node = data
    for part in table.split(".") if table else ():
        node = node[part]
        if isinstance(node, list):
            node = node[0]
    node["zz_not_a_key"] = 1
    with pytest.raises(SceneError) as info:
        Scene.from_dict(data, load_mesh=False)
    message = str(info.value)
    assert "zz_not_a_key" in message, message
    listed = re.search(r"allowed(?: keys in \[[^\]]*\])?: (.*)$", message).group(1)
    return [k.strip() for k in listed.split(",")]


@pytest.mark.parametrize("table", [t.name for t in TABLES])
def test_declared_keys_are_the_parsers(table):
    declared = [k.name for k in keys_of(table)]
    assert len(set(declared)) == len(declared), f"[{table}] declares a key twice"
    accepted = _allowed_by_parser(table)
    if table == "material":                  # plus the law's own parameters (hooke: lam, mu)
        accepted = [k for k in accepted if k not in laws.get("hooke").parameters]
    assert sorted(declared) == sorted(accepted), f"[{table}]: scene_keys {declared} vs parser {accepted}"


_DATACLASSES = {"mesh": scene_module.MeshSpec, "material": scene_module.Material, "fixed": scene_module.Fixed,
                "solver": scene_module.Solver, "probe": scene_module.Probe, "output": scene_module.Output,
                "adapt": scene_module.Adapt, "cut": scene_module.TopologyEvent,
                "remove": scene_module.TopologyEvent, "refine": scene_module.TopologyEvent,
                "contact": ContactSpec, "obstacle": Obstacle}
_FIELD_NAMES = {("adapt", "from"): "from_law", ("contact", "self"): "self_contact"}


def test_declared_defaults_are_the_parsers():
    checked, tables = 0, set()
    for key in KEYS:
        cls = _DATACLASSES.get(key.table)
        if cls is None or key.default_text is not None or key.default == REQUIRED:
            continue
        fields = {f.name: f for f in dataclasses.fields(cls)}
        name = _FIELD_NAMES.get((key.table, key.name), key.name)
        if name not in fields or fields[name].default is dataclasses.MISSING:
            continue
        expected = None if key.default == NO_DEFAULT else key.default
        assert fields[name].default == expected, f"{key.table}.{key.name}: {key.default!r} vs {fields[name].default!r}"
        checked += 1
        tables.add(key.table)
    assert checked >= 30
    assert {"contact", "obstacle"} <= tables      # their defaults live in ContactSpec and Obstacle


def test_allowed_values_resolve_and_are_accepted():
    """Every list of allowed values resolves, and its first value is one the parser takes."""
    resolved = {f"{k.table}.{k.name}": allowed_values(k) for k in KEYS if k.choices is not None}
    assert "implicit_euler" in resolved["solver.kind"]
    assert "von_mises" in resolved["output.fields"]
    assert "neohookean" in resolved["material.law"]
    assert "displacement" in resolved["material.formulation"]
    for name in resolved["solver.kind"]:
        data = copy.deepcopy(BASE)
        for other in ("cut", "remove", "refine"):
            data.pop(other)
        data["solver"] = {"kind": name, "steps": 2}
        Scene.from_dict(data, load_mesh=False)
