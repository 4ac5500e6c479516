"""The `tensormass` command line.

    tensormass list                               the catalogue, with op and constant counts
    tensormass generate --element tetra --law stvk --quadrature gauss1 --backend numba --out DIR
    tensormass generate --check                   regenerate the catalogue and diff it with generated/
    tensormass run SCENE.toml [--json SUMMARY]    simulate a scene
    tensormass demo                               the embedded default scene (a mixed bar under gravity)
    tensormass bench kernels|compile|steps        kernel throughput against a classic loop; compile budget; steps
    tensormass bench organ|history|formulations   gmsh organs and solvers; history cost; formulations' cost
    tensormass bench laws                         a step with Prony branches or fibres against the elastic one
    tensormass report accuracy|stability --out D  error against run time; stiff and extreme cases
    tensormass plot SUMMARY.json [-o PNG]         history curves of a run (probes, energies, reactions, solver)
    tensormass batch SCENES... [--vary K=V,..]    scenes x variations as tasks on dask.distributed, one table

Every ending is an exit code and at most one line on stderr (README, "Exit codes"):
0 done; 1 internal error (a bug: `tensormass: internal error: ...`, the traceback
with TENSORMASS_DEBUG=1); 2 bad input or environment (`tensormass: error: ...`
naming the problem: scene, mesh, paths, cache, disk full); 3 a run that stopped
or ended outside the trusted region; 130 interrupted (Ctrl-C), without a traceback.
"""
from __future__ import annotations

import argparse
import filecmp
import importlib
import importlib.util
import json
import os
import sys
import tempfile
import time
import traceback
from pathlib import Path

from .. import generated
from ..backends import BACKENDS
from ..generator import GENERATOR_VERSION
from ..runtime.base.errors import EXIT_BAD_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED, RunStopped, TensormassError
from ..runtime.base.cache import writable_cache_dir
from ..runtime.base.files import check_writable
from .commands import add_commands

# The commands whose modules import sympy, numba or the runtime at the top. Each one's parser is
# built only when the command line names it (or in full for the docs: build_parser()); otherwise a
# stub with the same help lists it, so `tensormass --help` and `tensormass run` start without them.
# Measured with `python -X importtime`, 2 shared cores: `tensormass --help` imports this module in
# 0.19 s; the commands' modules add generate (generator, sympy) 0.55 s, bench (numba, kernels,
# runtime) 1.9 s, report 0.7 s, batch 0.17 s, plot 0.2 s.
# name -> (module, function that adds its parser, help)
DEFERRED = {
    "generate": (".cli", "add_generate_command", "generate element x law x quadrature kernels"),
    "batch": (".batch", "add_batch_command",
              "run scene files x parameter variations as independent tasks (dask.distributed) into one table"),
    "bench": (".bench", "add_bench_command", "benchmark the kernels (speed, compile budget)"),
    "report": (".reports", "add_report_command",
               "accuracy against run time; stability on stiff and extreme cases"),
    "plot": (".plot", "add_plot_command", "draw the per-step history of a run summary (JSON) as a PNG"),
    "mesh": (".mesh_tools", "add_mesh_command", "mesh tools: simplify a surface (precision alpha), regenerate a volume"),
    "view": (".view", "add_view_command", "watch a scene run live in a browser and pull it with the mouse "
                                          "(needs tensormass[view])"),
}


def committed_dir() -> Path:
    """The generated/ folder of this installation (the committed catalogue)."""
    return Path(generated.__file__).resolve().parent


def _names(values, known, kind):
    """Flatten repeated/comma-separated options; 'all' or nothing means every known name."""
    if not values:
        return None
    flat = [v for value in values for v in value.split(",") if v]
    return None if "all" in flat else flat


