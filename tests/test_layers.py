"""The package's folders are its layers: every import points down, only render/ touches
Mitsuba or Dr.Jit, and nothing imports skyfit_testkit (docs/architecture.md)."""
import ast
from pathlib import Path

import pytest

import skyfit_mi

PKG = Path(skyfit_mi.__file__).parent
#: Bottom to top; a module may import from its own layer and those before it.
LAYERS = ["ground", "physics", "render", "pipeline", "fitting", "cli"]
GROUND = {"errors", "conventions", "files", "child", "__init__"}


def _layer(module):
    """Layer of a dotted module name inside the package (e.g. 'skyfit_mi.fitting.fit')."""
    parts = module.split(".")[1:]
    if not parts or parts[0] in GROUND or parts[0] not in LAYERS:   # e.g. skyfit_mi.__version__
        return "ground"
    return parts[0]


def _imports(path):
    """(dotted module imported, line) for every import in a file, relative ones resolved."""
    rel = path.relative_to(PKG.parent).with_suffix("")
    package = list(rel.parts[:-1]) if rel.name != "__init__" else list(rel.parts[:-1])
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
                if node.module is None:          # from . import x: x may be a module
                    for a in node.names:
                        yield f"{mod}.{a.name}", node.lineno
                    continue
                yield mod, node.lineno
            else:
                yield node.module, node.lineno


MODULES = sorted(p for p in PKG.rglob("*.py"))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PKG)))
def test_imports_point_down_and_only_render_touches_mitsuba(path):
    own = _layer(".".join(path.relative_to(PKG.parent).with_suffix("").parts))
    for mod, line in _imports(path):
        top = mod.split(".")[0]
        if top in ("mitsuba", "drjit"):
            assert own == "render", f"{path.name}:{line} imports {mod} outside render/"
        assert top != "skyfit_testkit", f"{path.name}:{line} imports {mod}: the test kit " \
                                        "builds on the package, not the other way round"
        if top == "skyfit_mi":
            other = _layer(mod) if mod != "skyfit_mi" else "ground"
            assert LAYERS.index(other) <= LAYERS.index(own), \
                f"{path.relative_to(PKG)}:{line} ({own}) imports {mod} ({other}), a layer above it"


def _module_name(path):
    """Dotted name of a file in the package; a package's ``__init__`` is the package."""
    parts = path.relative_to(PKG.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_graph():
    """Module -> the package's modules it imports, every import counted (inside functions too).

    ``import a.b`` imports ``a.b`` (not the packages above it, whose ``__init__`` runs too:
    counting those adds no circle today); ``from P import n`` imports ``P.n`` where that is a
    module, and ``P`` itself, since its ``__init__`` runs, unless ``P`` is the importer's own
    package (or an ancestor of it) and ``n`` is a module: that package is already initialised
    before any of its submodules runs, so ``from . import sibling`` adds only the sibling.
    Nor does being a submodule count as importing the package: a package's ``__init__`` that
    re-exports its submodules is a circle only with a submodule that explicitly imports a
    name from that ``__init__`` (``from . import NAME``, NAME not a module), which does read
    the half-run ``__init__``."""
    modules = {_module_name(p): p for p in MODULES}
    graph = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets.update(a.name for a in node.names if a.name in modules)
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[:len(package.split(".")) - node.level + 1]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module
                ancestor = package == source or package.startswith(source + ".")
                for a in node.names:
                    if f"{source}.{a.name}" in modules:
                        targets.add(f"{source}.{a.name}")
                        if not ancestor and source in modules:
                            targets.add(source)
                    elif source in modules:
                        targets.add(source)
        targets.discard(name)
        graph[name] = targets
    return graph


def _cycles(graph):
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
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
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_circle():
    """No module imports, directly or through others, a module that imports it: the package's
    modules form a hierarchy even counting the imports made inside functions (see
    ``_import_graph`` for what counts as an import)."""
    graph = _import_graph()
    cycles = _cycles(graph)

    def short(m):
        return m.removeprefix("skyfit_mi.")

    lines = []
    for component in cycles:
        inner = {m: sorted(map(short, graph[m] & set(component))) for m in component}
        edges = "; ".join(f"{short(m)} -> {', '.join(t)}" for m, t in inner.items())
        lines.append(" <-> ".join(map(short, component)) + ": " + edges)
    assert not cycles, "import circles:\n" + "\n".join(lines)
