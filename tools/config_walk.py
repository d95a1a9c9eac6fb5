#!/usr/bin/env python3
"""Walk a run's config through pngail_jax by static data flow (stdlib ``ast`` only).

Usage:  python config_walk.py ROOT [--json OUT.json] [--trace] [--objects]
        ROOT holds ``pngail_jax/`` and ``tests/test_layers.py``.

Definitions (applied identically to every checkout)
---------------------------------------------------
Start.  The function ``run`` in ``pngail_jax/jobs/sweep.py``, its parameter ``config`` tracked,
of class ``RunConfig`` (``pngail_jax.config.run_config``).

Carrying names (inside one function; flow-insensitive, iterated to a fixpoint).  A name
carries the config if it is a tracked parameter, or is the target of an assignment
(``=``, annotated ``=``, ``+=``, ``for .. in``, ``with .. as``, comprehension ``for``,
``:=``) whose value contains a carrying expression.  An expression carries if it contains a
carrying name anywhere (attribute access ``config.settings``, calls ``f(config)``,
``config.adversarial_config(..)``, subscripts, operators, f-strings ...).  Multiple
assignment is split: ``a, b = x, y`` pairs targets with values element by element; ``a, b =
f(config)`` (any value that is not a tuple/list literal of the same length) marks every
target.  ``d[k] = <carrying>`` marks ``d``.  ``self.attr = <carrying>`` in a method of class
C makes ``(C, attr)`` carrying in every method of C.  ``self.attr`` carries if (C, attr) is
carrying, or if ``self`` is tracked and C is "data-like" (none of its methods assigns a
``self.x``: the object *is* the data, e.g. the frozen ``RunConfig``).  A bare ``self`` carries
if ``self`` is tracked.  Bodies of nested ``def``/``lambda`` are read as part of the
enclosing function (closures see its carrying names); they are not stays of their own.

Following calls.  A call is part of the walk if one of its arguments (positional, keyword,
``*x``, ``**x``) carries, or its receiver carries (``obj.m(..)`` with ``obj`` carrying).  It
is followed when its callee resolves statically to a function defined in pngail_jax:
module-local functions and classes; ``from pngail_jax.x import f`` (re-exports followed);
``import pngail_jax.x as y`` / ``from pngail_jax import x`` then ``y.f`` / ``x.f``;
relative imports; imports inside functions count as the module's; ``ClassName(..)`` ->
``__init__`` (own or inherited from a pngail_jax base), else ``__post_init__`` with ``self``
tracked, else "constructed, no body" (no stay); ``self.m(..)`` and ``super().m(..)`` in a
class; ``Class.m(..)`` (classmethod/staticmethod aware); ``obj.m(..)`` when the class of
``obj`` is inferred: from a parameter annotation, from the class propagated from the caller's
argument (when the parameter has no annotation), from ``x = ClassName(..)``, from ``x = f(..)``
with a return annotation, from ``x = y`` / ``x: T``, and for ``a.b`` from the class-level
annotation (dataclass field), property return annotation or ``self.b = ..`` type of a's
class.  The parameters receiving carrying arguments are tracked in the callee (``self`` too
when the receiver carries); ``*args``/``**kwargs`` parameters receive unmatched ones; a
carrying ``*x``/``**x`` argument tracks every parameter.
Calls that are part of the walk but not followed are tallied by distinct call site:
``external`` (builtins, or a name bound to a non-pngail import such as ``np``/``jax``),
``closure`` (a nested def of the same function, already read inline), ``no-body``
(constructing a pngail_jax class without ``__init__``/``__post_init__``) and ``unresolved``
(everything else: a method on an object whose class is not inferred, a method not found in
the inferred pngail_jax class, calling a parameter or a value).

Memoisation.  Per function, on the union of its tracked parameters (and the classes known
for them): a function is walked again only when a call tracks a parameter (or brings a
parameter's class) it had not had; it is then walked with the union.  Calls back into a
function still on the depth-first stack only widen its memo.  The whole walk is repeated
until the set of carrying ``(class, attr)`` pairs stops growing; the last pass is reported.

Counts.  A *stay* is one distinct (module, function qualname) visited.  A *room* is one
distinct module visited.  A walk *edge* is a distinct (caller function, callee function)
pair of followed calls with caller and callee in different modules (calls within a module
are not edges).  Climbs, counted over distinct edges:
  (a) *up-layer*: the callee's module is in a higher layer than the caller's, per the
      ``LAYERS`` list parsed from that checkout's ``tests/test_layers.py`` (module names
      relative to pngail_jax, fnmatch patterns, the package itself is "").
  (b) *re-entry*: in depth-first order, at the edge's first traversal the callee's module
      had already been visited (a function of it entered earlier in the walk), i.e. the walk
      comes back into a room it had been in.  (b') is the part of (b) whose callee module
      was still on the depth-first stack (a true A -> B -> A cycle, not a sibling return).
Objects mode (``--objects``).  The same walk, but an expression carries only when its value
is a config object: a carrying name, a carrying ``self.attr``, ``replace(obj, ..)`` of a
config object, or an expression whose inferred class is data-like (no method assigns a
``self.x``) and named ``*Config`` or ``*Settings``; a value read from a config (an int, a
string) no longer carries.  A method called on an object that keeps a config object in an
attribute (``self.config = config`` made ``(C, config)`` carrying) is followed too, its
``self`` tracked: such a holder reaches the config through its attribute.
Order.  Within a function, calls are taken in evaluation order (sorted by where each call
ends, so ``f(g(config))`` visits ``g`` before ``f``); nested-def bodies are interleaved by
position.
Room pairs are reported for both, directed (``caller -> callee``) and unordered
(``a <-> b``).
"""

