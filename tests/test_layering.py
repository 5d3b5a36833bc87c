"""The project's import graph, read from the source with `ast`: no import cycle between modules, and no import that
runs against the layer order listed under "## Layers" in docs/ARCHITECTURE.md (a module imports only from its own
layer or the layers listed before it). Every import counts, also one inside a function.

Data-driven: the modules are whatever .py files the tree holds, the order is whatever the page lists, so moving code
between files or packages needs no change here; a top-level module or package the page does not list sits above
every listed layer (nothing listed may import it).

Beyond the order, the selection library `active/` stays a library: it draws no picture and writes no image file
(no matplotlib, PIL or `utils.image`) and reads no model directory (no `scene.trained`, `utils.checkpoint`, nor a
file name of `utils.model_dir`); its applications (training/, recommender/, the CLIs) do that (`LIBRARY_RULES`).
"""
from __future__ import annotations

import ast
import os
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "ARCHITECTURE.md"


@dataclass(frozen=True)
class Import:
    """One import statement's edge: module `source` imports module `target` (both dotted project names)."""

    source: str
    target: str
    where: str  # path:line


def read_layers(text: str) -> dict[str, int]:
    """{top-level name: layer} from the numbered list under "## Layers" (1 = lowest), e.g. "2. `utils`, `arguments`"."""
    match = re.search(r"^## Layers\n(.*?)(?=^## |\Z)", text, flags=re.M | re.S)
    assert match, 'docs/ARCHITECTURE.md has no "## Layers" section'
    layers: dict[str, int] = {}
    for line in match.group(1).splitlines():
        item = re.match(r"\s*(\d+)\.\s+((?:`\w+`(?:,\s*)?)+)", line)
        if item:
            for name in re.findall(r"`(\w+)`", item.group(2)):
                assert name not in layers, f"{name} is listed twice in the layer order"
                layers[name] = int(item.group(1))
    assert layers, 'the "## Layers" section lists no layer ("1. `name`, ...")'
    return layers


def project_modules(root: Path) -> dict[str, Path]:
    """{dotted module name: file} of every .py file under `root` (hidden folders and symlinked ones skipped)."""
    modules = {}
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith((".", "__pycache__")))
        rel = Path(folder).relative_to(root).parts
        for name in files:
            if name.endswith(".py"):
                parts = rel + (name[:-3],)
                modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = Path(folder) / name
    return modules


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The deepest project module that `name` (dotted) or a prefix of it names; None for other packages."""
    parts = name.split(".")
    for end in range(len(parts), 0, -1):
        if ".".join(parts[:end]) in modules:
            return ".".join(parts[:end])
    return None


def imported_names(root: Path) -> list[tuple[str, str, str]]:
    """(module, dotted name, path:line) for every name every project module imports, third-party ones included:
    `import a.b` gives "a.b", `from a import b` gives "a.b" (relative imports resolved against the package)."""
    out = []
    for source, path in sorted(project_modules(root).items()):
        package = source if path.name == "__init__.py" else source.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[:len(package.split(".")) - (node.level - 1)] if package else []
                    base = ".".join(anchor + ([base] if base else []))
                names = [f"{base}.{alias.name}" if base else alias.name for alias in node.names]
            else:
                continue
            out += [(source, name, f"{path.relative_to(root)}:{node.lineno}") for name in names]
    return out


def import_edges(root: Path) -> tuple[dict[str, Path], list[Import]]:
    """Every project module and every import of one project module by another (absolute and relative)."""
    modules = project_modules(root)
    edges = []
    for source, name, where in imported_names(root):
        target = _resolve(name, modules)
        edge = Import(source, target, where)
        if target is not None and target != source and edge not in edges:
            edges.append(edge)
    return modules, edges


# package -> (forbidden import prefixes, dotted names allowed despite a prefix)
LIBRARY_RULES = {
    "active": (("matplotlib", "PIL", "utils.image", "scene.trained", "utils.checkpoint", "utils.model_dir"),
               ("utils.model_dir.UNCERTAINTY_KINDS",)),  # the map kinds' names, not a file of a model directory
}


def library_violations(root: Path, rules: dict[str, tuple[tuple[str, ...], tuple[str, ...]]]) -> list[str]:
    """Imports by a package's modules of a name under one of its forbidden prefixes (and not allowed by name)."""
    def under(name: str, prefix: str) -> bool:
        return name == prefix or name.startswith(prefix + ".")

    violations = []
    for source, name, where in imported_names(root):
        forbidden, allowed = rules.get(source.split(".")[0], ((), ()))
        if any(under(name, p) for p in forbidden) and name not in allowed:
            violations.append(f"{where}: {source} imports {name}")
    return violations


def import_cycles(edges: list[Import]) -> list[list[str]]:
    """The strongly connected components of more than one module (each holds at least one cycle), Tarjan's way."""
    graph: dict[str, set[str]] = {}
    for e in edges:
        graph.setdefault(e.source, set()).add(e.target)
        graph.setdefault(e.target, set())
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []

    def visit(v: str) -> None:
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
                components.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(components)


