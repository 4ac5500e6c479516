"""The checks of single values in a scene (numbers, integers, strings, vectors, boxes, regions,
tables), each raising a SceneError that names the key: the primitives of runtime.scene.parser."""
from __future__ import annotations

import math
from pathlib import Path

from ..base.errors import SceneError


def type_name(value) -> str:
    return {bool: "boolean", int: "integer", float: "float", str: "string", list: "array",
            dict: "table"}.get(type(value), type(value).__name__)


def format_value(value) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    return repr(value) if isinstance(value, str) else str(value)


class ValueParser:
    def __init__(self, base_dir):
        self.base_dir = Path(base_dir) if base_dir is not None else Path.cwd()
        self.scene_dir = Path(base_dir) if base_dir is not None else None   # None: paths stay as written
        self.dim = None             # 2 or 3 once known
        self.shell = False          # a shell mesh: [[fixed]] components 3..5 are its rotations


    # -- primitives -------------------------------------------------------------------------
    @staticmethod
    def table(value, key) -> dict:
        if not isinstance(value, dict):
            raise SceneError(f"{key}: expected a table, got {type_name(value)}")
        return value

    @staticmethod
    def tables(value, key) -> list:
        """An array of tables; a single table is accepted as a one-element array."""
        if isinstance(value, dict):
            return [value]
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise SceneError(f"{key}: expected an array of tables ([[{key}]]), got {type_name(value)}")
        return value

    @staticmethod
    def keys(table, key, allowed, extra=()):
        unknown = [k for k in table if k not in allowed and k not in extra]
        if unknown:
            listed = ", ".join(tuple(allowed) + tuple(extra))
            if key:
                where = "[" + key.split("[")[0] + "]"
                raise SceneError(f"{key}.{unknown[0]}: unknown key; allowed keys in {where}: {listed}")
            raise SceneError(f"{unknown[0]}: unknown table or key; allowed: {listed}")

    @staticmethod
    def number(value, key, *, positive=False, min_value=None, allow_inf=False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(f"{key}: expected a number, got {type_name(value)} {format_value(value)}")
        value = float(value)
        if math.isnan(value) or (math.isinf(value) and not allow_inf):
            raise SceneError(f"{key}: must be a finite number (got {format_value(value)})")
        if positive and not value > 0:
            raise SceneError(f"{key}: must be > 0 (got {format_value(value)})")
        if min_value is not None and value < min_value:
            raise SceneError(f"{key}: must be >= {format_value(min_value)} (got {format_value(value)})")
        return value

    @staticmethod
    def integer(value, key, min_value=None, max_value=None, why="") -> int:
        """An int in [min_value, max_value]; why: the reason for max_value, for the message."""
        if isinstance(value, bool) or not isinstance(value, int):
            hint = ""
            if isinstance(value, float) and value.is_integer():
                # TOML reads 1e12 and 100.0 as floats: say so, and what the integer would hit
                hint = " (TOML reads numbers with an exponent or a decimal point as floats"
                if max_value is not None and value > max_value:
                    hint += f"; and {int(value):,} is above the limit of {max_value:,}{': ' + why if why else ''})"
                else:
                    hint += f": write {int(value)})"
            raise SceneError(f"{key}: expected an integer, got {type_name(value)} {format_value(value)}{hint}")
        if min_value is not None and value < min_value:
            raise SceneError(f"{key}: must be >= {min_value} (got {value})")
        if max_value is not None and value > max_value:
            raise SceneError(f"{key}: must be <= {max_value:,} (got {value:,}){': ' + why if why else ''}")
        return int(value)

    @staticmethod
    def string(value, key, choices=None) -> str:
        if not isinstance(value, str):
            raise SceneError(f"{key}: expected a string, got {type_name(value)} {format_value(value)}")
        if choices is not None and value not in choices:
            raise SceneError(f"{key}: unknown value {value!r}; allowed: {', '.join(choices)}")
        return value

    @staticmethod
    def boolean(value, key) -> bool:
        if not isinstance(value, bool):
            raise SceneError(f"{key}: expected true or false, got {type_name(value)} {format_value(value)}")
        return value

    def vector(self, value, key, dim=None, allow_inf=False) -> tuple:
        """A list of numbers with the scene's dimension (2 or 3 while it is not known yet)."""
        dim = dim if dim is not None else self.dim
        if not isinstance(value, list):
            raise SceneError(f"{key}: expected an array of {dim or '2 or 3'} numbers, got {type_name(value)}")
        if (dim is not None and len(value) != dim) or (dim is None and len(value) not in (2, 3)):
            what = f"{dim}" if dim is not None else "2 or 3"
            extra = " (the mesh is 2D: use 2 components)" if dim == 2 else (
                " (the mesh is 3D: use 3 components)" if dim == 3 else "")
            raise SceneError(f"{key}: expected {what} components, got {len(value)}{extra}")
        return tuple(self.number(v, f"{key}[{i}]", allow_inf=allow_inf) for i, v in enumerate(value))

    @staticmethod
    def region(value, key):
        """A region of the mesh: a group name (non-empty string) or an integer id (runtime.mesh.regions)."""
        if isinstance(value, bool) or not isinstance(value, (str, int)) or (isinstance(value, str) and not value.strip()):
            raise SceneError(f"{key}: expected a region name (a string) or an integer id, got "
                             f"{type_name(value)} {format_value(value)}")
        return value

    def box(self, value, key) -> tuple:
        if not isinstance(value, list) or len(value) != 2:
            raise SceneError(f"{key}: expected [[min...], [max...]] (two corner points), got {format_value(value)}")
        lo = self.vector(value[0], f"{key}[0]", allow_inf=True)
        hi = self.vector(value[1], f"{key}[1]", dim=len(lo), allow_inf=True)
        bad = [i for i in range(len(lo)) if lo[i] > hi[i]]
        if bad:
            i = bad[0]
            raise SceneError(f"{key}: min > max in component {i} ({format_value(lo[i])} > {format_value(hi[i])}); "
                             "write box = [[min...], [max...]]")
        return (lo, hi)
