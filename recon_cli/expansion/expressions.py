"""Script expressions (``${...}`` and ``$(eval ...)``): checked, guarded, bounded.

An expression is parsed and checked before it runs: arithmetic, comparisons,
conditionals, literals, subscripts and calls of a fixed set of pure functions (``math``,
``min``, ``max``, ``len``, ...); no lambdas, comprehensions, private names or attributes of
anything but xacro's namespaces. Every operation and call then runs through a guard that
refuses values beyond :class:`Limits` (integers, string and list sizes) before they are
built, and checks the expansion's deadline. The symbol table offers xacro's namespaces
restricted to that set, with ``xacro.load_yaml`` confined by the expansion's read rule
(:mod:`.readable`). :mod:`.sandbox` installs all this into xacro.
"""

from __future__ import annotations

import ast
import builtins
import math
import operator
import re
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from recon_cli.errors import LimitError, ScriptError
from recon_cli.expansion.readable import ReadRule, readable
from recon_cli.inputs.yamlfile import plain, read_yaml


@dataclass(frozen=True)
class Limits:
    """Hard limits of a script's expansion (stated in the README)."""

    max_int_bits: int = 63  # integers within +-2**63
    max_size: int = 100_000  # characters of a string, items (recursively) of a list/dict
    max_text: int = 20_000_000  # characters produced by all evaluations of one script
    max_elements: int = 10_000  # elements evaluated (each macro expansion counts again)
    max_macro_depth: int = 100  # nested macro calls
    max_seconds: float = 10.0  # wall-clock time of the expansion
    max_file_bytes: int = 5_000_000  # a script, an included file, a YAML file
    max_files: int = 50  # script + included files
    max_commands: int = 10_000  # typed commands after expansion (rings included)
    max_ring_count: int = 3600  # views of one <ring>
    percent_format: bool = False  # '%r 0 %r' % (x, y), with widths and precisions of at most 3 digits


LIMITS = Limits()


SandboxError = LimitError  # what the checks raise

# --------------------------------------------------------------------- value guards
def _size(value, budget: int) -> int:
    """Size of a value (characters of strings, items of containers, recursively), counted
    until it exceeds ``budget``."""
    if isinstance(value, (str, bytes)):
        return len(value)
    if isinstance(value, dict):
        total = len(value)
        for k, v in value.items():
            if total > budget:
                break
            total += _size(k, budget - total) + _size(v, budget - total)
        return total
    if isinstance(value, (list, tuple, set, frozenset)):
        total = len(value)
        for v in value:
            if total > budget:
                break
            total += _size(v, budget - total)
        return total
    if isinstance(value, range):
        return len(value)
    return 1


class Guard:
    """Runtime checks of one expansion (limits, deadline, evaluated text)."""

    def __init__(self, limits: Limits) -> None:
        self.limits = limits
        self.deadline = time.monotonic() + limits.max_seconds
        self.text = 0
        self.elements = 0
        self.depth = 0

    def tick(self) -> None:
        if time.monotonic() > self.deadline:
            raise SandboxError(f"the expansion takes longer than the limit of {self.limits.max_seconds:g} s",
                               hint="simplify the script's macros and expressions", limit="max_seconds",
                               bound=self.limits.max_seconds)

    def value(self, v):
        lim = self.limits
        if isinstance(v, bool) or v is None:
            return v
        if isinstance(v, int):
            if v.bit_length() > lim.max_int_bits:
                raise SandboxError(f"an expression gives an integer beyond the limit of +-2**{lim.max_int_bits}",
                                   hint="use numbers of a sensible size", limit="max_int_bits", bound=lim.max_int_bits)
            return v
        if isinstance(v, (float, complex)):
            return v
        if _size(v, lim.max_size) > lim.max_size:
            raise SandboxError(f"an expression gives a value larger than the limit of {lim.max_size} "
                               "characters or items", hint="use smaller strings and lists", limit="max_size",
                               bound=lim.max_size)
        return v

    def add_text(self, n: int) -> None:
        self.text += n
        if self.text > self.limits.max_text:
            raise SandboxError(f"the expansion produces more than the limit of {self.limits.max_text} characters "
                               "of text", hint="the script expands into too much; simplify its macros",
                               limit="max_text", bound=self.limits.max_text)


STATE = threading.local()  # the guard of the expansion running in this thread


def current_guard() -> Guard:
    g = getattr(STATE, "guard", None)
    if g is None:  # pragma: no cover - the patched functions are only installed inside sandboxed()
        raise RuntimeError("sandboxed xacro function called outside the sandbox")
    return g


_BINOPS = {
    "Add": operator.add, "Sub": operator.sub, "Mult": operator.mul, "Div": operator.truediv,
    "FloorDiv": operator.floordiv, "Mod": operator.mod, "Pow": operator.pow, "LShift": operator.lshift,
    "RShift": operator.rshift, "BitOr": operator.or_, "BitXor": operator.xor, "BitAnd": operator.and_,
}


