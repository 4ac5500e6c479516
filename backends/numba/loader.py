"""Load a generated numba module: an import (committed catalogue) or an import by path (a file
generated into the cache). The module itself is the kernel: METADATA and five @njit functions."""
from __future__ import annotations

import importlib
import importlib.util
import json
import sys
from pathlib import Path

from ..protocol import BackendError, check_metadata

METADATA_PREFIX = "METADATA = json.loads('"
COMMITTED_PACKAGE = "tensormass.generated.numba"


def read_metadata(path: Path) -> dict:
    """The METADATA line of a generated module, read as text (nothing imported or compiled)."""
    path = Path(path)
    try:
        with open(path, encoding="utf-8") as handle:
            for line in handle:
                if line.startswith(METADATA_PREFIX):
                    return check_metadata(json.loads(line[len(METADATA_PREFIX):].rstrip().removesuffix("')")), path)
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise BackendError(f"{path}: cannot read the kernel metadata ({error})") from None
    raise BackendError(f"{path}: no METADATA line (not a tensormass numba kernel?)")


def _committed_name(path: Path) -> str | None:
    """The package name of a module of the committed catalogue, else None."""
    spec = importlib.util.find_spec(COMMITTED_PACKAGE)
    folders = [Path(p).resolve() for p in (spec.submodule_search_locations or [])] if spec else []
    return f"{COMMITTED_PACKAGE}.{path.stem}" if path.parent in folders else None


def load_module(path: Path):
    """The module of a generated kernel file, checked to carry valid metadata."""
    path = Path(path).resolve()
    name = _committed_name(path)
    try:
        if name is not None:
            module = importlib.import_module(name)
        else:
            name = f"tensormass_kernel_{path.stem}"
            spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            spec.loader.exec_module(module)
    except (ImportError, OSError, SyntaxError) as error:
        raise BackendError(f"{path}: cannot import the numba kernel ({error})") from None
    check_metadata(getattr(module, "METADATA", {}), path)
    return module
