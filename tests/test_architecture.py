"""The layering of docs/architecture.md, enforced on the source: a module may
import its own layer and the layers below it, never one above, so that the
numerical core never depends on the command line, scenes, files or plots.
Imports inside functions count; imports under ``if TYPE_CHECKING:`` (type
annotations only) do not. Every module must be placed in a layer."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "nsga_jax"

LAYERS: list[tuple[str, set[str]]] = [
    # (layer, top-level modules or subpackages of nsga_jax), from the bottom up
    ("foundation", {"_compat", "_custom_types", "_util", "_results", "_validation", "_precision",
                    "_compilation_cache", "_packaged", "_process_settings"}),
    ("physics", {"_elements", "_assembly", "_blocks", "_models", "_system", "_exact", "_exact_pendulums"}),
    ("numerics", {"_integrators", "_adjoint", "_impact_time", "_impact_time_friction"}),
    ("runs", {"_saveat", "_integrate", "_simulate", "_run_core", "_solution", "_monitors", "_diagnosis", "_batch",
              "_distributed", "_run_inputs", "_chunks", "_memory", "_progress", "_first_step"}),
    ("application", {"_scenes", "_cli", "_cli_options", "_cli_config", "_bench", "_sweep", "_sweep_batches",
                     "_sweep_build", "_sweep_checks", "_grid", "_identify", "_fit_steps", "_data", "_studies",
                     "_output", "_plotting", "_sweep_plot", "_folders", "_tables", "_metrics", "_animate"}),
    # the public API: the package's names, its two public namespaces, and examples/ (a user's scene file)
    ("package", {"__init__", "system", "scenes", "examples"}),
]
PUBLIC = {"__init__", "system", "scenes", "examples"}
LEVEL = {unit: i for i, (_, units) in enumerate(LAYERS) for unit in units}
NAME = {i: name for i, (name, _) in enumerate(LAYERS)}


def unit_of(module: str) -> str:
    """``nsga_jax._integrators.ds`` -> ``integrators``; ``nsga_jax`` -> ``__init__``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _under_type_checking(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> bool:
    while node in parents:
        node = parents[node]
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            return True
    return False


def imports_of(source: str, module: str, is_package: bool = False) -> list[tuple[int, str]]:
    """(line, absolute nsga_jax module) for every import of the package in the
    ``source`` of ``module`` (``is_package``: the source is its ``__init__``)."""
    tree = ast.parse(source)
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    here = module.split(".")
    package = here if is_package else here[:-1]
    found = []
    for node in ast.walk(tree):
        if _under_type_checking(node, parents):
            continue
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
                names = [target] if node.module else [f"{target}.{a.name}" for a in node.names]
            else:
                names = [node.module or ""]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        else:
            continue
        found += [(node.lineno, n) for n in names if n == "nsga_jax" or n.startswith("nsga_jax.")]
    return found


SOURCES = sorted(PACKAGE.rglob("*.py"))


def test_every_module_has_a_layer():
    unplaced = sorted({unit_of(module_name(p)) for p in SOURCES} - set(LEVEL))
    assert not unplaced, f"place these in a layer of tests/test_architecture.py and docs/architecture.md: {unplaced}"


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_module_imports_a_layer_above_its_own(path):
    own = LEVEL[unit_of(module_name(path))]
    upward = [f"line {line}: {target} ({NAME[LEVEL[unit_of(target)]]})"
              for line, target in imports_of(path.read_text(), module_name(path), path.name == "__init__.py")
              if LEVEL.get(unit_of(target), -1) > own]
    assert not upward, f"{path.relative_to(PACKAGE)} ({NAME[own]}) imports from a layer above: {upward}"


def test_the_checker_sees_upward_imports():
    """The checker itself: a lazy import of the command line from inside a
    function of the numerics is found, and one under TYPE_CHECKING is not."""
    source = ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .._solution import Solution\n"
              "def f():\n    from .._cli import main\n    return main\n")
    found = imports_of(source, "nsga_jax._integrators.probe")
    assert found == [(5, "nsga_jax._cli")]
    assert LEVEL[unit_of("nsga_jax._cli")] > LEVEL[unit_of("nsga_jax._integrators.probe")]
    assert imports_of("from . import _results\n", "nsga_jax", is_package=True) == [(1, "nsga_jax._results")]


