"""Sphinx extension: the reference pages generated from the code at build time.

Directives (used in the MyST pages of docs/reference/):

    ```{tm-scene-keys}
    ```                      every scene table and key (runtime.scene.keys, checked against the parser)
    ```{tm-cli}
    ```                      every command and option of `tensormass` (apps.cli.build_parser, walked)
    ```{tm-fields}
    ```                      the output fields (runtime.physics.fields.FIELDS)
    ```{tm-catalogue} laws | elements | formulations | kernels
    ```                      laws/, elements/, runtime.physics.formulations, generated/manifest.json

Each directive writes Markdown and hands it to the page's own parser (MyST parses nested
content as Markdown), so the generated tables look like the hand-written ones.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from docutils.parsers.rst import Directive, directives
from docutils.statemachine import StringList

ROOT = Path(__file__).resolve().parents[2]


def _cell(text) -> str:
    """One Markdown table cell: pipes escaped, line breaks folded."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _code(text) -> str:
    return f"`{text}`" if text not in ("", None) else ""


def _table(header, rows) -> list:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return lines + [""]


class _Markdown(Directive):
    """A directive whose output is Markdown text made by lines()."""
    has_content = False
    optional_arguments = 1

    def lines(self) -> list:
        raise NotImplementedError

    def run(self):
        from docutils import nodes
        container = nodes.container()
        self.state.nested_parse(StringList(self.lines(), source="tensormass_docs"), self.content_offset, container)
        return container.children


# -- scene keys ------------------------------------------------------------------------------------

def _default(key) -> str:
    from tensormass.runtime.scene.keys import NO_DEFAULT, REQUIRED
    if key.default_text is not None:
        return key.default_text
    if key.default == REQUIRED:
        return "**required**"
    if key.default == NO_DEFAULT:
        return "none"
    value = key.default
    if isinstance(value, bool):
        return _code("true" if value else "false")
    if isinstance(value, tuple):
        return _code("[" + ", ".join(repr(v) for v in value) + "]")
    if isinstance(value, str):
        return _code(f'"{value}"')
    return _code(repr(value))


def scene_key_lines() -> list:
    from tensormass.runtime.scene.keys import MATERIAL_LAW_PARAMETERS, TABLES, allowed_values, keys_of
    out = []
    for table in TABLES:
        title = "top level" if not table.name else (f"[[{table.name}]]" if table.array else f"[{table.name}]")
        anchor = "scene-key-top" if not table.name else "scene-key-" + table.name.replace(".", "-")
        out += [f"({anchor})=", f"### `{title}`" if table.name else "### top level", "", table.doc, ""]
        rows = []
        for key in keys_of(table.name):
            values = allowed_values(key)
            rows.append((_code(key.name), key.type, _default(key), key.unit,
                         ", ".join(_code(v) for v in values) if values else "", key.doc))
        if table.name == "material":
            rows.append(("*law parameters*", "number", "", "", "", MATERIAL_LAW_PARAMETERS))
        out += _table(("key", "type", "default", "unit", "allowed values", "meaning"), rows)
    return out


class SceneKeys(_Markdown):
    def lines(self):
        return scene_key_lines()


# -- command line ------------------------------------------------------------------------------------

