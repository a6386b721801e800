"""What xacro may do while it expands a user's file (an automation script, a cell's robot
description): no code, no files beyond its read rule, no environment, bounded work.

xacro evaluates ``${...}`` with Python's ``eval`` and ``$(...)`` with substitution commands
that read the environment (``env``, ``optenv``), the file system (``find``, ``dirname``,
``cwd``, ``xacro.load_yaml``) or run an unrestricted ``eval`` (``$(eval ...)``). A script
or a cell file may come from someone else, so during the expansion of either
:func:`sandboxed` replaces those entry points:

* expressions go through :mod:`recon_cli.scripts.expressions` (checked, guarded, bounded);
* ``$(arg ...)`` and ``$(eval ...)`` (the same checked evaluator) are the only substitution
  commands; ``env``, ``optenv``, ``find``, ``dirname`` and ``cwd`` are refused;
* ``xacro:include`` reads only the files the caller resolved and checked beforehand (by
  their read rule, :mod:`.readable`), whatever an expression or ``xacro:element`` makes;
* the expansion is bounded in macro nesting, evaluated elements, evaluated text and time.

Every refusal is a :class:`~recon_cli.errors.LimitError` that names the limit; the loader
adds the file:line of the element or macro call being expanded.

:func:`readable` is the one rule for every file a script names to read (included files,
``xacro.load_yaml``, realism profiles, object and reference meshes, loaded images and
clouds), at validation and when the command runs.
"""

from __future__ import annotations

import contextlib
import io
import threading
import xml.dom
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from recon_cli.expansion import expressions as X
from recon_cli.expansion.expressions import LIMITS, Limits, SandboxError, safe_eval
from recon_cli.expansion.readable import ReadRule, readable, readable_roots

PI_TARGET = "recon-src"  # processing instruction placed before macro calls: <?recon-src file:line?>
__all__ = ["LIMITS", "PI_TARGET", "Frames", "Limits", "ReadRule", "SandboxError", "readable", "readable_roots",
           "sandboxed"]


# --------------------------------------------------------------------- substitution args
_SUBST_REFUSED = {
    "env": "$(env ...) reads the environment", "optenv": "$(optenv ...) reads the environment",
    "find": "$(find ...) looks up packages on this machine", "dirname": "$(dirname) reveals file-system paths",
    "cwd": "$(cwd) reveals file-system paths",
}


def eval_extension(text: str):
    """Drop-in for ``xacro.eval_extension``: only ``$(arg name)`` and ``$(eval expr)``."""
    import xacro

    X.current_guard().tick()
    inner = text[2:-1].strip()
    command, _, rest = inner.partition(" ")
    rest = rest.strip()
    args = xacro.substitution_args_context.get("arg", {})
    if command == "arg":
        if rest not in args:
            raise SandboxError(f"$(arg {rest}) is not defined",
                               hint=f'declare it: <xacro:arg name="{rest}" default="..."/>')
        return args[rest]
    if command == "eval":
        symbols = xacro.NameSpace(parent=xacro._global_symbols)
        for k, v in args.items():
            symbols._setitem(k, v, unevaluated=False)
        return str(safe_eval(rest, symbols))
    if command in _SUBST_REFUSED:
        raise SandboxError(f"{_SUBST_REFUSED[command]}; scripts may not use it",
                           hint="use a xacro:property or xacro:arg instead")
    raise SandboxError(f"unknown substitution $({command} ...)", hint="scripts may use $(arg name) and $(eval expr)")


# --------------------------------------------------------------------- text, elements, macros
@dataclass
class Frames:
    """Where the expansion is: sources of the elements and macro calls being expanded."""

    stack: list[tuple[str, str]] = field(default_factory=list)  # (kind, "file:line")
    failure: list[tuple[str, str]] | None = None  # the stack when the first error passed


def _source_of_call(node) -> str | None:

    prev = node.previousSibling
    while prev is not None and (prev.nodeType == xml.dom.Node.COMMENT_NODE
                                or (prev.nodeType == xml.dom.Node.TEXT_NODE and not prev.data.strip())):
        prev = prev.previousSibling
    if prev is not None and prev.nodeType == xml.dom.Node.PROCESSING_INSTRUCTION_NODE and prev.target == PI_TARGET:
        return prev.data.strip()
    return None