def private_names_imported(source: str, module: str, is_package: bool = False) -> list[str]:
    """``module.name`` for every ``from nsga_jax.module import _name`` where
    ``_name`` is a private name of another module (not a module itself)."""
    found = []
    here = module.split(".")
    package = here if is_package else here[:-1]
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.ImportFrom) or node.module == "__future__":
            continue
        base = ".".join(package[: len(package) - node.level + 1] + ([node.module] if node.module else [])) \
            if node.level else (node.module or "")
        if not base.startswith("nsga_jax"):
            continue
        for alias in node.names:
            target = PACKAGE.parent.joinpath(*base.split("."), alias.name)
            is_module = target.with_suffix(".py").exists() or (target / "__init__.py").exists()
            if alias.name.startswith("_") and not is_module:
                found.append(f"{base}.{alias.name}")
    return found


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_module_imports_another_modules_private_names(path):
    private = private_names_imported(path.read_text(), module_name(path), path.name == "__init__.py")
    assert not private, f"{path.relative_to(PACKAGE)} imports private names: {private}"


def test_the_private_name_checker_sees_them():
    assert private_names_imported("from .._precision import _hidden, precision\n", "nsga_jax._integrators.ds") == [
        "nsga_jax._precision._hidden"]
    assert private_names_imported("from . import _custom_types\n", "nsga_jax._solution") == []


def import_graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports (at the top or inside a
    function; not under TYPE_CHECKING). ``from .x import name`` counts as an
    import of module ``x``; a package's own ``__init__`` reached only as the
    parent of a submodule does not count, nor does the root ``nsga_jax``
    (it loads its names lazily, on first use)."""
    modules = {module_name(p): p for p in SOURCES}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module, path in modules.items():
        for _, target in imports_of(path.read_text(), module, path.name == "__init__.py"):
            while target not in modules and "." in target:
                target = target.rsplit(".", 1)[0]  # a name imported from a module
            if target in modules and target not in (module, "nsga_jax"):
                graph[module].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan),
    each sorted: every import cycle lies in one of them."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_no_import_cycles():
    """No module imports, directly or through others, a module that imports
    it back, even lazily inside a function: the package is a tree of
    dependencies that can be read from the bottom up."""
    assert cycles(import_graph()) == []


def test_the_cycle_checker_sees_cycles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"f"}, "f": {"e"}}
    assert cycles(graph) == [["a", "b", "c"], ["e", "f"]]
    assert cycles({"a": {"b"}, "b": set()}) == []
    graph = import_graph()
    assert "nsga_jax._scenes.spec" in graph["nsga_jax._scenes.system_file"]  # `from .spec import ...` is seen


def test_every_module_outside_the_public_api_is_private():
    """Like diffrax and equinox: the implementation lives in private modules
    (``_name.py``, ``_package/``); what a user imports is the package's flat
    API and its two public namespaces, ``nsga_jax.system`` (parts) and
    ``nsga_jax.scenes`` (scenes)."""
    public = sorted({unit_of(module_name(p)) for p in SOURCES} - PUBLIC)
    assert [unit for unit in public if not unit.startswith("_")] == []


def test_the_public_namespaces_only_re_export():
    """``system`` and ``scenes`` hold no code of their own: each name they
    export is defined in a private module, and internal modules never import
    them (the layer test above: they sit in the top layer)."""
    import nsga_jax.scenes
    import nsga_jax.system

    for namespace in (nsga_jax.system, nsga_jax.scenes):
        for name in namespace.__all__:
            value = getattr(namespace, name)
            home = getattr(value, "__module__", None) or namespace.__name__
            assert home.startswith("nsga_jax._") or not callable(value), (namespace.__name__, name, home)


def test_the_flat_api_is_documented():
    """Every name the package exports is spelled in docs/python-api.md."""
    import nsga_jax

    page = (PACKAGE.parent / "docs" / "python-api.md").read_text()
    missing = [name for name in nsga_jax.__all__ if f"`{name}" not in page and f"nj.{name}" not in page
               and f"nsga_jax.{name}" not in page]
    assert missing == []
    for name in nsga_jax.__all__:
        assert getattr(nsga_jax, name) is not None