def _subcommands(parser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                yield name, helps.get(name, ""), sub


def _option_rows(parser) -> list:
    rows = []
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        names = ", ".join(action.option_strings) if action.option_strings else action.dest.upper()
        default = action.default
        if default in (None, False, argparse.SUPPRESS) or isinstance(action, argparse._VersionAction):
            default = ""
        choices = ", ".join(str(c) for c in action.choices) if action.choices else ""
        help_text = (action.help or "") % {"default": action.default, "prog": parser.prog} if action.help else ""
        rows.append((_code(names), help_text, _code(default) if default != "" else "", choices))
    return rows


def cli_lines() -> list:
    from tensormass.apps.cli import build_parser
    out = []

    def walk(parser, words, help_text):
        subs = list(_subcommands(parser))
        command = " ".join(words)
        out.extend([f"### `{command}`", ""])
        if help_text:
            out.extend([help_text[0].upper() + help_text[1:] + ("" if help_text.endswith(".") else "."), ""])
        if parser.description and parser.description != help_text:
            out.extend([" ".join(parser.description.split()), ""])
        usage = " ".join(parser.format_usage().split())
        out.extend(["```text", usage.removeprefix("usage: "), "```", ""])
        rows = _option_rows(parser)
        if rows:
            out.extend(_table(("option", "what it does", "default", "choices"), rows))
        for name, sub_help, sub in subs:
            walk(sub, words + [name], sub_help or "")

    parser = build_parser()
    parser.prog = "tensormass"
    walk(parser, ["tensormass"], "")
    return out


class Cli(_Markdown):
    def lines(self):
        return cli_lines()


# -- fields --------------------------------------------------------------------------------------------

def field_lines() -> list:
    from tensormass.runtime.physics.fields import DEFAULT_FIELDS, FIELDS
    rows = [(_code(f.name), f.unit, f.kind, " and ".join(f"{w} data" for w in f.where),
             "yes" if f.name in DEFAULT_FIELDS else "", f.description) for f in FIELDS.values()]
    return _table(("name", "unit", "kind", "written as", "default", "what it is"), rows)


class Fields(_Markdown):
    def lines(self):
        return field_lines()


# -- catalogue -------------------------------------------------------------------------------------------

def _manifest() -> dict:
    return json.loads((ROOT / "generated" / "manifest.json").read_text())["entries"]


def law_lines() -> list:
    from tensormass import laws
    entries = _manifest()
    rows = []
    for name in laws.names(user=False):      # the published catalogue: never the builder's $TENSORMASS_LAWS
        law = laws.get(name)
        options = {o: d for o, d, _ in getattr(law, "options", ())}
        params = ", ".join(p + (f" (default {options[p]:g})" if options.get(p) is not None else "")
                           for p in dict.fromkeys(tuple(law.parameters) + tuple(options)))
        directions = getattr(law, "directions", ())
        if directions:                       # given per cell by [[material]] fibres
            params += f"; fibre direction{'s' if len(directions) > 1 else ''} {', '.join(directions)} (fibres)"
        mine = [e for e in entries.values() if e["law"] == name]
        elements = sorted({e["element"] for e in mine})
        quadratures = sorted({e["quadrature"] for e in mine})
        rows.append((_code(name), law.kind, params, ", ".join(elements) or "(generated on first use)",
                     ", ".join(quadratures), getattr(law, "description", "")))
    return _table(("law", "kind", "native parameters", "committed kernels on", "quadratures", "what it is"), rows)


def element_lines() -> list:
    from tensormass import elements
    rows = []
    for name in elements.names():
        e = elements.get(name)
        rows.append((_code(name), e.dim, ", ".join(str(d) for d in e.space_dims), len(e.nodes), e.order,
                     e.dofs_per_node or "space dimension", e.refinement or "", e.description))
    return _table(("element", "dimension", "space dimensions", "nodes", "order", "dofs per node",
                   "refinement", "what it is"), rows)


def formulation_lines() -> list:
    from tensormass.runtime.physics.formulations import FORMULATIONS, LOCKING_FREE
    rows = [(_code(name), "every element" if els is None else ", ".join(els),
             ", ".join(e for e, f in LOCKING_FREE.items() if f == name)) for name, els in FORMULATIONS.items()]
    return _table(("formulation", "elements", "the locking-free choice for"), rows)


def kernel_lines() -> list:
    entries = _manifest()
    table: dict = {}
    for e in entries.values():
        table.setdefault((e["element"], e["law"]), []).append(e["quadrature"])
    rows = [(_code(el), _code(law), ", ".join(sorted(q))) for (el, law), q in sorted(table.items())]
    return [f"{len(entries)} committed entries (`generated/manifest.json`), each in every backend.", ""] + \
        _table(("element", "law or measure", "quadratures"), rows)


class Catalogue(_Markdown):
    required_arguments = 1
    optional_arguments = 0

    def lines(self):
        what = self.arguments[0]
        makers = {"laws": law_lines, "elements": element_lines, "formulations": formulation_lines,
                  "kernels": kernel_lines}
        if what not in makers:
            raise self.error(f"tm-catalogue: unknown part {what!r}; known: {', '.join(makers)}")
        return makers[what]()


def setup(app):
    directives.register_directive("tm-scene-keys", SceneKeys)
    directives.register_directive("tm-cli", Cli)
    directives.register_directive("tm-fields", Fields)
    directives.register_directive("tm-catalogue", Catalogue)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
