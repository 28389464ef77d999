"""The package's modules import each other without circles, counting imports inside functions."""
import ast
from pathlib import Path

import radiosity_baker

ROOT = Path(radiosity_baker.__file__).parent
PACKAGE = "radiosity_baker"


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join([PACKAGE, *parts])


def _modules() -> dict:
    """{module name: path} of every module under core/ and addon/ and the package itself."""
    paths = [ROOT / "__init__.py", ROOT / "__main__.py"]
    for folder in ("core", "addon"):
        paths += sorted((ROOT / folder).rglob("*.py"))
    return {_module_name(p): p for p in paths}


def import_graph() -> dict:
    """{module: set of the package's modules it imports}, anywhere in its body."""
    modules = _modules()
    graph = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                base = package.split(".")
                if node.level:
                    base = base[:len(base) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    found.add(sub if sub in modules else target)
            elif isinstance(node, ast.Import):
                found.update(alias.name for alias in node.names)
        graph[name] = {m for m in found if m in modules and m != name}
    return graph


def cycles(graph: dict) -> list:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_import_walk_finds_a_circle_it_is_shown():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_module_of_core_or_addon_imports_itself_through_others():
    graph = import_graph()
    assert len(graph) > 40 and graph[f"{PACKAGE}.core.pipeline"]
    assert cycles(graph) == []


def test_core_never_imports_bpy_or_the_addon():
    for name, path in _modules().items():
        if ".core" not in name:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level
                     else [])
            assert not any(n.split(".")[0] in ("bpy", "mathutils") for n in names), name
            if isinstance(node, ast.ImportFrom) and node.level:
                assert "addon" not in (node.module or ""), name
