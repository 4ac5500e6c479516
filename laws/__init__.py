"""Constitutive laws: one small file per law, discovered automatically.

A law file defines ``LAW = Law(...)``: the strain-energy density W(F) per unit
rest volume written with sympy, its native parameters and how they follow from
Young's modulus E and Poisson's ratio nu. Adding a law means adding one file to
this folder; nothing else has to change.

A discrete law (``LAW = DiscreteLaw(...)``: mss.py, hybmss.py) writes instead the energy of one
element in its nodal positions (springs, lattice cubes; springs.py has the pieces).

A law file outside the package works the same way without reinstalling (docs/extending.md, "A
law"): a scene names it (``law_file = "yeoh.py"`` in a [[material]], through load_file), or the
search path $TENSORMASS_LAWS lists it (folders of law files or .py files, separated like PATH).
Such a user law may not take a built-in law's name; its kernels are generated on first use into
the user cache, in a folder keyed by the file's content hash (user_law(name).digest).
"""
from __future__ import annotations

import hashlib
import importlib
import inspect
import importlib.util
import os
import pkgutil
import re
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from .base import DiscreteLaw, Law, LawError, lame_from_E_nu
from .measures import MEASURES
from . import viscous as _viscous

__all__ = ["Law", "DiscreteLaw", "LawError", "lame_from_E_nu", "get", "names", "continuum_names", "discrete_names", "shell_names",
           "is_discrete", "is_shell", "is_quadratic", "measure_names", "kernel_law", "load_file", "user_law",
           "UserLaw", "SEARCH_PATH", "source_hash", "viscous_names"]

SEARCH_PATH = "TENSORMASS_LAWS"      # folders of law files or .py files, separated by os.pathsep

# A law's name becomes part of kernel, function and file names (tetra_<law>_gauss2.c).
_NAME = re.compile(r"[a-z][a-z0-9_]*")


# The generator's own temporaries (F00, gi0, h012, t_s3, A0_1, ...): a parameter is a local variable
# of the same generated functions.
_TEMPORARY = re.compile(r"(?:F|P|J|Ji|gi|gj|h|dn|du|u|r|a|c|k|x|v|q|t_[a-z]+|A\d+_)\d*")


