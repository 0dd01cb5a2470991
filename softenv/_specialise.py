"""Plain Python-float kernels from arithmetic written once against ``ops`` (:mod:`softenv._ops`).

The laryngoscope's substep arithmetic serves the single env (Python floats, :class:`ScalarOps`) and
the batched twin (numpy arrays) from one source. On floats, each ``ops.f(...)`` is a Python call and
each per-scene constant ``c.name`` an attribute lookup: together a third of a substep, which the
single env runs 20 times per step. :func:`scalar_kernel` rewrites such a function once, at its
syntax tree, into the code a person would write by hand for floats:

* ``ops.positive(x)``, ``index``, ``clip``, ``where``, ``take`` -> the conditional expressions that
  :class:`ScalarOps` evaluates (each argument evaluated once), ``ops.sqrt`` and the other ``math``
  functions -> those functions; so the kernel computes the same IEEE operations in the same order as
  the function called with ``ScalarOps``, and returns the same bits (tested);
* ``c.name`` -> a constant bound in the kernel's closure (``c`` names the constants: a parameter,
  or a local the function assigns them to);
* ``ops is ScalarOps`` -> ``True``;
* a statement ``a, b = helper(...)`` calling one of the listed helpers (functions of the same
  module) -> the helper's body, its locals renamed, its parameters replaced by the call's arguments.

The kernel keeps the function's signature (``c`` and ``ops`` are accepted and ignored) and runs in its
module's globals. Where the source cannot be read (an app frozen without its ``.py`` files), the
function itself is returned: callers pass ``c`` and ``ops`` anyway, so the results are the same, at
the plain speed. The ops' arguments must be free of side effects, as arithmetic is: one that the float
form does not need (the unselected branch of ``where``) is not evaluated.
"""

from __future__ import annotations

import ast
import copy
import inspect
import textwrap
from collections import Counter
from collections.abc import Callable
from functools import cache
from typing import Any

from ._ops import ScalarOps

# ops.f(args) -> an expression of the argument names a, b, c; an argument read more than once is
# bound by := at its first read, which every later read follows in evaluation order
_OPS = {
    "positive": (1, "(a if a > 0.0 else 0.0)"),
    "clip": (3, "(b if a < b else (c if a > c else a))"),
    "where": (3, "(b if a else c)"),
    "index": (2, "(int(a) if a < b else b)"),
    "take": (2, "a[b]"),
}
_MATH = ("sqrt", "cos", "sin", "atan2", "asin")
_OPS_NAMES = ("ops", ScalarOps.__name__)      # the ops argument, or ScalarOps passed for it


def scalar_kernel(fn: Callable[..., Any], constants: Any, helpers: tuple[Callable[..., Any], ...] = (),
                  constants_arg: str = "c") -> Callable[..., Any]:
    """``fn`` specialised to Python floats, with the attributes of ``constants`` (read by ``fn`` and
    the inlined ``helpers`` as ``c.name``) bound as constants."""
    try:
        bind, names, maths = _compile(fn, helpers, constants_arg)
    except OSError:                              # no source to read: run the function as written
        return fn
    return bind(*(getattr(constants, name) for name in names), *(getattr(ScalarOps, name) for name in maths))


def _function_def(fn: Callable[..., Any]) -> ast.FunctionDef:
    tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
    node = tree.body[0]
    if not isinstance(node, ast.FunctionDef) or fn.__code__.co_freevars:
        raise ValueError(f"scalar_kernel: {fn.__qualname__} is not a plain function of its module (the kernel "
                         "sees the module's globals, not an enclosing function's variables)")
    return node


