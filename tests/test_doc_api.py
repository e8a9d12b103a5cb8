"""Every Python block of README.md and docs/*.md, run or not, speaks the
real, public API: each ``nj.X`` / ``nsga_jax.X`` name (and each name imported from
nsga_jax) exists and is not private, each keyword argument of a call to one of them is a
parameter of its signature, and no adjoint is given as a string."""

from __future__ import annotations

import ast
import importlib
import inspect
import re
from pathlib import Path

import pytest

import nsga_jax

ROOT = Path(__file__).resolve().parents[1]
BLOCKS = [(page.relative_to(ROOT).as_posix(), page.read_text()[:m.start()].count("\n") + 2, m.group(1))
          for page in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
          for m in re.finditer(r"^```python\n(.*?)^```", page.read_text(), re.S | re.M)]


def _attribute(obj, name: str):
    """``obj.name``, or the submodule ``name`` of a package, or ``None``."""
    if hasattr(obj, name):
        return getattr(obj, name)
    if inspect.ismodule(obj):
        try:
            return importlib.import_module(f"{obj.__name__}.{name}")
        except ImportError:
            return None
    return None


def problems(code: str) -> list[str]:
    """What in ``code`` does not match the package (empty for a fragment that does not parse)."""
    try:
        tree = ast.parse(code)
    except SyntaxError:
        return []  # a fragment shown inside a class or a dict (marked "not run" in the page)
    names: dict[str, object] = {"nj": nsga_jax, "nsga_jax": nsga_jax}
    found = []
    for node in ast.walk(tree):
        private = [m for m in ([node.module or ""] if isinstance(node, ast.ImportFrom) else
                               [a.name for a in node.names] if isinstance(node, ast.Import) else [])
                   if m.startswith("nsga_jax._")]
        private += [f"nsga_jax.{node.attr}" for node in [node] if isinstance(node, ast.Attribute)
                    and node.attr.startswith("_") and ast.unparse(node.value) in ("nj", "nsga_jax")]
        found += [f"line {node.lineno}: {m} is private (use the package's public names)" for m in private]
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("nsga_jax"):
            module = importlib.import_module(node.module or "")
            for alias in node.names:
                value = _attribute(module, alias.name)
                if value is None:
                    found.append(f"line {node.lineno}: {node.module} has no {alias.name}")
                names[alias.asname or alias.name] = value

    def resolve(expr: ast.expr):
        if isinstance(expr, ast.Name):
            return names.get(expr.id)
        if isinstance(expr, ast.Attribute):
            base = resolve(expr.value)
            value = None if base is None else _attribute(base, expr.attr)
            if base is not None and value is None and inspect.ismodule(base):
                found.append(f"line {expr.lineno}: {base.__name__} has no {expr.attr}")
            return value
        return None

    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        function = resolve(node.func)
        if function is None or not callable(function):
            continue
        try:
            parameters = inspect.signature(function).parameters
        except (TypeError, ValueError):
            continue
        for kw in node.keywords:
            if kw.arg == "adjoint" and isinstance(kw.value, ast.Constant):
                found.append(f"line {node.lineno}: adjoint={kw.value.value!r} (an adjoint instance is expected)")
            if kw.arg and kw.arg not in parameters and not any(p.kind == p.VAR_KEYWORD for p in parameters.values()):
                found.append(f"line {node.lineno}: {ast.unparse(node.func)}() has no parameter {kw.arg!r}")
    return found


def test_the_pages_have_python_blocks():
    assert len(BLOCKS) > 20


@pytest.mark.parametrize("page, line, code", BLOCKS, ids=[f"{p}:{n}" for p, n, _ in BLOCKS])
def test_python_block_uses_the_real_api(page, line, code):
    assert not problems(code), f"{page}, the block at line {line}: {problems(code)}"


def test_the_checker_sees_a_stale_call():
    assert problems("import nsga_jax as nj\nnj.integrate(m, s, 0, 1, 1e-3, q, v, adjoint='discrete')\n") == [
        "line 2: adjoint='discrete' (an adjoint instance is expected)"]
    assert problems("import nsga_jax as nj\nnj.trajectory(m)\n") == ["line 2: nsga_jax has no trajectory"]
    assert problems("from nsga_jax._batch import simulate_batch\n") == [
        "line 1: nsga_jax._batch is private (use the package's public names)"]
    assert problems("import nsga_jax as nj\nnj.simulate(m, s, 0, 1, 1e-3, q, v, every=2)\n") == [
        "line 2: nj.simulate() has no parameter 'every'"]