@lru_cache(maxsize=None)
def _reserved() -> frozenset:
    """Names a law parameter must not take: every word of the backends' templates (their variables:
    K the stiffness, e the element, ...), the keywords and builtins of the languages, and E, nu
    (the keywords of Law.native_parameters; a spring law's own parameters).  Built-in laws are written to avoid them; a user law
    is checked when it is loaded."""
    import builtins
    import keyword
    words = set()
    for template in sorted((Path(__file__).resolve().parent.parent / "backends").glob("*/templates/*.j2")):
        words.update(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", template.read_text(encoding="utf-8")))
    c_words = ("auto break case char const continue default do double else enum extern float for goto if "
               "inline int long register restrict return short signed sizeof static struct switch typedef "
               "union unsigned void volatile while").split()
    return frozenset(words | set(keyword.kwlist) | set(dir(builtins)) | set(c_words)
                     | {"E", "nu", "np", "numpy", "math", "numba", "njit", "detJ", "theta", "xi", "eta", "zeta"})


@dataclass(frozen=True)
class UserLaw:
    """A law loaded from a file outside the package."""
    law: Law
    path: Path            # the file, resolved
    digest: str           # sha256 of its bytes (16 hex digits): its kernels' folder in the user cache


# The user laws of this process, by name.  Kernels are cached per process by law name
# (runtime.kernels.kernels.load_kernel), so a name keeps one content for the life of the process.
_user: dict[str, UserLaw] = {}


@lru_cache(maxsize=None)
def _builtin() -> dict[str, Law]:
    found: dict[str, Law] = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_") or info.name == "base":
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        law = vars(module).get("LAW")         # not getattr: sympy_lazy would import sympy to look
        if isinstance(law, Law):
            found[law.name] = law
    return dict(sorted(found.items()))


def _registry(user: bool = True) -> dict[str, Law]:
    """The built-in laws and, with user, those of $TENSORMASS_LAWS and of the law files loaded."""
    if not user:
        return _builtin()
    _search_path(os.environ.get(SEARCH_PATH, ""))
    if not _user:
        return _builtin()
    return dict(sorted({**_builtin(), **{n: u.law for n, u in _user.items()}}.items()))


def load_file(path) -> Law:
    """The law a file outside the package defines (``LAW = Law(...)``), registered for this process
    under its name: what a scene's ``law_file`` and $TENSORMASS_LAWS load.

    LawError naming the file when it cannot be read or imported, defines no LAW, takes a built-in
    law's name, or gives a name that another file with other content gave in this process."""
    given = Path(path).expanduser()
    if given.suffix != ".py":
        raise LawError(f"law file {given}: not a .py file (a law file is Python defining LAW = Law(...))")
    try:
        data = given.read_bytes()
    except OSError as exc:
        raise LawError(f"law file {given}: cannot be read ({exc.strerror or exc})") from None
    resolved = given.resolve()
    digest = hashlib.sha256(data).hexdigest()[:16]
    for known in _user.values():
        if known.digest == digest and known.path == resolved:
            return known.law
    law = _import_law(resolved, digest)
    name = law.name
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise LawError(f"law file {given}: law name {name!r} must be lower-case letters, digits and "
                       "underscores, starting with a letter (it becomes part of kernel file names)")
    if name in _builtin() or name in measure_names():
        raise LawError(f"law file {given}: law {name!r} is a built-in law of tensormass; give the law in "
                       "this file another name (LAW = Law(name=...))")
    own = ("E", "nu") if law.kind != "continuum" else ()     # a spring law's parameters are E and nu
    clash = [p for p in law.inputs if p not in own and (not isinstance(p, str) or not p.isidentifier()
                                                            or p in _reserved() or _TEMPORARY.fullmatch(p))]
    if clash:
        raise LawError(f"law file {given}: parameter {clash[0]!r} of law {name!r} is a name the generated kernels "
                       f"use themselves; rename it (for example {clash[0]}_{name})")
    known = _user.get(name)
    if known is not None and known.digest != digest:
        raise LawError(f"law file {given}: law {name!r} is already loaded in this process from {known.path} "
                       "with other content; give one of them another name, or run again in a new process "
                       "after editing a law file")
    if known is None:
        _user[name] = UserLaw(law, resolved, digest)
    return law


def _import_law(path: Path, digest: str) -> Law:
    """Import a law file as a module of its own (in sys.modules: the generator hashes the module's
    source, found through the energy function's module)."""
    module_name = f"tensormass_user_law_{digest}"
    module = sys.modules.get(module_name)       # the same content from another path: the same law
    if module is None:
        spec = importlib.util.spec_from_file_location(module_name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[module_name] = module
        try:
            spec.loader.exec_module(module)
        except Exception as exc:              # whatever the user's code raises: named, with the file
            del sys.modules[module_name]
            raise LawError(f"law file {path}: importing it failed: {type(exc).__name__}: {exc}") from None
    law = getattr(module, "LAW", None)
    if not isinstance(law, Law):
        got = "no LAW" if law is None else f"LAW = {type(law).__name__}"
        raise LawError(f"law file {path}: defines {got}; a law file defines LAW = Law(name=..., parameters=..., "
                       "energy=..., from_E_nu=..., description=..., validity=...) (from tensormass.laws import Law)")
    return law


@lru_cache(maxsize=None)
def _search_path(value: str) -> tuple[str, ...]:
    """Load the law files $TENSORMASS_LAWS lists (once per value): each entry a .py file or a folder,
    whose *.py files not starting with "_" are law files."""
    loaded = []
    for entry in value.split(os.pathsep):
        if not entry.strip():
            continue
        where = Path(entry).expanduser()
        if where.is_dir():
            files = sorted(f for f in where.glob("*.py") if not f.name.startswith("_"))
        elif where.exists():
            files = [where]
        else:
            raise LawError(f"${SEARCH_PATH}: {entry}: no such file or folder")
        for file in files:
            try:
                loaded.append(load_file(file).name)
            except LawError as exc:
                raise LawError(f"${SEARCH_PATH}: {exc}"
                               + ("; in a folder of law files, name helper modules _NAME.py" if where.is_dir()
                                  and "defines no LAW" in str(exc) else "")) from None
    return tuple(loaded)


def user_law(name: str) -> UserLaw | None:
    """The file behind a user law (path, content digest); None for a built-in law or a measure."""
    _registry()
    return _user.get(name)


def names(user: bool = True) -> list[str]:
    """Names of every known law, sorted (user=False: the built-in laws only, the catalogue's)."""
    return list(_registry(user))


def continuum_names(user: bool = True) -> list[str]:
    """The laws with an energy density W(F) (the finite elements' materials), sorted."""
    return [n for n, law in _registry(user).items() if law.kind == "continuum"]


def discrete_names() -> list[str]:
    """The discrete laws (springs, lattice cubes: an element energy in nodal positions), sorted."""
    return [n for n, law in _registry().items() if law.kind == "discrete"]


def shell_names() -> list[str]:
    """The shell laws (laws/cst_dkt.py: an energy in nodal displacements and rotations), sorted."""
    return [n for n, law in _registry().items() if law.kind == "shell"]


def is_shell(name: str) -> bool:
    """True for a shell law (cst_dkt): element "shell", quadrature "exact", 6 dofs per node."""
    return name in shell_names()


def is_discrete(name: str) -> bool:
    """True for a discrete law (mss, hybmss): no W(F), no formulations, quadrature "discrete"."""
    return name in discrete_names()


def measure_names() -> list[str]:
    """The volume measures (laws/measures.py): parameter-free "laws" the generator builds kernels
    for, which the locking-free formulations use; not materials."""
    return sorted(MEASURES)


def get(name: str) -> Law:
    """The law called ``name``; a LawError naming the known laws otherwise."""
    law = _builtin().get(name)
    if law is not None:
        return law
    try:
        return _registry()[name]
    except KeyError:
        base = _viscous.base_name(name)
        if base is not None and base in continuum_names():      # a viscous part's kernel law
            return _viscous.viscous(get(base))
        raise LawError(f"unknown law {name!r}; known laws: {', '.join(names())} (a law file outside the "
                       f"package: law_file = \"FILE.py\" in the [[material]], or ${SEARCH_PATH})") from None


def kernel_law(name: str) -> Law:
    """What a kernel integrates: a law, a volume measure, or a law's viscoelastic step energy
    NAME_viscous (laws/viscous.py) (generator and kernel loader)."""
    if name in MEASURES:
        return MEASURES[name][0]
    base = _viscous.base_name(name)
    if base is not None and base in continuum_names():
        return _viscous.viscous(get(base))
    return get(name)


def viscous_names() -> list[str]:
    """NAME_viscous for every law with an energy density W(F): kernels generated on first use."""
    return [n + _viscous.SUFFIX for n in continuum_names()]


def source_hash(law: Law) -> str:
    """sha256 (16 hex digits) of the source of the file defining a law's energy: what a committed
    table derived from the law (generated/volumetric.py) is checked against."""
    h = hashlib.sha256(inspect.getsource(sys.modules[law.energy.__module__]).encode())
    for module in law.sources:                  # the files a law's energy is built from (laws/hgo2.py: hgo.py)
        h.update(inspect.getsource(sys.modules[module]).encode())
    return h.hexdigest()[:16]


@lru_cache(maxsize=None)
def is_quadratic(name: str) -> bool:
    """True when W is a homogeneous quadratic in the displacement gradient H = F - I.

    Then W_E(u) = 1/2 u.K.u with a constant K, and f_int = -K u exactly: the
    runtime assembles K once and skips the kernel at every step (Hooke).
    """
    import sympy as sp
    law = get(name)
    if law.kind != "continuum":
        return False
    H = sp.Matrix(3, 3, lambda i, j: sp.Symbol(f"H{i}{j}", real=True))
    W = law.W(sp.eye(3) + H)
    entries = list(H)
    if not W.is_polynomial(*entries):          # checked before expanding: ln J, J^(-2/3) are slow to expand
        return False
    degrees = {sum(m) for m in sp.Poly(W, *entries).monoms()}
    return degrees == {2}