@cache
def _compile(fn: Callable[..., Any], helpers: tuple[Callable[..., Any], ...],
             constants_arg: str) -> tuple[Callable[..., Any], tuple[str, ...], tuple[str, ...]]:
    """The kernel's factory ((constants, math functions) -> kernel) and the names of its arguments."""
    kernel = _function_def(fn)
    foreign = [h.__qualname__ for h in helpers if h.__globals__ is not fn.__globals__]
    if foreign:
        raise ValueError(f"scalar_kernel: helpers {foreign} are not in {fn.__qualname__}'s module, whose globals "
                         "the kernel sees")
    kernel.body = _Inliner({h.__name__: _function_def(h) for h in helpers}).statements(kernel.body)
    rewriter = _Rewriter(constants_arg)
    kernel = rewriter.visit(kernel)
    for arg in kernel.args.args + kernel.args.kwonlyargs:
        arg.annotation = None
    kernel.returns, kernel.decorator_list = None, []
    names, maths = tuple(sorted(rewriter.constants)), tuple(sorted(rewriter.maths))
    args = ast.arguments(posonlyargs=[], args=[ast.arg(f"{constants_arg}_{n}") for n in names]
                         + [ast.arg(f"_ops_{n}") for n in maths], kwonlyargs=[], kw_defaults=[], defaults=[])
    factory = ast.FunctionDef(name="_bind", args=args, body=[kernel, ast.Return(ast.Name(kernel.name, ast.Load()))],
                              decorator_list=[])
    module = ast.fix_missing_locations(ast.Module(body=[factory], type_ignores=[]))
    scope: dict[str, Any] = {}               # the factory lands here, not in the function's module
    exec(compile(module, f"<scalar kernel of {fn.__qualname__}>", "exec"), fn.__globals__, scope)  # noqa: S102
    return scope["_bind"], names, maths