def _binop(name: str, a, b):
    g = current_guard()
    g.tick()
    lim = g.limits
    ints = isinstance(a, int) and isinstance(b, int)
    if name == "Pow" and ints and b > 0 and abs(a) > 1 and b * math.log2(abs(a)) > lim.max_int_bits:
        raise SandboxError(f"{a} ** {b} is beyond the integer limit of +-2**{lim.max_int_bits}",
                           hint="use numbers of a sensible size", limit="max_int_bits", bound=lim.max_int_bits)
    if name == "LShift" and ints and b > lim.max_int_bits:
        raise SandboxError(f"<< {b} is beyond the integer limit of +-2**{lim.max_int_bits}",
                           hint="use numbers of a sensible size", limit="max_int_bits", bound=lim.max_int_bits)
    if name == "Mult":
        seq, n = (a, b) if isinstance(b, int) else (b, a)
        if isinstance(seq, (str, list, tuple)) and isinstance(n, int) and n > 0:
            if _size(seq, lim.max_size) * n > lim.max_size:
                raise SandboxError(f"repeating a value {n} times exceeds the limit of {lim.max_size} characters "
                                   "or items", hint="use smaller strings and lists", limit="max_size",
                                   bound=lim.max_size)
    if name == "Mod" and isinstance(a, str):
        if not lim.percent_format:
            raise SandboxError("%-formatting of strings is not allowed in scripts", hint="use + to join strings")
        if _WIDE.search(a):
            raise SandboxError("a %-format with a width or precision of more than 3 digits (or '*') is not allowed",
                               hint="use widths and precisions below 1000")
    return g.value(_BINOPS[name](a, b))


_WIDE = re.compile(r"%(\([^)]*\))?[-+ #0]*(\*|\d{4,}|\d*\.(\*|\d{4,}))")

# functions an expression may call (besides the math module's)
_PURE = ("list", "dict", "len", "str", "float", "int", "bool", "min", "max", "round", "abs", "all", "any",
         "divmod", "enumerate", "reversed", "slice", "set", "sum", "tuple", "zip", "sorted", "range", "ord")
_MATH = ("pi", "e", "tau", "inf", "nan", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh",
         "tanh", "asinh", "acosh", "atanh", "sqrt", "exp", "log", "log10", "log2", "pow", "fabs", "floor", "ceil",
         "trunc", "radians", "degrees", "hypot", "copysign", "fmod", "isfinite", "isnan", "isinf", "isclose",
         "remainder", "cbrt", "dist", "modf", "frexp", "ldexp", "exp2", "expm1", "log1p", "fsum", "gcd")
_REFUSED = {
    "load_yaml": "xacro.load_yaml reads files only from the script's folder or scripts_xml/",
    "abs_filename": "xacro.abs_filename reveals file-system paths; scripts may not use it",
    "message": "xacro's message functions print to the terminal; scripts may not use them",
    "warning": "xacro's message functions print to the terminal; scripts may not use them",
    "error": "xacro's message functions print to the terminal; scripts may not use them",
    "print_location": "xacro's message functions print to the terminal; scripts may not use them",
    "map": "map() is not allowed in scripts (it calls functions outside the checks)",
    "filter": "filter() is not allowed in scripts (it calls functions outside the checks)",
    "type": "type() is not allowed in scripts", "vars": "vars() is not allowed in scripts",
    "isinstance": "isinstance() is not allowed in scripts", "issubclass": "issubclass() is not allowed in scripts",
    "hash": "hash() is not allowed in scripts", "repr": "repr() is not allowed in scripts",
    "complex": "complex() is not allowed in scripts", "frozenset": "frozenset() is not allowed in scripts",
}


def _refuser(name: str):
    def refuse(*args, **kwargs):
        raise SandboxError(_REFUSED[name], hint="remove it from the script")

    refuse.__name__ = name
    return refuse


def _call(f, *args, **kwargs):
    g = current_guard()
    g.tick()
    if f not in _allowed_callables():
        name = getattr(f, "__name__", type(f).__name__)
        raise SandboxError(f"calling {name!r} is not allowed in scripts",
                           hint="expressions may call math functions and min, max, len, str, float, int, ...")
    if f is range:
        r = range(*args)
        if len(r) > g.limits.max_size:
            raise SandboxError(f"range of {len(r)} items exceeds the limit of {g.limits.max_size}",
                               hint="use a smaller range", limit="max_size", bound=g.limits.max_size)
        return r
    if f is round and len(args) > 1 and isinstance(args[1], int) and abs(args[1]) > 400:
        raise SandboxError("round() to more than 400 digits is not allowed in scripts", hint="round to fewer digits")
    if f in (str, int, float) and args and _size(args[0], g.limits.max_size) > g.limits.max_size:
        raise SandboxError(f"converting a value larger than the limit of {g.limits.max_size} characters or items",
                           hint="use smaller strings and lists")
    return g.value(f(*args, **kwargs))