from __future__ import annotations

import argparse
import ast
import builtins
import json
from collections import Counter
from dataclasses import dataclass, field
from fnmatch import fnmatch
from pathlib import Path

PKG = "pngail_jax"
BUILTINS = set(dir(builtins))


# ----------------------------------------------------------------------------- index
@dataclass
class ClassInfo:
    module: str
    name: str
    node: ast.ClassDef
    methods: dict = field(default_factory=dict)  # name -> FunctionDef
    fields: dict = field(default_factory=dict)  # name -> annotation expr (class level)
    assigns_self: bool = False  # some method assigns self.x


@dataclass
class ModuleInfo:
    name: str  # relative to pngail_jax ("" for the package)
    path: Path
    tree: ast.Module
    is_package: bool
    defs: dict = field(
        default_factory=dict
    )  # top-level name -> ("func", node) | ("class", ClassInfo)
    imports: dict = field(
        default_factory=dict
    )  # local name -> ("mod", rel) | ("sym", rel, name) | ("ext", dotted)


def _self_assigns(fn: ast.FunctionDef) -> bool:
    if not fn.args.args:
        return False
    me = fn.args.args[0].arg
    for node in ast.walk(fn):
        targets = []
        if isinstance(node, ast.Assign):
            targets = node.targets
        elif isinstance(node, (ast.AnnAssign, ast.AugAssign)):
            targets = [node.target]
        for t in targets:
            for sub in ast.walk(t):
                if (
                    isinstance(sub, ast.Attribute)
                    and isinstance(sub.value, ast.Name)
                    and sub.value.id == me
                ):
                    return True
    return False