def layer_violations(edges: list[Import], layers: dict[str, int]) -> list[str]:
    """Imports of a module in a higher layer than the importer's (unlisted top-level names: above every layer)."""
    top = max(layers.values()) + 1

    def layer(module: str) -> int:
        return layers.get(module.split(".")[0], top)

    return [f"{e.where}: {e.source} (layer {layer(e.source)}) imports {e.target} (layer {layer(e.target)})"
            for e in edges if layer(e.target) > layer(e.source)]


def test_the_project_has_no_import_cycle():
    _, edges = import_edges(ROOT)
    cycles = import_cycles(edges)
    details = [f"{' <-> '.join(c)}: " + ", ".join(f"{e.where} ({e.source} -> {e.target})" for e in edges
                                                   if e.source in c and e.target in c) for c in cycles]
    assert not cycles, "import cycles:\n" + "\n".join(details)


def test_imports_follow_the_documented_layers():
    modules, edges = import_edges(ROOT)
    layers = read_layers(ARCHITECTURE.read_text())
    tops = {m.split(".")[0] for m in modules}
    stale = sorted(set(layers) - tops)
    assert not stale, f"docs/ARCHITECTURE.md lists layers for modules that do not exist: {stale}"
    violations = layer_violations(edges, layers)
    assert not violations, "imports against the layer order of docs/ARCHITECTURE.md:\n" + "\n".join(violations)


def test_the_selection_library_draws_nothing_and_reads_no_model_directory():
    violations = library_violations(ROOT, LIBRARY_RULES)
    assert not violations, "active/ is the selection library; move this to its application:\n" + "\n".join(violations)
    names = {name for module, name, _ in imported_names(ROOT) if module.startswith("active")}
    assert "torch" in names and "active.fisher.fisher_view_blocks" in names  # the check reads active/'s imports


def test_the_reader_sees_the_project():
    """Guards against a check that passes because it reads nothing (wrong root, a parse that finds no imports)."""
    modules, edges = import_edges(ROOT)
    assert "tests.test_layering" in modules and "gaussian_renderer.rasterize" in modules
    assert len(edges) > len(modules)  # the project's modules import each other a lot
    assert {e.source.split(".")[0] for e in edges} >= set(read_layers(ARCHITECTURE.read_text())) - {"arguments", "utils"}


@pytest.fixture
def bad_tree(tmp_path: Path) -> Path:
    """A small project with a function-level cycle, a relative-import cycle and two imports up the layers."""
    files = {
        "low/__init__.py": "",
        "low/a.py": "import os\nfrom low import b\n",
        "low/b.py": "def f():\n    from low.a import f\n",  # low.a <-> low.b, through a function-level import
        "low/c.py": "from .d import x\n",
        "low/d.py": "from . import c\n",  # low.c <-> low.d, relative
        "low/up.py": "import high.top\n",  # against the layers
        "high/__init__.py": "",
        "high/top.py": "from low.a import b\n",
        "script.py": "import high\n",  # unlisted: the top
        "low/uses_script.py": "def g():\n    import script\n",  # against the layers: low imports the unlisted top
    }
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    return tmp_path


def test_the_checks_catch_cycles_and_imports_up_the_layers(bad_tree):
    _, edges = import_edges(bad_tree)
    assert {(e.source, e.target) for e in edges} == {  # no edge for the standard library (os)
        ("low.a", "low.b"), ("low.b", "low.a"), ("low.c", "low.d"), ("low.d", "low.c"), ("low.up", "high.top"),
        ("high.top", "low.a"), ("script", "high"), ("low.uses_script", "script")}
    assert import_cycles(edges) == [["low.a", "low.b"], ["low.c", "low.d"]]
    layers = read_layers("# x\n## Layers\n1. `low`\n2. `high`: text with `code`\n## Next\n3. `script`\n")
    assert layers == {"low": 1, "high": 2}
    violations = layer_violations(edges, layers)
    assert [v.split(":")[0] for v in violations] == ["low/up.py", "low/uses_script.py"]
    assert "low.up (layer 1) imports high.top (layer 2)" in violations[0]


def test_the_library_rules_catch_pictures_and_model_directories(tmp_path):
    files = {
        "lib/__init__.py": "",
        "lib/plot.py": "def f():\n    import matplotlib.pyplot as plt\n",
        "lib/image.py": "from PIL import Image\n",
        "lib/files.py": "from utils.model_dir import CFG_ARGS, KINDS\nfrom utils import model_dir\n",
        "lib/fine.py": "import math\nfrom .plot import f\nimport PILLOW\n",
        "app.py": "import matplotlib\n",  # not under a rule
    }
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    rules = {"lib": (("matplotlib", "PIL", "utils.model_dir"), ("utils.model_dir.KINDS",))}
    assert library_violations(tmp_path, rules) == [
        "lib/files.py:1: lib.files imports utils.model_dir.CFG_ARGS", "lib/files.py:2: lib.files imports utils.model_dir",
        "lib/image.py:1: lib.image imports PIL.Image", "lib/plot.py:2: lib.plot imports matplotlib.pyplot"]
