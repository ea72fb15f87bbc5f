"""The house rules of docs/ARCHITECTURE.md, read from the source itself (Python's ast, no import of the packages):

- no numba kernel takes more than 20 parameters (state travels in named bundles);
- no function is longer than 150 lines unless a comment right above it says why it cannot be split;
- no file of the four packages is longer than 900 lines;
- the import graph of sgim, dda, adapters and cases (imports inside functions included) has no circle, and every
  import points down the floors cases -> adapters -> dda -> sgim;
- an import inside a function carries a comment saying why it is not at the top of the file: on the statement or
  above it in the function, or once for the file in a comment among the top-level imports.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FLOORS = ("sgim", "dda", "adapters", "cases")  # lowest first: a package imports only its own floor and those below
MAX_PARAMS, MAX_LINES, MAX_FILE = 20, 150, 900


def _modules():
    """{dotted module name: path} of every Python file of the four packages."""
    out = {}
    for pkg in FLOORS:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = path
    return out


MODULES = _modules()
TREES = {name: ast.parse(path.read_text(), str(path)) for name, path in MODULES.items()}


def _functions(tree):
    return [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]


def _is_kernel(fn):
    return any("jit" in ast.unparse(d) for d in fn.decorator_list)


def _n_params(fn):
    a = fn.args
    return len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + bool(a.vararg) + bool(a.kwarg)


def _comment_above(lines, first_line):
    """Whether the line right above `first_line` (1-based; the first decorator or the def) is a comment."""
    i = first_line - 2
    return i >= 0 and lines[i].strip().startswith("#")


def _imported(name, node):
    """The package modules an import statement of module `name` loads."""
    if isinstance(node, ast.Import):
        return {a.name for a in node.names if a.name in MODULES}
    pkg = name if MODULES[name].name == "__init__.py" else name.rpartition(".")[0]
    if node.level:
        base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
        mod = ".".join(base + ([node.module] if node.module else []))
    else:
        mod = node.module or ""
    subs = {f"{mod}.{a.name}" for a in node.names} & MODULES.keys()
    rest = any(f"{mod}.{a.name}" not in MODULES for a in node.names)
    return subs | ({mod} if rest and mod in MODULES else set())


def _graph():
    return {name: {m for node in ast.walk(tree) if isinstance(node, (ast.Import, ast.ImportFrom))
                   for m in _imported(name, node) if m != name}
            for name, tree in TREES.items()}


def _circles(graph):
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_kernels_take_at_most_20_parameters():
    wide = [f"{MODULES[m].relative_to(ROOT)}:{fn.name} ({_n_params(fn)})"
            for m, tree in TREES.items() for fn in _functions(tree) if _is_kernel(fn) and _n_params(fn) > MAX_PARAMS]
    assert not wide, f"kernels with more than {MAX_PARAMS} parameters: {wide}"


def test_long_functions_say_why():
    long = []
    for m, tree in TREES.items():
        lines = MODULES[m].read_text().splitlines()
        for fn in _functions(tree):
            first = min([d.lineno for d in fn.decorator_list] + [fn.lineno])
            if fn.end_lineno - fn.lineno + 1 > MAX_LINES and not _comment_above(lines, first):
                long.append(f"{MODULES[m].relative_to(ROOT)}:{fn.name} ({fn.end_lineno - fn.lineno + 1} lines)")
    assert not long, f"functions over {MAX_LINES} lines without a comment above saying why: {long}"


def test_files_at_most_900_lines():
    big = [f"{p.relative_to(ROOT)} ({n})" for p in MODULES.values()
           if (n := len(p.read_text().splitlines())) > MAX_FILE]
    assert not big, f"files over {MAX_FILE} lines: {big}"


def test_no_import_circle():
    circles = _circles(_graph())
    assert not circles, f"import circles: {circles}"


def test_imports_point_down():
    floor = {pkg: i for i, pkg in enumerate(FLOORS)}
    up = [f"{m} -> {d}" for m, deps in _graph().items() for d in deps
          if floor[d.split(".")[0]] > floor[m.split(".")[0]]]
    assert not up, f"imports pointing up the floors {' <- '.join(FLOORS)}: {up}"


@pytest.mark.parametrize("name", sorted(MODULES))
def test_imports_inside_functions_say_why(name):
    lines = MODULES[name].read_text().splitlines()
    tree = TREES[name]
    first_def = min([n.lineno for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))] + [len(lines)])
    if any(ln.startswith("#") and "import" in ln for ln in lines[:first_def]):
        return  # the file says once why its functions import
    bare = []
    for fn in _functions(tree):
        body = [s for s in ast.walk(fn) if isinstance(s, (ast.Import, ast.ImportFrom))]
        for node in body:
            said = any("#" in ln for ln in lines[fn.lineno - 1: node.lineno])  # in the function, before it
            if not said:
                bare.append(f"line {node.lineno}: {lines[node.lineno - 1].strip()}")
    assert not bare, f"{MODULES[name].relative_to(ROOT)}: imports inside functions without a comment: {bare}"