class _Inliner:
    """Replaces ``targets = helper(args)`` statements by the helper's renamed body."""

    def __init__(self, helpers: dict[str, ast.FunctionDef]) -> None:
        self.helpers = helpers
        self.count = 0

    def statements(self, body: list[ast.stmt]) -> list[ast.stmt]:
        out: list[ast.stmt] = []
        for stmt in body:
            for field in ("body", "orelse"):
                if isinstance(getattr(stmt, field, None), list):
                    setattr(stmt, field, self.statements(getattr(stmt, field)))
            call = stmt.value if isinstance(stmt, ast.Assign) else None
            if isinstance(call, ast.Call) and isinstance(call.func, ast.Name) and call.func.id in self.helpers:
                out += self._inline(self.helpers[call.func.id], call, stmt.targets)
            else:
                out.append(stmt)
        return out

    def _inline(self, helper: ast.FunctionDef, call: ast.Call, targets: list[ast.expr]) -> list[ast.stmt]:
        body = [copy.deepcopy(s) for s in helper.body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant))]
        returns = [n for s in body for n in ast.walk(s) if isinstance(n, ast.Return)]
        if not body or returns != [body[-1]] or call.keywords or len(call.args) != len(helper.args.args):
            raise ValueError(f"scalar_kernel can inline {helper.name} only as `x = {helper.name}(positional args)` "
                             "with one return, its last statement")
        self.count += 1
        prefix = f"_{helper.name.strip('_')}{self.count}_"
        stores = Counter(n.id for s in body for n in ast.walk(s) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store))
        out: list[ast.stmt] = []
        params: dict[str, ast.expr] = {}
        for a, arg in zip(helper.args.args, call.args):
            if a.arg in stores:
                raise ValueError(f"scalar_kernel cannot inline {helper.name}: it assigns to its parameter {a.arg}")
            if _plain(arg) or isinstance(arg, ast.Tuple) and all(_plain(e) for e in arg.elts):
                params[a.arg] = arg                 # substituted where it is read
            else:                                   # evaluated once, before the body
                out.append(ast.Assign([ast.Name(prefix + a.arg, ast.Store())], arg))
                params[a.arg] = ast.Name(prefix + a.arg, ast.Load())
        # `x, y = param` of a tuple argument: no tuple is built and unpacked; a name assigned only
        # there stands for its element, any other is assigned it
        aliases: dict[str, ast.expr] = {}
        kept: list[ast.stmt] = []
        for stmt in body[:-1]:
            names = stmt.targets[0].elts if isinstance(stmt, ast.Assign) and isinstance(stmt.targets[0], ast.Tuple) else []
            source = params.get(stmt.value.id) if isinstance(stmt, ast.Assign) and isinstance(stmt.value, ast.Name) else None
            if not (isinstance(source, ast.Tuple) and len(stmt.targets) == 1 and len(source.elts) == len(names)
                    and all(isinstance(t, ast.Name) for t in names)):
                kept.append(stmt)
                continue
            for target, element in zip(names, source.elts):
                if stores[target.id] == 1:
                    aliases[target.id] = element
                else:           # the caller's names are not changed by the body: safe to assign up front
                    out.append(ast.Assign([ast.Name(prefix + target.id, ast.Store())], element))
        renamer = _Renamer({**params, **aliases}, {n: prefix + n for n in stores if n not in aliases})
        out += self.statements([renamer.visit(s) for s in kept])
        value = renamer.visit(body[-1]).value
        target_names = {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
        if (len(targets) == 1 and isinstance(targets[0], ast.Tuple) and isinstance(value, ast.Tuple)
                and len(value.elts) == len(targets[0].elts)
                and not target_names & {n.id for n in ast.walk(value) if isinstance(n, ast.Name)}):
            out += [ast.Assign([t], v) for t, v in zip(targets[0].elts, value.elts)]   # no tuple to unpack
        else:
            out.append(ast.Assign(targets, value))
        return out


def _plain(node: ast.expr) -> bool:
    """A name or a constant: reading it again costs nothing and changes nothing."""
    return isinstance(node, (ast.Name, ast.Constant))


class _Renamer(ast.NodeTransformer):
    def __init__(self, params: dict[str, ast.expr], local: dict[str, str]) -> None:
        self.params, self.local = params, local

    def visit_Name(self, node: ast.Name) -> ast.expr:
        if node.id in self.local:
            return ast.Name(self.local[node.id], node.ctx)
        if node.id in self.params and isinstance(node.ctx, ast.Load):
            return copy.copy(self.params[node.id])
        return node


class _Rewriter(ast.NodeTransformer):
    """``ops.f(...)`` -> float expressions, ``c.name`` -> closure constants, ``ops is ScalarOps`` -> True."""

    def __init__(self, constants_arg: str) -> None:
        self.constants_arg = constants_arg
        self.constants: set[str] = set()
        self.maths: set[str] = set()
        self.temporaries = 0

    def visit_Attribute(self, node: ast.Attribute) -> ast.expr:
        if isinstance(node.value, ast.Name) and node.value.id == self.constants_arg and isinstance(node.ctx, ast.Load):
            self.constants.add(node.attr)
            return ast.Name(f"{self.constants_arg}_{node.attr}", ast.Load())
        return self.generic_visit(node)

    def visit_Compare(self, node: ast.Compare) -> ast.expr:
        if (len(node.ops) == 1 and isinstance(node.ops[0], ast.Is) and isinstance(node.left, ast.Name)
                and node.left.id in _OPS_NAMES and isinstance(node.comparators[0], ast.Name)
                and node.comparators[0].id == ScalarOps.__name__):
            return ast.Constant(True)
        return self.generic_visit(node)

    def visit_Call(self, node: ast.Call) -> ast.expr:
        self.generic_visit(node)
        f = node.func
        if not (isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and f.value.id in _OPS_NAMES):
            return node
        if f.attr in _MATH:                     # ScalarOps' math function, bound: a C call without the lookup
            self.maths.add(f.attr)
            return ast.Call(ast.Name(f"_ops_{f.attr}", ast.Load()), node.args, [])
        if f.attr not in _OPS:
            raise ValueError(f"scalar_kernel: ops.{f.attr} has no float form here")
        arity, template = _OPS[f.attr]
        if len(node.args) != arity or node.keywords:
            raise ValueError(f"scalar_kernel: ops.{f.attr} takes {arity} positional arguments")
        names: dict[str, ast.expr] = {}
        first: dict[str, ast.expr] = {}          # where each argument is first read: bound there by :=
        for letter, arg in zip("abc", node.args):
            if _plain(arg) or _reads(template, letter) == 1:
                names[letter] = arg
            else:
                self.temporaries += 1
                temp = f"_t{self.temporaries}"
                names[letter] = ast.Name(temp, ast.Load())
                first[letter] = ast.NamedExpr(ast.Name(temp, ast.Store()), arg)
        return _Substitute(names, first).visit(ast.parse(template, mode="eval").body)


def _reads(template: str, letter: str) -> int:
    """How often a template reads an argument (once: the argument is substituted as it is)."""
    return sum(isinstance(n, ast.Name) and n.id == letter for n in ast.walk(ast.parse(template, mode="eval")))


class _Substitute(ast.NodeTransformer):
    """Fills a template's argument letters; an argument's first read (in evaluation order) binds it."""

    def __init__(self, names: dict[str, ast.expr], first: dict[str, ast.expr]) -> None:
        self.names, self.first = names, first

    def visit_IfExp(self, node: ast.IfExp) -> ast.expr:
        node.test = self.visit(node.test)           # a conditional evaluates its test first
        node.body = self.visit(node.body)
        node.orelse = self.visit(node.orelse)
        return node

    def visit_Name(self, node: ast.Name) -> ast.expr:
        if node.id in self.first:
            return self.first.pop(node.id)
        return self.names.get(node.id, node)