def cmd_list(args) -> int:
    from .. import laws                    # deferred: 0.01 s, only for the list of law names
    from ..generator.elements import ELEMENTS      # deferred: sympy, 0.52 s
    from ..runtime.kernels import catalogue          # deferred: numpy, only for this command
    manifest = {r["name"]: r for r in catalogue.committed().values()}
    rows = [("entry", "points", "constants", "ops energy", "ops forces", "ops f+K", "backends")]
    for key, r in sorted(manifest.items()):
        rows.append((key, r["points"], r["constants"], r["ops"]["energy"], r["ops"]["forces"],
                     r["ops"]["forces_and_stiffness"], ",".join(sorted(r["files"]))))
    widths = [max(len(str(row[i])) for row in rows) for i in range(len(rows[0]))]
    for row in rows:
        print("  ".join(str(c).ljust(w) if i == 0 else str(c).rjust(w) for i, (c, w) in enumerate(zip(row, widths))))
    print(f"{len(manifest)} entries; elements: {', '.join(ELEMENTS)}; laws: {', '.join(laws.names())}")
    return 0


def cmd_generate(args) -> int:
    from ..generator import shape_tables, volumetric             # deferred: sympy, jinja2, 0.55 s
    from ..generator.catalogue import COMMITTED_VISCOUS, catalogue_laws, entries
    from ..generator.elements import ELEMENTS
    from ..generator.pipeline import generate_all
    from .. import laws
    from ..runtime.kernels.kernels import kernel_folder
    # --law takes names and law files (FILE.py: a law outside the package, laws.load_file);
    # no --law: the whole catalogue of built-in laws, the formulations' volume-measure kernels too
    law_names = [laws.load_file(v).name if v.endswith(".py") else v for v in _names(args.law, None, "law") or []]
    elements, quadratures = _names(args.element, ELEMENTS, "element"), _names(args.quadrature, None, "quadrature")
    selected = entries(elements, law_names or catalogue_laws(user=False), quadratures)
    if not law_names:                      # the committed viscous step kernels (generator.catalogue)
        selected = sorted(selected + [e for e in COMMITTED_VISCOUS if (elements is None or e.element in elements)
                                      and (quadratures is None or e.quadrature in quadratures)])
    backends = _names(args.backend, BACKENDS, "backend") or list(BACKENDS)
    unknown = sorted(set(backends) - set(BACKENDS))
    if unknown:
        raise ValueError(f"unknown backend {', '.join(unknown)}; known: {', '.join(BACKENDS)}")
    if args.check:
        return check(selected, backends)
    # Without --out, a user law's kernels go where runs look for them: the user cache, in the
    # folder of the law file's content (runtime.kernels.kernels.kernel_folder).
    user = sorted({e.law for e in selected if laws.user_law(e.law)}) if args.out is None else []
    builtin = [e for e in selected if e.law not in user]
    out = _output_folder(args.out if args.out is not None else "tensormass-kernels") if builtin else None
    for law in user:
        folder = writable_cache_dir(kernel_folder(law), f"generate --law {law}")
        law_entries = [e for e in selected if e.law == law]
        generate_all(law_entries, backends, folder, constants=args.constants)
        if "numba" in backends and not args.no_compile and args.constants == "precompute":
            report_numba_compile_times(law_entries, folder)
        print(f"law {law!r} ({laws.user_law(law).path}): kernels in the user cache, {folder}; runs that "
              f"load this file (law_file in a [[material]], or ${laws.SEARCH_PATH}) use them")
    if builtin:
        generate_all(builtin, backends, out, constants=args.constants)
        shape_tables.write(out)            # N, dN/dxi for consistent loads and masses (runtime/assembly/loads.py)
        volumetric.write(out)              # U(theta) of every built-in law, for the locking-free formulations
        if "numba" in backends and not args.no_compile and args.constants == "precompute":
            report_numba_compile_times(builtin, out)
        if args.out is None:
            print(f"runs read the kernels of built-in laws from this installation ({committed_dir()}), not "
                  f"from {out}; in a checkout, --out generated replaces the committed ones")
    return 0


