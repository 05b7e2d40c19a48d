"""Each compiled module's ``.pxd`` matches its ``.py`` (docs/architecture.md, "Changing a core
module"): the C declarations name what the source has, so an edit of the source that renames an
argument, a local, a field or a function cannot leave a declaration behind that types nothing,
or one that Cython would reject only at the next build.

- every ``cdef class`` of the ``.pxd`` is a class of the ``.py``, with the same base;
- every ``cdef``/``cpdef`` function or method is defined in the ``.py`` at the same place, with
  the same argument names in the same order and a default (``=*``) where the source has one;
- every field of a ``cdef class`` is named in the class (``self.NAME`` in a method, in it or in a
  base class of the module, a name of its ``__slots__`` or at the class's level); every
  module-level C variable is a module-level name of the ``.py``;
- every name of a ``@cython.locals(...)`` (in the ``.pxd`` or in the ``.py``) is an argument of
  the function it decorates or a local assigned in it.

A ``cdef inline`` function written in full in the ``.pxd`` (a body, no ``.py`` twin) is the
``.pxd``'s own and is not compared. The check reads the files with ``ast`` and a small reader of
the ``.pxd``'s declarations: no Cython, no compiler, well under a second for the whole core.
"""

from __future__ import annotations

import ast
import re
import time
from dataclasses import dataclass, field

from helpers import REPO

from humanoid_twin.core_modules import CORE_MODULES, source_path

ROOT = REPO


# ---- the .pxd's declarations -----------------------------------------------------------------

@dataclass
class PxdFunction:
    name: str
    args: list[str]
    defaults: set[str]
    locals_: list[str]
    line: int


@dataclass
class PxdClass:
    name: str
    base: str | None
    line: int
    fields: list[tuple[str, int]] = field(default_factory=list)
    methods: list[PxdFunction] = field(default_factory=list)


@dataclass
class Pxd:
    classes: list[PxdClass] = field(default_factory=list)
    functions: list[PxdFunction] = field(default_factory=list)
    variables: list[tuple[str, int]] = field(default_factory=list)


def _strip_comment(line: str) -> str:
    quote = None
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch == "#":
            return line[:i]
    return line


def _statements(text: str) -> list[tuple[int, int, str]]:
    """(line number, indentation, statement) for each logical line: comments dropped, lines
    inside brackets joined."""
    out: list[tuple[int, int, str]] = []
    buf, start, indent, depth = "", 0, 0, 0
    for n, raw in enumerate(text.splitlines(), 1):
        line = _strip_comment(raw).rstrip()
        if not buf:
            if not line.strip():
                continue
            start, indent = n, len(line) - len(line.lstrip())
        buf += (" " if buf else "") + line.strip()
        depth += sum(line.count(c) for c in "([{") - sum(line.count(c) for c in ")]}")
        if depth <= 0:
            out.append((start, indent, buf))
            buf, depth = "", 0
    return out


def _split_top(text: str) -> list[str]:
    """``text`` split at the commas outside brackets and quotes."""
    parts, depth, quote, cur = [], 0, None, ""
    for ch in text:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(cur)
            cur = ""
            continue
        cur += ch
    if cur.strip():
        parts.append(cur)
    return [p.strip() for p in parts]


_TRAILER = re.compile(r"\s*(?:except\s*[?*+]?\s*[-\w.]*|noexcept|nogil|with\s+gil|const)\s*$")
_ARG_NAME = re.compile(r"(\w+)\s*$")


def _function(stmt: str) -> tuple[str, list[str], set[str]] | None:
    """(name, argument names, those with a default) when ``stmt`` (without its ``cdef``/``cpdef``
    keyword) declares a function; None for a variable."""
    s = stmt
    while True:
        t = _TRAILER.sub("", s)
        if t == s:
            break
        s = t
    if not s.endswith(")"):
        return None
    depth = 0
    for i in range(len(s) - 1, -1, -1):
        depth += {")": 1, "(": -1}.get(s[i], 0)
        if depth == 0:
            break
    head, inner = s[:i].rstrip(), s[i + 1:-1]
    m = re.search(r"(?:^|[\s*&])(\w+)$", head)
    if not m:
        return None           # a C tuple type with no name before it: not a function
    args, defaults = [], set()
    for arg in _split_top(inner):
        decl, _, default = arg.partition("=")
        decl = re.sub(r"\s+(?:not|or)\s+None$", "", decl.strip())
        name = _ARG_NAME.search(decl)
        if name is None:
            continue
        args.append(name.group(1))
        if default:
            defaults.add(name.group(1))
    return m.group(1), args, defaults