class Index:
    def __init__(self, root: Path):
        self.root = root
        self.modules: dict[str, ModuleInfo] = {}
        pkg = root / PKG
        for path in sorted(pkg.rglob("*.py")):
            parts = list(path.relative_to(pkg).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            if is_package:
                parts = parts[:-1]
            name = ".".join(parts)
            info = ModuleInfo(name, path, ast.parse(path.read_text(), str(path)), is_package)
            self.modules[name] = info
        for info in self.modules.values():
            self._read(info)

    def _read(self, info: ModuleInfo) -> None:
        for node in info.tree.body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                info.defs[node.name] = ("func", node)
            elif isinstance(node, ast.ClassDef):
                cls = ClassInfo(info.name, node.name, node)
                for item in node.body:
                    if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                        cls.methods[item.name] = item
                        cls.assigns_self |= _self_assigns(item)
                    elif isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
                        cls.fields[item.target.id] = item.annotation
                info.defs[node.name] = ("class", cls)
        package = info.name.split(".") if info.is_package else info.name.split(".")[:-1]
        package = [p for p in package if p]
        for node in ast.walk(info.tree):  # imports anywhere in the module, functions too
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name == PKG or alias.name.startswith(PKG + "."):
                        rel = alias.name[len(PKG) + 1 :]
                        if alias.asname:
                            info.imports[alias.asname] = ("mod", rel)
                        else:  # import pngail_jax.x.y binds pngail_jax
                            info.imports[PKG] = ("mod", "")
                    else:
                        local = alias.asname or alias.name.split(".")[0]
                        info.imports[local] = ("ext", alias.name if alias.asname else local)
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package[: len(package) - (node.level - 1)] if node.level > 1 else package
                    source = ".".join(base + ([node.module] if node.module else []))
                    internal = True
                else:
                    internal = node.module == PKG or (node.module or "").startswith(PKG + ".")
                    source = (node.module or "")[len(PKG) + 1 :] if internal else node.module
                for alias in node.names:
                    local = alias.asname or alias.name
                    if not internal:
                        info.imports[local] = ("ext", f"{source}.{alias.name}")
                        continue
                    sub = f"{source}.{alias.name}" if source else alias.name
                    if sub in self.modules:
                        info.imports[local] = ("mod", sub)
                    else:
                        info.imports[local] = ("sym", source, alias.name)

    def symbol(self, module: str, name: str, depth: int = 0):
        """What ``name`` is in ``module``: ("func", mod, node) | ("class", ClassInfo) |
        ("mod", rel) | ("ext", dotted) | None."""
        if depth > 20 or module not in self.modules:
            return None
        info = self.modules[module]
        if name in info.defs:
            kind, obj = info.defs[name]
            return ("func", module, obj) if kind == "func" else ("class", obj)
        if name in info.imports:
            imp = info.imports[name]
            if imp[0] == "sym":
                return self.symbol(imp[1], imp[2], depth + 1)
            return imp
        sub = f"{module}.{name}" if module else name
        if sub in self.modules:
            return ("mod", sub)
        return None

    def find_method(self, cls: ClassInfo, name: str, depth: int = 0):
        """(ClassInfo owning it, FunctionDef) through pngail_jax bases, or None."""
        if depth > 20:
            return None
        if name in cls.methods:
            return cls, cls.methods[name]
        for base in cls.node.bases:
            ref = self.static_ref(cls.module, base)
            if ref and ref[0] == "class":
                found = self.find_method(ref[1], name, depth + 1)
                if found:
                    return found
        return None

    def static_ref(self, module: str, expr):
        """A Name/Attribute chain naming a module, class, function or external thing."""
        if isinstance(expr, ast.Name):
            got = self.symbol(module, expr.id)
            if got is None and expr.id in BUILTINS:
                return ("ext", expr.id)
            return got
        if isinstance(expr, ast.Attribute):
            base = self.static_ref(module, expr.value)
            if base is None:
                return None
            if base[0] == "mod":
                return self.symbol(base[1], expr.attr)
            if base[0] == "ext":
                return ("ext", f"{base[1]}.{expr.attr}")
            if base[0] == "class":
                found = self.find_method(base[1], expr.attr)
                if found:
                    return ("method", found[0], found[1])
                return None
        return None

    def annotation_class(self, module: str, ann):
        """The first pngail_jax class an annotation names (``X | None``, ``Optional[X]``,
        ``"X"``)."""
        if ann is None:
            return None
        if isinstance(ann, ast.Constant) and isinstance(ann.value, str):
            try:
                ann = ast.parse(ann.value, mode="eval").body
            except SyntaxError:
                return None
        if isinstance(ann, ast.BinOp):
            return self.annotation_class(module, ann.left) or self.annotation_class(
                module, ann.right
            )
        if isinstance(ann, ast.Subscript):
            head = ann.value
            if isinstance(head, (ast.Name, ast.Attribute)) and getattr(
                head, "id", getattr(head, "attr", "")
            ) in (
                "Optional",
                "Union",
            ):
                inner = ann.slice
                items = inner.elts if isinstance(inner, ast.Tuple) else [inner]
                for item in items:
                    got = self.annotation_class(module, item)
                    if got:
                        return got
            return None
        ref = self.static_ref(module, ann)
        if ref and ref[0] == "class":
            return ref[1]
        return None


# ----------------------------------------------------------------------------- layers
def read_layers(root: Path):
    tree = ast.parse((root / "tests" / "test_layers.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "LAYERS" for t in node.targets
        ):
            return ast.literal_eval(node.value)
    raise SystemExit("no LAYERS in tests/test_layers.py")


def layer_of(module: str, layers) -> int | None:
    for i, (_, patterns) in enumerate(layers):
        if any(fnmatch(module, p) for p in patterns):
            return i
    return None


# ----------------------------------------------------------------------------- the walk
def is_config_class(cls: ClassInfo) -> bool:
    """Objects mode's config objects: pngail_jax's data-like classes named ``*Config`` or
    ``*Settings`` (the run config, its parts, and the forms the trainers take it in)."""
    return not cls.assigns_self and cls.name.endswith(("Config", "Settings"))


def fkey(module: str, cls: ClassInfo | None, fn) -> tuple[str, str]:
    return (module, f"{cls.name}.{fn.name}" if cls else fn.name)


def _params(fn):
    a = fn.args
    return [p.arg for p in a.posonlyargs + a.args], [p.arg for p in a.kwonlyargs], a.vararg, a.kwarg


def _decorators(fn) -> set[str]:
    out = set()
    for d in fn.decorator_list:
        if isinstance(d, ast.Name):
            out.add(d.id)
        elif isinstance(d, ast.Attribute):
            out.add(d.attr)
    return out


def _own_nodes(fn):
    """Every node of a function's body, nested defs and lambdas included (read inline)."""
    for stmt in fn.body:
        yield from ast.walk(stmt)


class Walk:
    def __init__(self, index: Index, carrying_attrs: set, objects: bool = False):
        self.ix = index
        self.objects = objects  # follow config objects only (see "Objects mode")
        self.carrying_attrs = set(carrying_attrs)  # {(module, class, attr)}
        self.attr_types: dict = {}  # (module, class, attr) -> ClassInfo
        self.memo: dict = {}  # fkey -> (frozenset tracked, {param: ClassInfo})
        self.stack: list = []
        self.visit_order: list = []  # fkeys at each (re)walk start, DFS order
        self.stays: dict = {}  # fkey -> first visit number
        self.rooms_order: list = []
        self.rooms: set = set()
        self.edges: dict = {}  # (caller fkey, callee fkey) -> dict(first=int, reentry=bool)
        self.inner_edges: set = set()
        self.tallies: dict = {k: {} for k in ("external", "closure", "no-body", "unresolved")}
        self.events = 0

    # -- entering a function
    def visit(self, module, cls, fn, tracked: set, types: dict, caller=None):
        key = fkey(module, cls, fn)
        old = self.memo.get(key)
        if old is not None:
            new_tracked = old[0] | tracked
            new_types = dict(old[1])
            for k, v in types.items():
                new_types.setdefault(k, v)
            if new_tracked == old[0] and new_types.keys() == old[1].keys():
                return
            self.memo[key] = (frozenset(new_tracked), new_types)
            if key in self.stack:
                return
            tracked, types = set(new_tracked), new_types
        else:
            self.memo[key] = (frozenset(tracked), dict(types))
        if key not in self.stays:
            self.stays[key] = len(self.stays)
        if module not in self.rooms:
            self.rooms.add(module)
            self.rooms_order.append(module)
        self.visit_order.append(key)
        self.stack.append(key)
        try:
            Body(self, module, cls, fn, tracked, types).walk()
        finally:
            self.stack.pop()

    def edge(self, caller, callee):
        if caller[0] == callee[0]:
            self.inner_edges.add((caller, callee))
            return
        if (caller, callee) not in self.edges:
            self.events += 1
            self.edges[(caller, callee)] = {
                "order": self.events,
                "reentry": callee[0] in self.rooms,
                "on_stack": callee[0] in {k[0] for k in self.stack},
            }

    def tally(self, kind, module, node, text):
        self.tallies[kind].setdefault((module, node.lineno, node.col_offset), text)


class Body:
    """One function's walk: its carrying names, then its calls in source order."""

    def __init__(self, walk: Walk, module, cls, fn, tracked, types):
        self.w, self.ix = walk, walk.ix
        self.module, self.cls, self.fn = module, cls, fn
        self.key = fkey(module, cls, fn)
        self.tracked = set(tracked)
        self.types: dict = {}
        pos, kwonly, _, _ = _params(fn)
        self.self_name = (
            pos[0] if cls is not None and pos and "staticmethod" not in _decorators(fn) else None
        )
        all_params = fn.args.posonlyargs + fn.args.args + fn.args.kwonlyargs
        for p in all_params:
            got = self.ix.annotation_class(module, p.annotation)
            if got is None:
                got = types.get(p.arg)
            if got is not None:
                self.types[p.arg] = got
        if self.self_name and cls is not None:
            self.types[self.self_name] = cls
        self.locals_defs = {
            n.name for n in _own_nodes(fn) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))
        }
        self._fixpoint()

    # -- carrying
    def self_attr_carries(self, attr: str) -> bool:
        if self.cls is None:
            return False
        if (self.cls.module, self.cls.name, attr) in self.w.carrying_attrs:
            return True
        return self.self_name in self.tracked and not self.cls.assigns_self

    def carries(self, expr) -> bool:
        found = self._contains_carrying(expr)
        if not found or not self.w.objects or isinstance(expr, ast.Name):
            return found
        return self._is_config_object(expr)

    def _is_config_object(self, expr) -> bool:
        """Objects mode: a carrying expression counts only when its value is a config object
        (its inferred class is data-like), or ``replace(obj, ...)`` of one."""
        if isinstance(expr, ast.Call) and expr.args:
            f = expr.func
            callee = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None)
            if callee == "replace" and self._contains_carrying(expr.args[0]):
                return self._is_config_object(expr.args[0])
        if (
            isinstance(expr, ast.Name)
            or isinstance(expr, ast.Attribute)
            and self.self_name
            and isinstance(expr.value, ast.Name)
            and expr.value.id == self.self_name
            and (self.cls.module, self.cls.name, expr.attr) in self.w.carrying_attrs
        ):
            return True
        t = self.etype(expr)
        return t is not None and is_config_class(t)

    def _holds_config(self, receiver) -> bool:
        """Objects mode: a method called on an object that keeps a config object in an
        attribute (``self.config = config``) is followed, its ``self`` tracked."""
        if not self.w.objects:
            return False
        t = self.etype(receiver)
        return t is not None and any(
            (m, c) == (t.module, t.name) for m, c, _ in self.w.carrying_attrs
        )

    def _contains_carrying(self, expr) -> bool:
        if expr is None:
            return False
        if isinstance(expr, ast.Name):
            return expr.id in self.tracked
        if (
            isinstance(expr, ast.Attribute)
            and self.self_name
            and isinstance(expr.value, ast.Name)
            and expr.value.id == self.self_name
        ):
            return self.self_attr_carries(expr.attr)
        return any(self._contains_carrying(child) for child in ast.iter_child_nodes(expr))

    def _mark(self, target, value_carries: bool, value=None) -> bool:
        changed = False
        if isinstance(target, (ast.Tuple, ast.List)):
            if (
                isinstance(value, (ast.Tuple, ast.List))
                and len(value.elts) == len(target.elts)
                and not any(isinstance(e, ast.Starred) for e in target.elts + value.elts)
            ):
                for t, v in zip(target.elts, value.elts, strict=True):
                    changed |= self._mark(t, self.carries(v), v)
            else:
                for t in target.elts:
                    changed |= self._mark(t, value_carries, None)
            return changed
        if isinstance(target, ast.Starred):
            return self._mark(target.value, value_carries, None)
        if isinstance(target, ast.Name):
            if value is not None and target.id not in self.types:
                t = self.etype(value)
                if t is not None:
                    self.types[target.id] = t
                    changed = True
            if value_carries and target.id not in self.tracked:
                self.tracked.add(target.id)
                changed = True
            return changed
        if isinstance(target, ast.Attribute):
            if (
                self.self_name
                and isinstance(target.value, ast.Name)
                and target.value.id == self.self_name
                and self.cls
            ):
                k = (self.cls.module, self.cls.name, target.attr)
                if value is not None and k not in self.w.attr_types:
                    t = self.etype(value)
                    if t is not None:
                        self.w.attr_types[k] = t
                if value_carries and k not in self.w.carrying_attrs:
                    self.w.carrying_attrs.add(k)
                    changed = True
            return changed
        if isinstance(target, ast.Subscript):
            base = target.value
            while isinstance(base, (ast.Subscript, ast.Attribute)):
                base = base.value
            if isinstance(base, ast.Name) and value_carries and base.id not in self.tracked:
                self.tracked.add(base.id)
                return True
        return changed

    def _fixpoint(self):
        nodes = list(_own_nodes(self.fn))
        for _ in range(50):
            changed = False
            for n in nodes:
                if isinstance(n, ast.Assign):
                    c = self.carries(n.value)
                    for t in n.targets:
                        changed |= self._mark(t, c, n.value)
                elif isinstance(n, ast.AnnAssign):
                    if isinstance(n.target, ast.Name) and n.target.id not in self.types:
                        t = self.ix.annotation_class(self.module, n.annotation)
                        if t is not None:
                            self.types[n.target.id] = t
                            changed = True
                    if n.value is not None:
                        changed |= self._mark(n.target, self.carries(n.value), n.value)
                elif isinstance(n, ast.AugAssign):
                    changed |= self._mark(n.target, self.carries(n.value), None)
                elif isinstance(n, (ast.For, ast.AsyncFor, ast.comprehension)):
                    changed |= self._mark(n.target, self.carries(n.iter), None)
                elif isinstance(n, ast.withitem) and n.optional_vars is not None:
                    changed |= self._mark(n.optional_vars, self.carries(n.context_expr), None)
                elif isinstance(n, ast.NamedExpr):
                    changed |= self._mark(n.target, self.carries(n.value), n.value)
            if not changed:
                return

    # -- types
    def etype(self, expr):
        if isinstance(expr, ast.Name):
            return self.types.get(expr.id)
        if isinstance(expr, ast.Attribute):
            base = self.etype(expr.value)
            if base is None:
                return None
            return self.attr_type(base, expr.attr)
        if isinstance(expr, ast.Call):
            target = self.resolve(expr)
            if target[0] == "func":
                _, module, cls, fn, _bound = target
                if fn.name in ("__init__", "__post_init__") and cls is not None:
                    return cls
                return self.ix.annotation_class(module, fn.returns)
            if target[0] == "no-body":
                return target[1]
        return None

    def attr_type(self, cls: ClassInfo, attr: str, depth=0):
        if attr in cls.fields:
            return self.ix.annotation_class(cls.module, cls.fields[attr])
        found = self.ix.find_method(cls, attr)
        if found and "property" in _decorators(found[1]):
            return self.ix.annotation_class(found[0].module, found[1].returns)
        return self.w.attr_types.get((cls.module, cls.name, attr))

    # -- calls
    def resolve(self, call: ast.Call):
        """("func", module, ClassInfo|None, FunctionDef, skip_first) | ("no-body", cls) |
        ("external", text) | ("closure", text) | ("unresolved", text)."""
        f = call.func
        text = ast.unparse(f)
        if isinstance(f, ast.Name):
            if f.id in self.locals_defs:
                return ("closure", text)
            params = {
                a.arg
                for a in self.fn.args.posonlyargs + self.fn.args.args + self.fn.args.kwonlyargs
            }
            if f.id in params:
                return ("unresolved", f"{text} (a parameter)")
            return self._from_ref(self.ix.static_ref(self.module, f), text, bound=False)
        if isinstance(f, ast.Attribute):
            v = f.value
            # super().m(...)
            if (
                isinstance(v, ast.Call)
                and isinstance(v.func, ast.Name)
                and v.func.id == "super"
                and self.cls
            ):
                for base in self.cls.node.bases:
                    ref = self.ix.static_ref(self.cls.module, base)
                    if ref and ref[0] == "class":
                        found = self.ix.find_method(ref[1], f.attr)
                        if found:
                            return ("func", found[0].module, found[0], found[1], True)
                return ("external", text)
            # self.m(...)
            if self.self_name and isinstance(v, ast.Name) and v.id == self.self_name and self.cls:
                found = self.ix.find_method(self.cls, f.attr)
                if found:
                    return self._method(found, bound=True)
                return ("unresolved", f"{text} (not a method of {self.cls.name})")
            # a static chain: module.f, module.Class, Class.m, np.x
            is_local = isinstance(v, ast.Name) and (
                v.id in self.tracked or v.id in self.types or self._is_local(v.id)
            )
            if not is_local:
                ref = self.ix.static_ref(self.module, f)
                if ref is not None:
                    return self._from_ref(ref, text, bound=False)
                base = self.ix.static_ref(self.module, v)
                if base is not None and base[0] == "ext":
                    return ("external", text)
            # obj.m(...) with obj's class inferred
            t = self.etype(v)
            if t is not None:
                found = self.ix.find_method(t, f.attr)
                if found:
                    return self._method(found, bound=True)
                return ("unresolved", f"{text} (no method {f.attr} in {t.name})")
            return ("unresolved", f"{text} (receiver's class unknown)")
        return ("unresolved", f"{text} (a computed callee)")

    def _is_local(self, name: str) -> bool:
        a = self.fn.args
        return name in {p.arg for p in a.posonlyargs + a.args + a.kwonlyargs} | (
            {a.vararg.arg} if a.vararg else set()
        ) | ({a.kwarg.arg} if a.kwarg else set())

    def _method(self, found, bound: bool):
        owner, fn = found
        decos = _decorators(fn)
        if "staticmethod" in decos:
            skip = False
        elif "classmethod" in decos:
            skip = True
        else:
            skip = bound
        return ("func", owner.module, owner, fn, skip)

    def _from_ref(self, ref, text, bound):
        if ref is None:
            return ("unresolved", text)
        kind = ref[0]
        if kind == "func":
            return ("func", ref[1], None, ref[2], False)
        if kind == "method":
            return self._method((ref[1], ref[2]), bound=False)
        if kind == "class":
            cls = ref[1]
            for name in ("__init__", "__post_init__"):
                found = self.ix.find_method(cls, name)
                if found:
                    return ("func", found[0].module, found[0], found[1], True)
            return ("no-body", cls)
        if kind == "ext":
            return ("external", text)
        return ("unresolved", f"{text} (a module)")

    def walk(self):
        calls = [n for n in _own_nodes(self.fn) if isinstance(n, ast.Call)]
        # evaluation order: a call's arguments (which end first) before the call itself
        calls.sort(key=lambda n: (n.end_lineno, n.end_col_offset, n.lineno, n.col_offset))
        for call in calls:
            self.call(call)

    def call(self, call: ast.Call):
        f = call.func
        receiver = f.value if isinstance(f, ast.Attribute) else None
        receiver_carries = receiver is not None and (
            self.carries(receiver) or self._holds_config(receiver)
        )
        args_carry = [self.carries(a) for a in call.args]
        kw_carry = [self.carries(k.value) for k in call.keywords]
        if not (receiver_carries or any(args_carry) or any(kw_carry)):
            return
        target = self.resolve(call)
        kind = target[0]
        if kind != "func":
            name = kind if kind != "no-body" else "no-body"
            text = target[1] if kind != "no-body" else f"{target[1].name}(...)"
            self.w.tally(name, self.module, call, text)
            return
        _, module, cls, fn, skip_first = target
        tracked, types = self._bind(call, fn, skip_first, receiver, receiver_carries, args_carry,
                                    kw_carry)  # fmt: skip
        callee = fkey(module, cls, fn)
        self.w.edge(self.key, callee)
        self.w.visit(module, cls, fn, tracked, types, caller=self.key)

    def _bind(self, call, fn, skip_first, receiver, receiver_carries, args_carry, kw_carry):
        """The callee's parameters that receive the config (tracked) and their known types."""
        pos, kwonly, vararg, kwarg = _params(fn)
        tracked, types = set(), {}
        if skip_first and pos:
            first, pos = pos[0], pos[1:]
            is_ctor = fn.name in ("__init__",)
            if fn.name == "__post_init__" and (any(args_carry) or any(kw_carry)):
                tracked.add(first)
            elif receiver_carries and not is_ctor:
                tracked.add(first)
            if receiver is not None and not is_ctor:
                t = self.etype(receiver)
                if t is not None:
                    types[first] = t
        for i, (arg, carries) in enumerate(zip(call.args, args_carry, strict=True)):
            arg_type = self.etype(arg)
            if isinstance(arg, ast.Starred):
                if carries:
                    tracked.update(pos[i:])
                    if vararg:
                        tracked.add(vararg.arg)
                continue
            name = pos[i] if i < len(pos) else (vararg.arg if vararg else None)
            if name is None:
                continue
            if carries:
                tracked.add(name)
            if arg_type is not None and i < len(pos):
                types[name] = arg_type
        for kw, carries in zip(call.keywords, kw_carry, strict=True):
            if kw.arg is None:  # **mapping
                if carries:
                    tracked.update(pos + kwonly)
                    if kwarg:
                        tracked.add(kwarg.arg)
                continue
            name = kw.arg if kw.arg in pos or kw.arg in kwonly else (kwarg.arg if kwarg else None)
            if name is None:
                continue
            if carries:
                tracked.add(name)
            t = self.etype(kw.value)
            if t is not None and name == kw.arg:
                types[name] = t
        return tracked, types