def _output_folder(path) -> Path:
    """The --out folder of `generate`, checked before anything is generated: a folder (or a
    name still free) where this process may write."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise TensormassError(f"--out {out}: exists and is not a folder; give a folder for the generated kernels")
    check_writable(out, "--out")
    return out


def check(selected, backends) -> int:
    """Regenerate into a temporary folder and compare byte for byte with generated/."""
    from ..generator import shape_tables, volumetric             # deferred: sympy, jinja2, 0.55 s
    from ..generator.pipeline import generate_all
    committed = committed_dir()
    with tempfile.TemporaryDirectory() as tmp:
        generate_all(selected, backends, Path(tmp))
        shape_tables.write(Path(tmp))      # compared below like every generated file
        volumetric.write(Path(tmp))
        fresh = Path(tmp)
        differing = []
        for path in sorted(fresh.rglob("*")):
            if path.is_file() and path.name != "manifest.json":
                rel = path.relative_to(fresh)
                old = committed / rel
                if not old.exists() or not filecmp.cmp(path, old, shallow=False):
                    differing.append(str(rel))
        fresh_manifest = json.loads((fresh / "manifest.json").read_text())["entries"]
        old_manifest = json.loads((committed / "manifest.json").read_text())["entries"]
        for key, record in fresh_manifest.items():
            if old_manifest.get(key) != record:
                differing.append(f"manifest.json[{key}]")
    if differing:
        print(f"generated/ is out of date: {len(differing)} file(s) differ:", file=sys.stderr)
        for name in differing:
            print(f"  {name}", file=sys.stderr)
        print("regenerate with: tensormass generate --out generated", file=sys.stderr)
        return 1
    print(f"generated/ is up to date ({len(selected)} entries, backends {', '.join(backends)})")
    return 0


def report_numba_compile_times(selected, out: Path) -> None:
    """Import each generated numba module from `out` and time the first call of every kernel."""
    import numpy as np                     # with the generator: generate only
    from ..generator.elements import element
    slowest = (0.0, "")
    for entry in selected:
        path = out / "numba" / f"{entry.name}.py"
        spec = importlib.util.spec_from_file_location(f"_tm_compile_{entry.name}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        X = np.array([[float(x) for x in node] for node in element(entry.element).nodes])[None].copy()
        params = np.ones((1, len(module.METADATA["parameters"])))
        D = np.empty((1, module.METADATA["n_constants"]))
        flags = np.zeros(1, dtype=np.int32)
        u = np.zeros_like(X)
        n = module.METADATA["n_dofs"]
        t0 = time.perf_counter()
        module.constants(X, params, D, flags)
        module.energy(D, u, np.empty(1), flags)
        module.forces(D, u, np.empty((1, n)), flags)
        module.stiffness(D, u, np.empty((1, n, n)), flags)
        module.forces_and_stiffness(D, u, np.empty((1, n)), np.empty((1, n, n)), flags)
        seconds = time.perf_counter() - t0
        slowest = max(slowest, (seconds, entry.name))
        print(f"numba first call (compile) {entry.name}: {seconds:.2f} s")
    if selected:
        print(f"slowest numba compile: {slowest[1]} {slowest[0]:.2f} s")


def add_generate_command(subparsers) -> None:
    """Add `generate` (its help lists the elements and laws: the generator, with sympy, is imported)."""
    from ..generator.catalogue import catalogue_laws
    from ..generator.elements import ELEMENTS
    p = subparsers.add_parser("generate", help=DEFERRED["generate"][2])
    p.add_argument("--element", nargs="+", help=f"element(s) or all: {', '.join(ELEMENTS)}")
    p.add_argument("--law", nargs="+", help=f"law(s), volume measure(s), law files (FILE.py) or all (the default): "
                                            f"{', '.join(catalogue_laws())}")
    p.add_argument("--quadrature", nargs="+", help="quadrature(s) or all: gauss1 gauss2 gauss3 exact")
    p.add_argument("--backend", nargs="+", help=f"backend(s) or all: {', '.join(BACKENDS)}")
    p.add_argument("--out", help="output folder (default: a law file's kernels into the user cache, where runs "
                                 "look; the built-in laws' into ./tensormass-kernels)")
    p.add_argument("--constants", choices=("precompute", "recompute"), default="precompute",
                   help="precompute: shape gradients and det J per point stored per element (default, the catalogue); "
                        "recompute: store rest coordinates and recompute the geometry at every call")
    p.add_argument("--check", action="store_true", help="regenerate into a temporary folder and diff with generated/")
    p.add_argument("--no-compile", action="store_true", help="skip timing numba's first-call compilation")
    p.set_defaults(run=cmd_generate)


def build_parser(full=None) -> argparse.ArgumentParser:
    """The whole command line. full: the names of DEFERRED commands to build in full (None: all of
    them, as the docs need); the others are stubs with their help only (see DEFERRED)."""
    parser = argparse.ArgumentParser(prog="tensormass", description=__doc__.split("\n\n")[0])
    parser.add_argument("--version", action="version", version=f"tensormass {GENERATOR_VERSION}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("list", help="list the kernel catalogue with op and constant counts")
    p.set_defaults(run=cmd_list)
    # the order of `tensormass --help`: generate, run, demo, batch, bench, report, plot
    _add_deferred(sub, "generate", full)
    add_commands(sub)                      # run, demo
    for name in ("batch", "bench", "report", "plot", "mesh", "view"):
        _add_deferred(sub, name, full)     # batch: dask; bench: kernels, compile, steps, ...; report; plot; mesh
    return parser


def _add_deferred(sub, name: str, full) -> None:
    module, adder, help_text = DEFERRED[name]
    if full is None or name in full:
        getattr(importlib.import_module(module, __package__), adder)(sub)
    else:
        sub.add_parser(name, help=help_text, add_help=False)


def named_command(argv) -> str | None:
    """The command an argument list names: its first word that is not an option (the top-level
    parser has only --help and --version, neither takes a value)."""
    return next((a for a in argv if not a.startswith("-")), None)


def main(argv=None) -> int:
    """Run one command and turn every way it can end into an exit code and one line on stderr."""
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        args = build_parser(full={named_command(argv)}).parse_args(argv)
        return args.run(args)
    except KeyboardInterrupt:
        return _say("interrupted", EXIT_INTERRUPTED)
    except RunStopped as stop:                # a command that let a stopped run through (runs print their own)
        return _say(f"run {stop.status}: {stop}", stop.exit_code)
    except (TensormassError, ValueError) as error:
        return _say(f"error: {error}", EXIT_BAD_INPUT)
    except OSError as error:                  # disk full, permissions, read-only file systems
        return _say(f"error: {_os_error(error)}", EXIT_BAD_INPUT)
    except MemoryError:
        return _say("error: out of memory (try a smaller mesh or fewer steps, or free memory)", EXIT_BAD_INPUT)
    except Exception as error:                # a bug: one line, the traceback only on request
        if os.environ.get("TENSORMASS_DEBUG", "") not in ("", "0"):
            traceback.print_exc()
        return _say(f"internal error: {type(error).__name__}: {error} (set TENSORMASS_DEBUG=1 for the traceback)",
                    EXIT_INTERNAL)


def _say(text: str, code: int) -> int:
    print(f"tensormass: {text}", file=sys.stderr)
    return code


def _os_error(error: OSError) -> str:
    """'PATH: No space left on device' (the file first, as a user looks for it)."""
    what = error.strerror or str(error)
    names = [str(n) for n in (error.filename, error.filename2) if n is not None]
    return f"{' -> '.join(names)}: {what}" if names else what


if __name__ == "__main__":
    sys.exit(main())