def _attr(obj, name: str):
    import xacro

    current_guard().tick()
    if not isinstance(obj, (xacro.Table, xacro.YamlDictWrapper)):
        raise SandboxError(f"attribute access .{name} is not allowed in scripts (only namespaces such as "
                           "math.pi, python.abs, xacro.tokenize or a loaded YAML's keys)",
                           hint="call functions by their namespace, e.g. math.sin(x)")
    try:
        value = obj[name]
    except KeyError:
        raise SandboxError(f"name {name!r} is not defined", hint="check the property or namespace") from None
    return current_guard().value(value)


_ALLOWED_NODES = (
    ast.Expression, ast.Constant, ast.Name, ast.Load, ast.BinOp, ast.UnaryOp, ast.BoolOp, ast.Compare, ast.IfExp,
    ast.Call, ast.keyword, ast.Attribute, ast.Subscript, ast.Slice, ast.List, ast.Tuple, ast.Dict, ast.Set,
    ast.JoinedStr, ast.FormattedValue,
    ast.operator, ast.unaryop, ast.boolop, ast.cmpop, ast.expr_context,
)
_NODE_WORDS = {
    ast.Lambda: "lambda", ast.ListComp: "comprehensions", ast.SetComp: "comprehensions",
    ast.DictComp: "comprehensions", ast.GeneratorExp: "generator expressions", ast.NamedExpr: "':='",
    ast.Starred: "'*' unpacking", ast.Await: "await", ast.Yield: "yield", ast.YieldFrom: "yield",
}


class _Rewrite(ast.NodeTransformer):
    """Routes operations, calls and attribute access through the guards."""

    def visit_BinOp(self, node):  # noqa: N802
        self.generic_visit(node)
        return ast.Call(ast.Name("__recon_binop__", ast.Load()),
                        [ast.Constant(type(node.op).__name__), node.left, node.right], [])

    def visit_Call(self, node):  # noqa: N802
        self.generic_visit(node)
        return ast.Call(ast.Name("__recon_call__", ast.Load()), [node.func, *node.args], node.keywords)

    def visit_Attribute(self, node):  # noqa: N802
        self.generic_visit(node)
        return ast.Call(ast.Name("__recon_attr__", ast.Load()), [node.value, ast.Constant(node.attr)], [])


_GUARDS = {"__builtins__": {}, "__recon_binop__": _binop, "__recon_call__": _call, "__recon_attr__": _attr}


def check_expression(expr: str) -> ast.Expression:
    """Parse an expression and refuse what scripts may not use (before anything runs)."""
    lim = current_guard().limits if getattr(STATE, "guard", None) else LIMITS
    try:
        tree = ast.parse(expr.strip(), mode="eval")
    except SyntaxError as exc:
        raise SandboxError(f"invalid expression {expr.strip()!r} ({exc.msg})",
                           hint="fix the expression") from None
    for node in ast.walk(tree):
        if not isinstance(node, _ALLOWED_NODES):
            word = _NODE_WORDS.get(type(node), type(node).__name__)
            raise SandboxError(f"{word} not allowed in script expressions ({expr.strip()!r})",
                               hint="use arithmetic, comparisons and calls of math functions")
        if isinstance(node, ast.Name) and node.id.startswith("_"):
            raise SandboxError(f"name {node.id!r} is not allowed in script expressions",
                               hint="names starting with '_' are private")
        if isinstance(node, ast.Attribute) and node.attr.startswith("_"):
            raise SandboxError(f"attribute {node.attr!r} is not allowed in script expressions",
                               hint="names starting with '_' are private")
        if isinstance(node, ast.keyword) and node.arg is None:
            raise SandboxError("'**' unpacking is not allowed in script expressions", hint="pass arguments by name")
        if isinstance(node, ast.FormattedValue) and node.format_spec is not None:
            raise SandboxError("format specifications in f-strings are not allowed in script expressions",
                               hint="use round() or str()")
        if isinstance(node, ast.MatMult):
            raise SandboxError("'@' is not allowed in script expressions", hint="use arithmetic operators")
        if isinstance(node, ast.Constant):
            if isinstance(node.value, int) and not isinstance(node.value, bool) \
                    and node.value.bit_length() > lim.max_int_bits:
                raise SandboxError(f"integer literal beyond the limit of +-2**{lim.max_int_bits}",
                                   hint="use numbers of a sensible size", limit="max_int_bits",
                                   bound=lim.max_int_bits)
            if isinstance(node.value, (str, bytes)) and len(node.value) > lim.max_size:
                raise SandboxError(f"string literal longer than the limit of {lim.max_size} characters",
                                   hint="use shorter strings")
    return tree