def _patched(original_eval_text, original_eval_all, original_macro_call):
    import xacro

    frames: Frames = X.STATE.frames

    def eval_text(text, symbols):
        g = X.current_guard()
        g.tick()
        results, lex = [], xacro.QuickLexer(xacro.LEXER)
        lex.lex(text)
        size = 0
        while lex.peek():
            kind = lex.peek()[0]
            if kind == lex.EXPR:
                expr = lex.next()[1][2:-1]
                try:
                    value = xacro.safe_eval(eval_text(expr, symbols), symbols)
                except (SandboxError, xacro.XacroException):
                    raise
                except Exception as exc:
                    raise xacro.XacroException(exc=exc, suffix=f"when evaluating expression '{expr}'") from None
            elif kind == lex.EXTENSION:
                value = xacro.eval_extension(f"$({eval_text(lex.next()[1][2:-1], symbols)})")
            elif kind == lex.TEXT:
                value = lex.next()[1]
            else:  # DOLLAR_DOLLAR_BRACE
                value = lex.next()[1][1:]
            results.append(value)
            size += len(value) if isinstance(value, str) else 8
            if size > g.limits.max_size * 10:
                raise SandboxError(f"an attribute or text expands beyond {g.limits.max_size * 10} characters",
                                   hint="the script expands into too much; simplify its properties")
        g.add_text(size)
        return results[0] if len(results) == 1 else "".join(map(str, results))

    def eval_all(node, macros, symbols):
        g = X.current_guard()
        g.tick()
        g.elements += 1
        if g.elements > g.limits.max_elements:
            raise SandboxError(f"the expansion exceeds the limit of {g.limits.max_elements} elements",
                               hint="call fewer macros, or smaller ones", limit="max_elements",
                               bound=g.limits.max_elements)
        src = node.getAttribute(_SRC_ATTR) if hasattr(node, "getAttribute") else ""
        if src:
            frames.stack.append(("element", src))
        try:
            original_eval_all(node, macros, symbols)
        except BaseException:
            if frames.failure is None:
                frames.failure = list(frames.stack)
            raise
        finally:
            if src:
                frames.stack.pop()

    def handle_macro_call(node, macros, symbols):
        g = X.current_guard()
        g.tick()
        if not node.tagName.startswith("xacro:") or node.tagName == "xacro:call":
            return original_macro_call(node, macros, symbols)
        src = _source_of_call(node)
        g.depth += 1
        frames.stack.append(("macro", src or "?"))
        try:
            if g.depth > g.limits.max_macro_depth:
                raise SandboxError(f"macro calls nest deeper than the limit of {g.limits.max_macro_depth} "
                                   f"({node.tagName} calls itself?)", hint="end the recursion with xacro:if",
                                   limit="max_macro_depth", bound=g.limits.max_macro_depth)
            return original_macro_call(node, macros, symbols)
        except BaseException:
            if frames.failure is None:
                frames.failure = list(frames.stack)
            raise
        finally:
            g.depth -= 1
            frames.stack.pop()

    return eval_text, eval_all, handle_macro_call


_SRC_ATTR = "recon_source"
_lock = threading.Lock()


def _include_guard(original, allowed: frozenset[str]):
    """xacro's process_include, for the files resolved beforehand only."""
    import xacro

    def process_include(elt, macros, symbols, func):
        X.current_guard().tick()
        spec = elt.getAttribute("filename")
        if spec not in allowed:
            raise SandboxError("xacro:include of a file named by an expression or made by xacro:element is refused",
                               hint="include files by a plain relative path written in the file")
        for name in ("ns", "optional"):
            if elt.hasAttribute(name):
                raise SandboxError(f"xacro:include {name}=... is not supported here",
                                   hint="include the file without it")
        if xacro.first_child_element(elt):
            raise SandboxError("xacro:include has child elements", hint="remove them")
        return original(elt, macros, symbols, func)

    return process_include


@contextlib.contextmanager
def sandboxed(rule: ReadRule | Path, limits: Limits | None = None, *, includes: frozenset[str] = frozenset(),
              originals: dict[str, Path] | None = None) -> Iterator[Frames]:
    """Patch xacro for the expansion of one user's file; yields the expansion's frames (for
    error locations). ``rule``: where ``xacro.load_yaml`` may read (a script's folder for
    :func:`~.readable.script_rule`); ``includes``: the files ``xacro:include`` may name (the
    checked copies); ``originals``: copy -> the user's file (see :func:`.expressions.symbol_table`).
    xacro's module state is global, so expansions are serialized."""
    import xacro

    with _lock:
        names = ("safe_eval", "eval_extension", "eval_text", "eval_all", "handle_macro_call", "process_include",
                 "_global_symbols")
        saved = {name: getattr(xacro, name) for name in names}
        X.STATE.guard = X.Guard(limits or LIMITS)
        X.STATE.frames = Frames()
        eval_text, eval_all, macro_call = _patched(saved["eval_text"], saved["eval_all"], saved["handle_macro_call"])
        try:
            xacro._global_symbols = X.symbol_table(rule, originals)
            xacro.safe_eval = safe_eval
            xacro.eval_extension = eval_extension
            xacro.eval_text = eval_text
            xacro.eval_all = eval_all
            xacro.handle_macro_call = macro_call
            xacro.process_include = _include_guard(saved["process_include"], includes)
            with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
                yield X.STATE.frames
        finally:
            for name, value in saved.items():
                setattr(xacro, name, value)
            X.STATE.guard = None
            X.clear_symbols()