def run_walk(root: Path, objects: bool = False):
    index = Index(root)
    info = index.modules["jobs.sweep"]
    fn = info.defs["run"][1]
    # RunConfig's module: config/run_config.py since issue 74, run_config.py at the root before.
    found = index.symbol("config.run_config", "RunConfig")
    found = found or index.symbol("run_config", "RunConfig")
    run_config = found[1]
    attrs: set = set()
    for passes in range(1, 20):  # noqa: B007 (the count is reported)
        w = Walk(index, attrs, objects)
        w.visit("jobs.sweep", None, fn, {"config"}, {"config": run_config})
        if w.carrying_attrs == attrs:
            break
        attrs = set(w.carrying_attrs)
    return index, w, passes


def name(key):
    return f"{key[0]}:{key[1]}"


def pairs(edges, directed: bool) -> list:
    """The room pairs of ``edges``, most common first (``a -> b``, or ``a <-> b`` unordered)."""
    c = Counter()
    for a, b in edges:
        if directed:
            c[f"{a[0] or PKG} -> {b[0] or PKG}"] += 1
        else:
            x, y = sorted([a[0], b[0]])
            c[f"{x} <-> {y}"] += 1
    return c.most_common()


def _layer_name(room: str, layers) -> str:
    index = layer_of(room, layers)
    return layers[index][0] if index is not None else "?"


