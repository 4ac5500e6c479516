"""Laws outside the package (docs/extending.md, "A law"; docs/guide/materials.md, "Your own law").

A law file named by a scene ([[material]] law_file) or by $TENSORMASS_LAWS works without
reinstalling: these are the mechanisms the documented steps use, independent of how tensormass is
installed. Its kernels are generated on first use into the user cache, in a folder keyed by the
file's content; `tensormass generate --law FILE.py` writes there.
"""
from __future__ import annotations

import hashlib
import json
import re
import textwrap
import tomllib
from pathlib import Path

import pytest

from tensormass import laws
from tensormass.apps.cli import main
from tensormass.runtime.base.errors import SceneError
from tensormass.runtime.kernels.kernels import kernel_folder, kernel_source
from tensormass.runtime.scene.scene import Scene

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "yeoh"


@pytest.fixture(autouse=True)
def _forget_user_laws(forget_user_laws):
    """Every test here: its user laws leave with it (conftest.forget_user_laws)."""


def _backend() -> str:
    from tensormass.backends.c.loader import compiler
    try:
        compiler()
    except Exception:
        return "numba"
    return "c"


# Linear elasticity written with the shear and bulk moduli: Hooke with mu = shear,
# lam = bulk - 2/3 shear. Quadratic, so its kernels take well under a second to generate.
LINEAR = '''
import sympy as sp

from tensormass.laws import Law


def energy(F, shear, bulk):
    H = F - sp.eye(3)
    eps = (H + H.T) / 2
    tr = eps.trace()
    return shear * ((eps * eps).trace() - tr ** 2 / 3) + bulk / 2 * tr ** 2


LAW = Law(name=NAME, parameters=("shear", "bulk"), energy=energy,
          from_E_nu=lambda E, nu: {"shear": E / (2 * (1 + nu)), "bulk": E / (3 * (1 - 2 * nu))},
          description="linear elasticity in shear and bulk moduli", validity="small strains")
'''