def _locals_names(decorator: str) -> list[str]:
    tree = ast.parse(decorator.lstrip("@"), mode="eval").body
    assert isinstance(tree, ast.Call), decorator
    return [k.arg for k in tree.keywords if k.arg]


def _variable_names(decl: str) -> list[str]:
    """The names a C variable declaration (``long long a, b``, ``double[:, ::1] x``, ``char t[8]``)
    declares."""
    names = []
    for i, part in enumerate(_split_top(decl)):
        part = re.sub(r"\[[^\]]*\]$", "", part.strip()).strip()      # an array's size
        m = re.search(r"(\w+)$", part) if i == 0 else re.match(r"\**\s*(\w+)$", part)
        if m:
            names.append(m.group(1))
    return names


def parse_pxd(text: str) -> Pxd:
    """The declarations of an augmenting ``.pxd``."""
    pxd = Pxd()
    cls: PxdClass | None = None
    class_indent = 0
    skip_deeper: int | None = None      # inside a body the .pxd writes itself (inline, struct ...)
    pending_locals: list[str] = []
    for line, indent, stmt in _statements(text):
        if skip_deeper is not None:
            if indent > skip_deeper:
                continue
            skip_deeper = None
        if cls is not None and indent <= class_indent:
            cls = None
        if stmt.startswith("@"):
            if re.match(r"@cython\.locals\s*\(", stmt):
                pending_locals += _locals_names(stmt)
            continue
        if stmt.startswith(("cimport ", "from ", "import ", "include ")) or stmt == "pass":
            continue
        m = re.match(r"cdef\s+class\s+(\w+)\s*(?:\(\s*([\w.]+)\s*\))?\s*(:?)$", stmt)
        if m:
            if m.group(3):      # a forward declaration has no colon
                cls = PxdClass(m.group(1), m.group(2), line)
                class_indent = indent
                pxd.classes.append(cls)
            continue
        m = re.match(r"(cdef|cpdef|ctypedef)\s+(.*)$", stmt)
        if not m:
            raise ValueError(f"line {line}: not understood: {stmt}")
        kind, rest = m.groups()
        if kind == "ctypedef" or re.match(r"(struct|union|enum|extern|packed)\b", rest):
            if rest.endswith(":"):
                skip_deeper = indent
            pending_locals = []
            continue
        body = rest.endswith(":")
        rest = rest.removesuffix(":").rstrip()
        fn = _function(rest)
        if fn is not None:
            if body:                # written in full in the .pxd: its own, not the .py's
                skip_deeper = indent
            else:
                f = PxdFunction(fn[0], fn[1], fn[2], pending_locals, line)
                (cls.methods if cls is not None else pxd.functions).append(f)
            pending_locals = []
            continue
        rest = re.sub(r"^(public|readonly)\s+", "", rest)
        names = [(n, line) for n in _variable_names(rest)]
        (cls.fields if cls is not None else pxd.variables).extend(names)
    return pxd


# ---- the .py's names ---------------------------------------------------------------------------

def _arguments(fn: ast.FunctionDef) -> tuple[list[str], set[str]]:
    a = fn.args
    positional = [x.arg for x in (*a.posonlyargs, *a.args)]
    with_default = set(positional[len(positional) - len(a.defaults):]) if a.defaults else set()
    with_default |= {x.arg for x, d in zip(a.kwonlyargs, a.kw_defaults, strict=True) if d is not None}
    names = positional + ([a.vararg.arg] if a.vararg else []) + [x.arg for x in a.kwonlyargs]
    names += [a.kwarg.arg] if a.kwarg else []
    return names, with_default


def _targets(node: ast.AST) -> set[str]:
    """The names a target binds (a name, a tuple or list of them, a starred one)."""
    if isinstance(node, ast.Name):
        return {node.id}
    if isinstance(node, ast.Starred):
        return _targets(node.value)
    if isinstance(node, ast.Tuple | ast.List):
        return set().union(*(_targets(e) for e in node.elts)) if node.elts else set()
    return set()


def _own_nodes(fn: ast.AST) -> list[ast.AST]:
    """The nodes of a function's own body: not those of a nested function, class, lambda or
    comprehension (their names are not the function's locals)."""
    out, todo = [], list(ast.iter_child_nodes(fn))
    nested = (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Lambda, ast.ListComp,
              ast.SetComp, ast.DictComp, ast.GeneratorExp)
    while todo:
        node = todo.pop()
        out.append(node)
        if not isinstance(node, nested):
            todo.extend(ast.iter_child_nodes(node))
    return out