def _unresolved_kind(text: str) -> str:
    if "receiver's class unknown" in text:
        return "method on an object of unknown class"
    if "(a parameter)" in text:
        return "calling a parameter"
    if "not a method" in text or "no method" in text:
        return "method not found in the inferred class"
    return "other (local value, computed callee)"


def report(root: Path, trace: bool = False, objects: bool = False):
    index, w, passes = run_walk(root, objects)
    layers = read_layers(root)
    up, reentry, on_stack = [], [], []
    for (a, b), meta in sorted(w.edges.items(), key=lambda kv: kv[1]["order"]):
        la, lb = layer_of(a[0], layers), layer_of(b[0], layers)
        if la is not None and lb is not None and lb > la:
            up.append((a, b))
        if meta["reentry"]:
            reentry.append((a, b))
        if meta["on_stack"]:
            on_stack.append((a, b))

    rooms = w.rooms_order
    out = {
        "root": str(root),
        "passes": passes,
        "stays": len(w.stays),
        "rooms": len(rooms),
        "edges_cross_module": len(w.edges),
        "edges_within_module": len(w.inner_edges),
        "climbs_up_layer": len(up),
        "climbs_reentry": len(reentry),
        "climbs_reentry_on_stack": len(on_stack),
        "calls_unresolved": len(w.tallies["unresolved"]),
        "calls_external": len(w.tallies["external"]),
        "calls_closure": len(w.tallies["closure"]),
        "calls_no_body": len(w.tallies["no-body"]),
        "rooms_list": [f"{r or PKG} (layer {_layer_name(r, layers)})" for r in rooms],
        "stays_list": [name(k) for k in sorted(w.stays, key=w.stays.get)],
        "up_layer_edges": [f"{name(a)} -> {name(b)}" for a, b in up],
        "reentry_edges": [f"{name(a)} -> {name(b)}" for a, b in reentry],
        "up_layer_pairs_directed": pairs(up, True),
        "up_layer_pairs": pairs(up, False),
        "reentry_pairs_directed": pairs(reentry, True),
        "reentry_pairs": pairs(reentry, False),
        "on_stack_edges": [f"{name(a)} -> {name(b)}" for a, b in on_stack],
        "on_stack_pairs_directed": pairs(on_stack, True),
        "reentry_pairs_by_room_pair_count": len(pairs(reentry, False)),
        "unresolved_kinds": Counter(
            _unresolved_kind(t) for t in w.tallies["unresolved"].values()
        ).most_common(),
        "unresolved": sorted(f"{m}:{n} {t}" for (m, n, _), t in w.tallies["unresolved"].items()),
        "no_body": sorted(f"{m}:{n} {t}" for (m, n, _), t in w.tallies["no-body"].items()),
        "carrying_attrs": sorted(".".join(x) for x in w.carrying_attrs),
    }
    if trace:
        out["walk_order"] = [name(k) for k in w.visit_order]
        out["all_edges"] = [
            f"{m['order']:3d} {name(a)} -> {name(b)}{'  [re-entry]' if m['reentry'] else ''}"
            f"{'[on-stack]' if m['on_stack'] else ''}"
            for (a, b), m in sorted(w.edges.items(), key=lambda kv: kv[1]["order"])
        ]
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("root", type=Path)
    parser.add_argument("--json", type=Path)
    parser.add_argument("--trace", action="store_true")
    parser.add_argument(
        "--objects",
        action="store_true",
        help="follow config objects only, not values read from them",
    )
    args = parser.parse_args(argv)
    out = report(args.root, args.trace, args.objects)
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    print(
        f"{out['root']}: {out['stays']} stays in {out['rooms']} rooms; climbs: "
        f"{out['climbs_up_layer']} up-layer (a), {out['climbs_reentry']} re-entries (b), "
        f"{out['climbs_reentry_on_stack']} of them into a room on the stack (b'); "
        f"{out['edges_cross_module']} cross-module edges; unresolved calls "
        f"{out['calls_unresolved']} (external {out['calls_external']}, closure "
        f"{out['calls_closure']}, no-body {out['calls_no_body']}); passes {out['passes']}"
    )
    return out


if __name__ == "__main__":
    main()
