"""Applying a mutant's patches to a file's source, each to one function found by its qualified name.

A patch (:class:`tests.mutants.model.Edit`, ``Replace`` or ``Wrap``) changes
the syntax tree of its function only. The function is then written out again
(``ast.unparse``: its comments are lost, its meaning is not) over its own lines
(decorators included), and every other line of the file is kept as it is. So
a mutant does not depend on how the code is formatted, on comments, or on
whether the same code also occurs elsewhere in the file: it fails only when
its function is gone or no longer holds the code it changes, and then
loudly (an AssertionError naming the mutant, the function and what is
missing), never by silently testing an unmutated renderer.
"""

from __future__ import annotations

import ast
import copy
import io
import textwrap
import tokenize

from tests.mutants.model import Edit, Patch, Replace, Wrap

_DEFS = (ast.FunctionDef, ast.AsyncFunctionDef)


def find_function(tree: ast.Module, qualname: str, where: str = "") -> ast.FunctionDef:
    """The function ``qualname`` (``"f"``, ``"Class.method"``, ``"f.inner"``) of a parsed module: AssertionError
    unless exactly one definition has that name at each level."""
    node: ast.AST = tree
    for part in qualname.split("."):
        found = [n for n in node.body if isinstance(n, (*_DEFS, ast.ClassDef)) and n.name == part]
        assert len(found) == 1, f"{where}: {len(found)} definitions of {part!r} (of {qualname!r}); expected one"
        node = found[0]
    assert isinstance(node, _DEFS), f"{where}: {qualname!r} is a class, not a function"
    return node


def span(fn: ast.FunctionDef) -> tuple[int, int]:
    """The function's lines (1-based, inclusive), its decorators included."""
    return min([d.lineno for d in fn.decorator_list] + [fn.lineno]), fn.end_lineno


def _inside(fn: ast.FunctionDef):
    """Every node of ``fn``'s body (not its decorators, arguments or annotation)."""
    for stmt in fn.body:
        yield from ast.walk(stmt)


def _statement_lists(fn: ast.FunctionDef):
    """Every list of statements inside ``fn`` (its body, the branches of its ifs and loops, nested blocks)."""
    yield fn.body
    for node in _inside(fn):
        for field in ("body", "orelse", "finalbody"):
            stmts = getattr(node, field, None)
            if isinstance(stmts, list) and stmts and isinstance(stmts[0], ast.stmt):
                yield stmts


def _parse(code: str, where: str) -> list[ast.stmt]:
    try:
        return ast.parse(textwrap.dedent(code).strip("\n")).body if code.strip() else []
    except SyntaxError as e:
        raise AssertionError(f"{where}: {textwrap.dedent(code).strip()!r} is not Python ({e.msg})") from None


def _edit(fn: ast.FunctionDef, p: Edit, where: str) -> None:
    old, new = _parse(p.old, where), _parse(p.new, where)
    assert old, f"{where}: an Edit needs the code it changes"
    if len(old) == len(new) == 1 and isinstance(old[0], ast.Expr) and isinstance(new[0], ast.Expr):
        # An expression for an expression, wherever it occurs in the function.
        want = ast.dump(old[0].value)
        hits = [(parent, field, i) for parent in _inside(fn) for field, value in ast.iter_fields(parent)
                for i, child in (enumerate(value) if isinstance(value, list) else [(None, value)])
                if isinstance(child, ast.expr) and ast.dump(child) == want]
        _assert_once(hits, "expression", p.old, where)
        parent, field, i = hits[0]
        if i is None:
            setattr(parent, field, copy.deepcopy(new[0].value))
        else:
            getattr(parent, field)[i] = copy.deepcopy(new[0].value)
        return
    # Statements for statements: a run of consecutive statements in one block.
    want = [ast.dump(s) for s in old]
    hits = [(stmts, i) for stmts in _statement_lists(fn) for i in range(len(stmts) - len(want) + 1)
            if [ast.dump(s) for s in stmts[i:i + len(want)]] == want]
    _assert_once(hits, "statement(s)", p.old, where)
    stmts, i = hits[0]
    stmts[i:i + len(want)] = copy.deepcopy(new) or ([ast.Pass()] if len(stmts) == len(want) else [])


def _assert_once(hits: list, what: str, old: str, where: str) -> None:
    assert len(hits) == 1, (f"{where}: the {what} {textwrap.dedent(old).strip()!r} occur(s) {len(hits)} times in the "
                            f"function (expected exactly once); update the mutant's family module under tests/mutants/ "
                            f"to the refactored source")


def _replace(fn: ast.FunctionDef, p: Replace, where: str) -> ast.FunctionDef:
    defs = _parse(p.source, where)
    assert len(defs) == 1 and isinstance(defs[0], _DEFS) and defs[0].name == fn.name, \
        f"{where}: a Replace's source is one def named {fn.name!r}"
    new = defs[0]
    new.decorator_list = fn.decorator_list
    return new


def _wrap(fn: ast.FunctionDef, p: Wrap, where: str) -> list[ast.stmt]:
    defs = _parse(p.wrapper, where)
    assert len(defs) == 1 and isinstance(defs[0], ast.FunctionDef), f"{where}: a Wrap's wrapper is one def"
    wrapper = defs[0]
    wrapper.name = f"_mutant_wrap_{fn.name}"
    fn.decorator_list.insert(0, ast.Name(wrapper.name, ast.Load()))
    # The wrapper's name is deleted once applied: the module (or class) gains no attribute.
    return [wrapper, fn, ast.Delete([ast.Name(wrapper.name, ast.Del())])]


def _indent(code: str, prefix: str) -> str:
    """``code`` indented by ``prefix``, except the continuation lines of its multi-line strings (a docstring's
    text must not change)."""
    inside = set()
    for tok in tokenize.generate_tokens(io.StringIO(code).readline):
        if tok.type == tokenize.STRING and tok.end[0] > tok.start[0]:
            inside.update(range(tok.start[0] + 1, tok.end[0] + 1))
    return "".join(line if n in inside or not line.strip() else prefix + line
                   for n, line in enumerate(code.splitlines(keepends=True), 1))


def apply_patch(text: str, p: Patch, mutant: str) -> str:
    """``text`` (the source of ``p.file``) with the patch applied: only the lines of ``p.function`` change."""
    where = f"mutant {mutant!r}, {p.function} in {p.file}"
    fn = find_function(ast.parse(text), p.function, where)
    before = ast.dump(fn)
    if isinstance(p, Edit):
        _edit(fn, p, where)
        nodes = [fn]
    elif isinstance(p, Replace):
        nodes = [_replace(fn, p, where)]
    else:
        nodes = _wrap(fn, p, where)
    assert len(nodes) > 1 or ast.dump(nodes[0]) != before, f"{where}: the patch does not change the function"
    code = "\n".join(ast.unparse(ast.fix_missing_locations(n)) for n in nodes) + "\n"
    first, last = span(fn)
    lines = text.splitlines(keepends=True)
    return "".join(lines[:first - 1]) + _indent(code, " " * fn.col_offset) + "".join(lines[last:])


def named_functions(patches) -> dict[str, set[str]]:
    """{file: the qualified names of the functions its patches change}."""
    out: dict[str, set[str]] = {}
    for p in patches:
        out.setdefault(p.file, set()).add(p.function)
    return out