def _law_file(folder: Path, name: str, text: str = LINEAR, file: str | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / (file or f"{name}.py")
    path.write_text(text.replace("NAME", repr(name)), encoding="utf-8")
    return path


def _pull_scene(material: str, backend: str) -> str:
    """A 1 cm cube of 6 tetrahedra clamped at x = 0 and pulled by 1 um at x = 1 cm."""
    return textwrap.dedent('''
        [mesh]
        generate = "bar"
        element = "tetra"
        size = [0.01, 0.01, 0.01]
        cells = [1, 1, 1]
        [[material]]
        quadrature = "gauss1"
        MATERIAL
        [[fixed]]
        name = "clamp"
        box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
        [[fixed]]
        name = "pull"
        box = [[0.00999, -1, -1], [1, 1, 1]]
        displacement = [1.0e-6, 0.0, 0.0]
        [solver]
        kind = "static"
        steps = 1
        backend = "BACKEND"
        ''').replace("MATERIAL", material).replace("BACKEND", backend)


def _run(scene: Path, tmp_path: Path, tag: str) -> dict:
    """`tensormass run SCENE` (in this process); the pull reaction's x force of its summary."""
    summary = tmp_path / f"{tag}.json"
    code = main(["run", str(scene), "--out", str(tmp_path / f"out_{tag}"), "--quiet", "--json", str(summary)])
    assert code == 0, tag
    return json.loads(summary.read_text())


def _pull(summary: dict) -> float:
    return summary["reactions"]["pull"]["force"][0]


# -- the documented steps --------------------------------------------------------------------------

def _docs_blocks(lang: str) -> list[str]:
    text = (ROOT / "docs" / "extending.md").read_text(encoding="utf-8")
    section = text[text.index("## A law\n"):text.index("A **discrete law**")]
    return [textwrap.dedent(m.group(2)) for m in re.finditer(r"^( *)```" + lang + r"\n(.*?)^\1```", section, re.M | re.S)]


def test_the_documented_law_file_is_the_example():
    """The docs show examples/yeoh/yeoh.py verbatim, and the [[material]] of its scene."""
    law_text = next(b for b in _docs_blocks("python") if b.startswith("# yeoh.py"))
    assert law_text == (EXAMPLE / "yeoh.py").read_text(encoding="utf-8")
    fragment = tomllib.loads(next(b for b in _docs_blocks("toml") if "law_file" in b))["material"][0]
    scene = tomllib.loads((EXAMPLE / "pull.toml").read_text(encoding="utf-8"))["material"][0]
    assert fragment == scene
    assert "tensormass run examples/yeoh/pull.toml\n" in _docs_blocks("bash")


def test_the_documented_steps_run_and_yeoh_is_hooke_at_small_strain(tmp_path, monkeypatch):
    """`tensormass run examples/yeoh/pull.toml` from the checkout (the docs' command, with --out):
    the law file is found through law_file, its kernels land in the user cache under the file's
    content hash, and at 1e-4 strain its reaction is Hooke's for the same E and nu."""
    monkeypatch.chdir(ROOT)
    yeoh = _run(Path("examples/yeoh/pull.toml"), tmp_path, "yeoh")
    digest = hashlib.sha256((EXAMPLE / "yeoh.py").read_bytes()).hexdigest()[:16]
    assert kernel_folder("yeoh").name == f"yeoh-{digest}"
    assert list(kernel_folder("yeoh").glob("*/tetra_yeoh_gauss1.*")), "the kernel is not in the user cache"
    hooke_text = (EXAMPLE / "pull.toml").read_text(encoding="utf-8").replace('law_file = "yeoh.py"', 'law = "hooke"')
    assert 'law = "hooke"' in hooke_text
    (tmp_path / "hooke.toml").write_text(hooke_text, encoding="utf-8")
    hooke = _run(tmp_path / "hooke.toml", tmp_path, "hooke")
    assert _pull(hooke) > 0
    assert _pull(yeoh) == pytest.approx(_pull(hooke), rel=1e-3)
    assert _pull(yeoh) != _pull(hooke)            # a law of its own, not Hooke's kernels


# -- the search path, and the formulations -----------------------------------------------------------

def test_search_path_law_runs_like_hooke_and_with_nodal_pressure(tmp_path, monkeypatch):
    folder = tmp_path / "my_laws"
    _law_file(folder, "tl_linear_search")
    monkeypatch.setenv(laws.SEARCH_PATH, str(folder))
    backend = _backend()
    shear, bulk = 3.0e5, 9.0e5
    runs = {}
    for tag, material in (("user", f'law = "tl_linear_search"\nshear = {shear}\nbulk = {bulk}'),
                          ("hooke", f'law = "hooke"\nmu = {shear}\nlam = {bulk - 2 * shear / 3}'),
                          ("nodal", f'law = "tl_linear_search"\nshear = {shear}\nbulk = {bulk}\n'
                                    'formulation = "nodal_pressure"')):
        scene = tmp_path / f"{tag}.toml"
        scene.write_text(_pull_scene(material, backend), encoding="utf-8")
        runs[tag] = _pull(_run(scene, tmp_path, tag))
    assert runs["hooke"] > 0
    assert runs["user"] == pytest.approx(runs["hooke"], rel=1e-9)
    # Averaging the volumetric energy over node patches relaxes it (Jensen): never stiffer.
    assert 0 < runs["nodal"] <= runs["user"] * (1 + 1e-12)


def test_search_path_errors_name_the_entry(tmp_path, monkeypatch):
    monkeypatch.setenv(laws.SEARCH_PATH, str(tmp_path / "nowhere"))
    with pytest.raises(laws.LawError, match=r"^\$TENSORMASS_LAWS: .*nowhere: no such file or folder"):
        laws.names()
    folder = tmp_path / "folder"
    _law_file(folder, "tl_helper_ok")
    (folder / "helpers.py").write_text("X = 1\n", encoding="utf-8")
    monkeypatch.setenv(laws.SEARCH_PATH, str(folder))
    with pytest.raises(laws.LawError, match=r"helpers\.py: defines no LAW.*name helper modules _NAME\.py"):
        laws.get("tl_helper_ok")


# -- errors of a scene's law_file ---------------------------------------------------------------------

BAD_FILES = [
    ("builtin", LINEAR.replace("name=NAME", 'name="neohookean"'),
     r"law 'neohookean' is a built-in law of tensormass; give the law in this file another name"),
    ("nolaw", "import sympy\nTHE_LAW = 1\n", r"defines no LAW; a law file defines LAW = Law\("),
    ("syntax", "def energy(F:\n", r"importing it failed: SyntaxError"),
    ("raises", "raise RuntimeError('no sympy here')\n", r"importing it failed: RuntimeError: no sympy here"),
    ("reserved", LINEAR.replace('"bulk"', '"K"').replace("bulk", "K"),
     r"parameter 'K' of law 'tl_bad_reserved' is a name the generated kernels use"),
]


@pytest.mark.parametrize("tag, text, message", BAD_FILES, ids=[b[0] for b in BAD_FILES])
def test_a_bad_law_file_is_refused_naming_it(tmp_path, tag, text, message):
    _law_file(tmp_path, f"tl_bad_{tag}", text, file="mylaw.py")
    scene = _pull_scene('law_file = "mylaw.py"\nE = 1.0e6\nnu = 0.3', "numba")
    with pytest.raises(SceneError, match=r"^material\[0\]\.law_file: law file .*mylaw\.py: " + message):
        Scene.from_string(scene, base_dir=tmp_path, load_mesh=False)


def test_law_file_errors_in_a_scene(tmp_path, capsys):
    scene = _pull_scene('law_file = "missing.py"\nE = 1.0e6\nnu = 0.3', "numba")
    (tmp_path / "scene.toml").write_text(scene, encoding="utf-8")
    assert main(["run", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "material[0].law_file: law file not found:" in err and "missing.py" in err
    assert not (tmp_path / "out").exists()
    _law_file(tmp_path, "tl_mismatch")
    scene = _pull_scene('law = "hooke"\nlaw_file = "tl_mismatch.py"\nE = 1.0e6\nnu = 0.3', "numba")
    with pytest.raises(SceneError, match=r"^material\[0\]\.law: 'hooke', but material\[0\]\.law_file "
                                         r"'tl_mismatch\.py' defines law 'tl_mismatch'"):
        Scene.from_string(scene, base_dir=tmp_path, load_mesh=False)


def test_a_law_file_is_keyed_by_its_content(tmp_path):
    """The kernels' folder is named by the file's content hash; within one process a law name
    keeps one content (kernels are cached by name), so another content is refused."""
    first = _law_file(tmp_path / "a", "tl_keyed")
    law = laws.load_file(first)
    digest = hashlib.sha256(first.read_bytes()).hexdigest()[:16]
    assert kernel_folder("tl_keyed").name == f"tl_keyed-{digest}"
    assert laws.load_file(first) is law and "tl_keyed" in laws.names() and "tl_keyed" not in laws.names(user=False)
    edited = _law_file(tmp_path / "b", "tl_keyed", LINEAR.replace("bulk / 2", "bulk / 3"))
    with pytest.raises(laws.LawError, match=r"law 'tl_keyed' is already loaded in this process from .*a.tl_keyed\.py "
                                            r"with other content"):
        laws.load_file(edited)
    same = _law_file(tmp_path / "c", "tl_keyed")           # the same content elsewhere: the same law
    assert laws.load_file(same) is law


# -- generate --law ---------------------------------------------------------------------------------

def test_generate_law_file_writes_where_runs_look(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("TENSORMASS_CACHE", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    path = _law_file(tmp_path, "tl_generated")
    assert main(["generate", "--law", str(path), "--element", "tetra", "--quadrature", "gauss1",
                 "--backend", "numba", "--no-compile"]) == 0
    folder = kernel_folder("tl_generated")
    assert folder.is_relative_to(tmp_path / "cache") and str(folder) in capsys.readouterr().out
    written = folder / "numba" / "tetra_tl_generated_gauss1.py"
    assert written.is_file() and not (tmp_path / "tensormass-kernels").exists()
    stamp = written.stat().st_mtime_ns
    assert kernel_source("tetra", "tl_generated", "gauss1", "numba") == written     # what a run loads
    assert written.stat().st_mtime_ns == stamp                                       # not generated again
