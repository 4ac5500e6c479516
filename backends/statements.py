"""Printing the generator's statement tree (generator/kernel_body.py) as lines of code.

A StatementPrinter walks the tree; a language subclass says how one statement of each kind
looks (declaration, loop head, flag) and how an array element is written. Expressions go
through the language's sympy printer, which calls back here for array elements (Ref).
"""
from __future__ import annotations

from sympy.printing.str import StrPrinter


class IndexPrinter(StrPrinter):
    """Integer index expressions and loop bounds: 3*i + 1, (r // 3)*3 (or r / 3 in C)."""

    def __init__(self, division: str):
        super().__init__()
        self.division = division

    def _print_IntDiv(self, expr):
        a, b = expr.args
        return f"({self._print(a)} {self.division} {self._print(b)})"


class RefPrinting:
    """sympy-printer mixin: Ref(array, indices) printed by the statement printer that owns it."""

    ref_text = None          # set by StatementPrinter: callable(array name, index args) -> str

    def _print_Ref(self, expr):
        return self.ref_text(str(expr.args[0]), expr.args[1:])


class StatementPrinter:
    indent = "    "

    def __init__(self, expr_printer, index_printer: IndexPrinter):
        self.expr = expr_printer
        self.index = index_printer
        expr_printer.ref_text = self.ref

    # -- what a language defines -------------------------------------------------------------
    def ref(self, array: str, indices) -> str:
        raise NotImplementedError

    def declare(self, st) -> str:
        raise NotImplementedError

    def loop(self, st) -> str:
        raise NotImplementedError

    def flag(self, st) -> list[str]:
        raise NotImplementedError

    def loop_prologue(self, st) -> list[str]:
        """Lines a language adds at the top of a loop body (none by default)."""
        return []

    def flag_if(self, st) -> list[str]:
        raise NotImplementedError

    def comment(self, text: str) -> str:
        raise NotImplementedError

    loop_end: str | None = None          # the closing line of a loop, if the language has one
    terminator = ""                      # after each simple statement

    # -- shared --------------------------------------------------------------------------------
    def code(self, expr) -> str:
        return self.expr.doprint(expr)

    def target(self, expr) -> str:
        return self.expr._print(expr)

    def idx(self, expr) -> str:
        return self.index.doprint(expr)

    def lines(self, statements, depth: int) -> list[str]:
        out = []
        pad = self.indent * depth
        for st in statements:
            kind = type(st).__name__
            if kind == "Loop":
                out.append(pad + self.loop(st))
                out += [pad + self.indent + line for line in self.loop_prologue(st)]
                out += self.lines(st.body, depth + 1)
                if self.loop_end is not None:
                    out.append(pad + self.loop_end)
            elif kind == "Declare":
                out.append(pad + self.declare(st) + self.terminator)
            elif kind == "Assign":
                out.append(f"{pad}{self.target(st.target)} = {self.code(st.value)}{self.terminator}")
            elif kind == "Accumulate":
                op = "+=" if st.sign > 0 else "-="
                out.append(f"{pad}{self.target(st.target)} {op} {self.code(st.value)}{self.terminator}")
            elif kind == "Flag":
                out += [pad + line for line in self.flag(st)]
            elif kind == "FlagIf":
                out += [pad + line for line in self.flag_if(st)]
            elif kind == "Comment":
                out.append(pad + self.comment(st.text))
            else:
                raise TypeError(f"unknown statement {kind}")
        return out

    def text(self, statements, depth: int) -> str:
        return "\n".join(self.lines(statements, depth))