def assigned_locals(fn: ast.FunctionDef) -> set[str]:
    """The names a function assigns in its own body."""
    names: set[str] = set()
    for node in _own_nodes(fn):
        if isinstance(node, ast.Assign):
            for t in node.targets:
                names |= _targets(t)
        elif isinstance(node, ast.AugAssign | ast.AnnAssign | ast.For | ast.NamedExpr):
            names |= _targets(node.target)
        elif isinstance(node, ast.withitem) and node.optional_vars is not None:
            names |= _targets(node.optional_vars)
        elif isinstance(node, ast.ExceptHandler) and node.name:
            names.add(node.name)
        elif isinstance(node, ast.Import | ast.ImportFrom):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names}
    return names


def _class_fields(cls: ast.ClassDef) -> set[str]:
    """The fields a class names: ``self.NAME`` in its methods (set or read), its ``__slots__``,
    the names at the class's level."""
    names: set[str] = set()
    for node in cls.body:
        if isinstance(node, ast.Assign | ast.AnnAssign):
            for t in (node.targets if isinstance(node, ast.Assign) else [node.target]):
                names |= _targets(t)
                if isinstance(t, ast.Name) and t.id == "__slots__" and node.value is not None:
                    names |= {c.value for c in ast.walk(node.value)
                              if isinstance(c, ast.Constant) and isinstance(c.value, str)}
        elif isinstance(node, ast.FunctionDef):
            names |= {sub.attr for sub in ast.walk(node)
                      if isinstance(sub, ast.Attribute) and isinstance(sub.value, ast.Name)
                      and sub.value.id == "self"}
    return names


def _module_level(tree: ast.Module) -> tuple[dict[str, ast.AST], set[str]]:
    """(functions and classes by name, every module-level name) of a module, looking into its
    top-level ``if``/``try``/``with`` blocks (``if cython.compiled:``, an optional import)."""
    defs: dict[str, ast.AST] = {}
    names: set[str] = set()
    todo = list(tree.body)
    while todo:
        node = todo.pop(0)
        if isinstance(node, ast.FunctionDef | ast.ClassDef):
            defs[node.name] = node
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            for t in node.targets:
                names |= _targets(t)
        elif isinstance(node, ast.AnnAssign | ast.AugAssign):
            names |= _targets(node.target)
        elif isinstance(node, ast.Import | ast.ImportFrom):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names}
        elif isinstance(node, ast.If | ast.Try | ast.With):
            for attr in ("body", "orelse", "finalbody", "handlers"):
                todo.extend(getattr(node, attr, []))
        elif isinstance(node, ast.ExceptHandler):
            todo.extend(node.body)
    return defs, names


def _base_name(node: ast.expr) -> str:
    return node.attr if isinstance(node, ast.Attribute) else getattr(node, "id", "?")


def _check_locals(where: str, names: list[str], fn: ast.FunctionDef) -> list[str]:
    args, _ = _arguments(fn)
    known = set(args) | assigned_locals(fn)
    return [f"{where}: @cython.locals names '{n}', neither an argument nor a local of {fn.name}"
            for n in names if n not in known]


def _check_function(where: str, decl: PxdFunction, fn: ast.AST | None) -> list[str]:
    if not isinstance(fn, ast.FunctionDef):
        return [f"{where}: '{decl.name}' is declared but not defined in the .py"]
    args, defaults = _arguments(fn)
    out = []
    if args != decl.args:
        out.append(f"{where}: '{decl.name}' takes ({', '.join(decl.args)}) in the .pxd, "
                   f"({', '.join(args)}) in the .py")
    elif defaults != decl.defaults:
        out.append(f"{where}: '{decl.name}' has defaults for {sorted(decl.defaults)} in the .pxd, "
                   f"{sorted(defaults)} in the .py")
    return out + _check_locals(where, decl.locals_, fn)


def mismatches(py_text: str, pxd_text: str, name: str = "module") -> list[str]:
    """Every declaration of ``pxd_text`` that does not match ``py_text``, one message each."""
    tree = ast.parse(py_text)
    pxd = parse_pxd(pxd_text)
    defs, names = _module_level(tree)
    out: list[str] = []
    for var, line in pxd.variables:
        if var not in names:
            out.append(f"{name}.pxd:{line}: the C variable '{var}' is not a module-level name of the .py")
    for decl in pxd.functions:
        out += _check_function(f"{name}.pxd:{decl.line}", decl, defs.get(decl.name))
    classes = {c.name: c for c in pxd.classes}
    for c in pxd.classes:
        where = f"{name}.pxd:{c.line}"
        node = defs.get(c.name)
        if not isinstance(node, ast.ClassDef):
            out.append(f"{where}: 'cdef class {c.name}' is not a class of the .py")
            continue
        bases = [_base_name(b) for b in node.bases]
        if (c.base or None) != (bases[0] if bases else None) and not (c.base is None and bases == ["object"]):
            out.append(f"{where}: class {c.name} derives from {c.base} in the .pxd, {bases} in the .py")
        fields = _class_fields(node)
        base = c.base
        while base in classes and isinstance(defs.get(base), ast.ClassDef):
            fields |= _class_fields(defs[base])        # type: ignore[arg-type]
            base = classes[base].base
        for f, line in c.fields:
            if f not in fields:
                out.append(f"{name}.pxd:{line}: field '{c.name}.{f}' is not named in the .py's class")
        methods = {n.name: n for n in node.body if isinstance(n, ast.FunctionDef)}
        for decl in c.methods:
            out += _check_function(f"{name}.pxd:{decl.line}", decl, methods.get(decl.name))
    for fn in ast.walk(tree):                   # the .py's own @cython.locals
        if isinstance(fn, ast.FunctionDef):
            for d in fn.decorator_list:
                if (isinstance(d, ast.Call) and isinstance(d.func, ast.Attribute)
                        and d.func.attr == "locals" and _base_name(d.func.value) == "cython"):
                    out += _check_locals(f"{name}.py:{d.lineno}", [k.arg for k in d.keywords if k.arg], fn)
    return out