def safe_eval(expr: str, symbols, locals_=None):
    """Drop-in for ``xacro.safe_eval``: check, rewrite through the guards, evaluate."""
    g = current_guard()
    g.tick()
    tree = ast.fix_missing_locations(_Rewrite().visit(check_expression(str(expr))))
    code = compile(tree, "<script expression>", "eval")
    try:
        value = eval(code, dict(_GUARDS), symbols if locals_ is None else locals_)  # noqa: S307
    except RecursionError:
        raise SandboxError("an expression nests too deeply (recursive property definitions?)",
                           hint="check the properties it uses") from None
    except (OverflowError, ZeroDivisionError, ValueError, TypeError) as exc:
        raise SandboxError(f"expression {str(expr).strip()!r} fails: {exc}", hint="fix the expression") from None
    return g.value(value)


# --------------------------------------------------------------------- the symbol table
_allowed: set[int] = set()


def _allowed_callables() -> _CallableSet:
    return _CallableSet()


class _CallableSet:
    def __contains__(self, f) -> bool:
        return id(f) in _allowed


def symbol_table(rule: ReadRule | Path, originals: dict[str, Path] | None = None) -> dict:
    """xacro's global symbols, restricted: pure builtins, math, and a load_yaml confined by
    ``rule`` (a script's folder: :func:`~.readable.script_rule`). ``originals`` maps the
    files xacro expands (annotated copies) to the user's files: ``load_yaml`` then looks
    beside the user's file that calls it, as plain xacro does; without it beside the rule's home."""

    import xacro

    table: dict = {}
    python = xacro.NameSpace()
    for name in _PURE:
        f = getattr(builtins, name)
        python[name] = f
        table[name] = f
    for name in ("True", "False"):
        table[name] = python[name] = getattr(builtins, name)
    m = xacro.NameSpace()
    for name in _MATH:
        if hasattr(math, name):
            m[name] = getattr(math, name)
            table[name] = m[name]
    x = xacro.NameSpace()
    x["load_yaml"] = table["load_yaml"] = _confined_load_yaml(rule, originals)
    x["dotify"] = table["dotify"] = xacro.YamlDictWrapper
    x["tokenize"] = xacro.tokenize
    x["arg"] = lambda name: xacro.substitution_args_context["arg"][name]
    x["fatal"] = _fatal
    for name in ("abs_filename", "message", "warning", "error", "print_location"):
        x[name] = _refuser(name)
    for name in ("map", "filter", "type", "vars", "isinstance", "issubclass", "hash", "repr", "complex",
                 "frozenset"):
        python[name] = table[name] = _refuser(name)
    table.update(python=python, math=m, xacro=x)
    _allowed.clear()
    for ns in (table, python, m, x):
        for v in dict.values(ns) if isinstance(ns, dict) else ():
            if callable(v):
                _allowed.add(id(v))
    _allowed.add(id(xacro.YamlDictWrapper))
    return table


def _fatal(*args):
    raise SandboxError("xacro.fatal: " + " ".join(map(str, args)), hint="the script stopped itself")


def _confined_load_yaml(rule: ReadRule | Path, originals: dict[str, Path] | None):
    def load_yaml(filename):
        import xacro

        name = str(filename)
        if any(ch in name for ch in "$(){}"):
            raise SandboxError(f"xacro.load_yaml({name!r}): YAML files are loaded only by a plain relative path",
                               hint="copy the file beside the file that loads it")
        beside = None
        if originals is not None and xacro.filestack:
            user_file = originals.get(str(xacro.filestack[-1]))
            beside = user_file.parent if user_file is not None else None
        try:
            path = readable(name, rule, None, "YAML file", beside=beside)
        except LimitError:
            raise
        except ScriptError as exc:
            raise SandboxError(f"xacro.load_yaml({name!r}): {exc.message}", hint=exc.hint) from None
        size = path.stat().st_size
        if size > current_guard().limits.max_file_bytes:
            raise SandboxError(f"xacro.load_yaml({name!r}): {size} bytes exceeds the limit of "
                               f"{current_guard().limits.max_file_bytes} bytes", hint="use a smaller file")
        return current_guard().value(_read_yaml(path))

    return load_yaml


def _read_yaml(path: Path):
    """A YAML file through recon's guarded reader (no aliases, no tags, bounded), as xacro's
    wrappers (``a.b`` for ``a['b']``)."""
    import xacro

    return xacro.YamlListWrapper.wrap(plain(read_yaml(path, "YAML file")))


def clear_symbols() -> None:
    """Forget the callables of the last symbol table (end of an expansion)."""
    _allowed.clear()
