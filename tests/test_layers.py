"""The package's folders are its layers: every import points down, and only render/ touches
Mitsuba or Dr.Jit (docs/architecture.md)."""
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
        if top == "skyfit_mi":
            other = _layer(mod) if mod != "skyfit_mi" else "ground"
            assert LAYERS.index(other) <= LAYERS.index(own), \
                f"{path.relative_to(PKG)}:{line} ({own}) imports {mod} ({other}), a layer above it"