# ---- the tests ---------------------------------------------------------------------------------

def test_every_pxd_matches_its_py() -> None:
    t0 = time.process_time()
    found: list[str] = []
    for module in CORE_MODULES:
        py = ROOT / source_path(module)
        pxd = py.with_suffix(".pxd")
        if pxd.is_file():           # a module without its .pxd: tests/project/test_core_list.py says so
            found += mismatches(py.read_text(), pxd.read_text(), module.replace(".", "/"))
    assert found == [], "\n".join(found)
    assert time.process_time() - t0 < 1.0


GOOD_PY = '''
import cython

LIMIT = 90

class Base:
    def __init__(self, n):
        self.n = n

class Clock(Base):
    period = 20

    def __init__(self, n, start=0):
        super().__init__(n)
        self.now_us = start

    def run(self, t_us, callback=None):
        total = 0
        for i in range(t_us):
            total += i
        a, (b, c) = 1, (2, 3)
        return total + a + b + c

def shr(v, n):
    out = v >> n
    return out

@cython.locals(k=cython.long)
def twice(x):
    k = 2 * x
    return k
'''

GOOD_PXD = '''
cimport cython
from humanoid_twin.clock cimport Clock as OtherClock

cdef long LIMIT

cdef class Base:
    cdef public long long n

cdef class Clock(Base):
    cdef public long long now_us
    cdef long long[::1] period   # set at the class's level

    @cython.locals(total=cython.longlong, i=cython.longlong,
                   a=cython.long, b=cython.long, c=cython.long)
    cpdef long long run(self, long long t_us, object callback=*) except? -1

@cython.locals(out=cython.longlong)
cpdef long long shr(long long v, long n)

cdef inline long helper(long x):
    return x + 1
'''


def test_a_matching_pair_gives_no_mismatch() -> None:
    assert mismatches(GOOD_PY, GOOD_PXD, "good") == []


def test_each_kind_of_mismatch_is_found() -> None:
    pxd = GOOD_PXD + '''
cdef class Missing:
    pass

cpdef long gone(long x)
cdef long NOT_THERE
'''
    pxd = (pxd.replace("cpdef long long shr(long long v, long n)", "cpdef long long shr(long long v, long m)")
              .replace("a=cython.long,", "a=cython.long, z=cython.long,")
              .replace("cdef public long long now_us", "cdef public long long now_us, later")
              .replace("object callback=*", "object callback")
              .replace("cdef class Clock(Base):", "cdef class Clock:"))
    found = mismatches(GOOD_PY, pxd, "bad")
    expected = [
        "the C variable 'NOT_THERE' is not a module-level name",
        "'gone' is declared but not defined in the .py",
        "'shr' takes (v, m) in the .pxd, (v, n) in the .py",
        "'cdef class Missing' is not a class of the .py",
        "class Clock derives from None in the .pxd, ['Base'] in the .py",
        "field 'Clock.later' is not named",
        "'run' has defaults for [] in the .pxd, ['callback'] in the .py",
        "@cython.locals names 'z', neither an argument nor a local of run",
    ]
    for e in expected:
        assert any(e in f for f in found), f"not found: {e}\n" + "\n".join(found)
    assert len(found) == len(expected), "\n".join(found)


def test_a_locals_name_of_the_py_that_the_function_lacks_is_found() -> None:
    py = GOOD_PY.replace("@cython.locals(k=cython.long)", "@cython.locals(k=cython.long, j=cython.long)")
    (found,) = mismatches(py, GOOD_PXD, "bad")
    assert "bad.py:" in found and "'j', neither an argument nor a local of twice" in found
