"""The layering rules of docs/architecture.md ("Layers"): the library never imports the viewer or a GUI toolkit."""

import ast
import re
import shutil
from pathlib import Path
from typing import Iterator, List, Optional, Tuple

import pytest

import stylize3d_core

LIB = Path(stylize3d_core.__file__).parent
FORBIDDEN = ("app", "stylize3d_app", "open3d.visualization", "tkinter", "PySide6", "PyQt5", "PyQt6", "wx")

LAYERS: Tuple[Tuple[str, ...], ...] = (
    ("errors",),
    ("checks",),
    ("options",),
    ("defaults",),
    ("resources",),
    ("threads", "memory"),
    ("geometry",),
    ("io",),
    ("depth",),
    ("scene",),
    ("render", "points"),
    ("models",),
    ("train", "stylize"),
    ("export",),
    ("multiview",),
    ("eval", "pipeline"),
    ("bench",),
    ("stylize3d_core",),
    ("info",),
)
"""The package order of ``stylize3d_core``, bottom first; the viewer and the CLI (``app/``) sit above it all.

Each name is a package (``io``) or a top-level module (``errors.py``); ``stylize3d_core`` is the
package's own ``__init__.py``, which may re-export anything; ``info`` (the ``stylize3d info``
report, which reads the package version) sits above it. A module may import from its own
package and from lower layers only: never from a higher layer, nor from another package of its
own layer (``render`` and ``points``, ``train`` and ``stylize``, ``eval`` and ``pipeline`` are
independent of each other). Imports inside functions count as well.
"""


def _imports(path: Path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module
            yield from (f"{node.module}.{a.name}" for a in node.names)


def test_library_has_no_gui_or_app_imports():
    bad = []
    for path in sorted(LIB.rglob("*.py")):
        for name in _imports(path):
            if any(name == f or name.startswith(f + ".") for f in FORBIDDEN):
                bad.append(f"{path.relative_to(LIB)}: {name}")
    assert not bad, bad


def test_every_library_package_has_tests():
    tests = Path(__file__).parent
    packages = [p.name for p in LIB.iterdir() if p.is_dir() and (p / "__init__.py").exists()]
    missing = [p for p in packages if not any((tests / p).glob("test_*.py"))]
    assert not missing, f"packages without a tests/<package>/test_*.py: {missing}"


# ---------------------------------------------------------------------------- package order


def _module_parts(path: Path, root: Path) -> List[str]:
    """['stylize3d_core', 'io', 'images'] for root/io/images.py; a package's __init__ is the package."""
    parts = [root.name, *path.relative_to(root).with_suffix("").parts]
    return parts[:-1] if parts[-1] == "__init__" else parts


def _is_module(parts: List[str], root: Path) -> bool:
    where = root.joinpath(*parts[1:])
    return where.with_suffix(".py").is_file() or (where / "__init__.py").is_file()


def _library_imports(path: Path, root: Path) -> Iterator[Tuple[int, List[str]]]:
    """(line, dotted name as parts) of every import of the package ``root`` in ``path``, relative ones resolved."""
    here = _module_parts(path, root)
    package = here if path.name == "__init__.py" else here[:-1]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name.split(".")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1] + (node.module.split(".") if node.module else [])
            else:
                base = node.module.split(".")
            for alias in node.names:  # `from .. import depth` imports the package depth
                candidate = base + [alias.name]
                yield node.lineno, candidate if base[0] == root.name and _is_module(candidate, root) else base


def _unit(parts: List[str], root: Path) -> Optional[str]:
    """The LAYERS name a module belongs to; None outside the package."""
    if parts[0] != root.name:
        return None
    return parts[1] if len(parts) > 1 else root.name


def layer_violations(root: Path) -> List[str]:
    """Every import in the package at ``root`` that goes up (or sideways) in :data:`LAYERS`, in words."""
    rank = {name: i for i, layer in enumerate(LAYERS) for name in layer}
    bad = []
    for path in sorted(root.rglob("*.py")):
        src = _unit(_module_parts(path, root), root)
        for line, parts in _library_imports(path, root):
            dst = _unit(parts, root)
            if dst is None or dst == src:
                continue
            where = f"{path.relative_to(root)}:{line}: {src} imports {'.'.join(parts)}"
            unknown = [u for u in (src, dst) if u not in rank]
            if unknown:
                bad.append(f"{where} ({', '.join(unknown)} not in LAYERS: place it in the package order)")
            elif rank[dst] == rank[src]:
                bad.append(f"{where} (same layer: {src} and {dst} must stay independent)")
            elif rank[dst] > rank[src]:
                bad.append(f"{where} (upward: {dst} is above {src})")
    return bad


def test_imports_follow_the_package_order():
    assert not layer_violations(LIB), "\n".join(layer_violations(LIB))


def test_layers_name_every_package_and_top_level_module():
    present = {p.name for p in LIB.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    present |= {p.stem for p in LIB.glob("*.py") if p.name != "__init__.py"} | {LIB.name}
    listed = [name for layer in LAYERS for name in layer]
    assert len(listed) == len(set(listed))
    assert set(listed) == present


@pytest.fixture
def library_copy(tmp_path: Path) -> Path:
    """A copy of the package to plant bad imports in."""
    return Path(shutil.copytree(LIB, tmp_path / LIB.name, ignore=shutil.ignore_patterns("__pycache__")))


@pytest.mark.parametrize(
    "module, source, expected",
    [
        ("io/_planted.py", "from ..depth.types import DepthMap\n", "io imports stylize3d_core.depth.types (upward"),
        ("geometry/_planted.py", "def f():\n    from stylize3d_core.scene import ldi\n",
         "geometry imports stylize3d_core.scene.ldi (upward"),
        ("render/_planted.py", "import stylize3d_core.models.checkpoint\n", "render imports stylize3d_core.models"),
        ("errors_extra.py", "from .errors import InputError\n", "errors_extra not in LAYERS"),
        ("points/_planted.py", "from .. import render\n", "points imports stylize3d_core.render (same layer"),
        ("depth/_planted.py", "from stylize3d_core import pipeline\n", "depth imports stylize3d_core.pipeline (upward"),
        ("pipeline_planted.py", "import numpy\nfrom . import errors\n", "pipeline_planted not in LAYERS"),
    ],
)
def test_planted_bad_import_is_caught(library_copy, module, source, expected):
    target = library_copy / module
    target.parent.mkdir(exist_ok=True)
    target.write_text(source, encoding="utf-8")
    found = layer_violations(library_copy)
    assert len(found) == 1 and expected in found[0] and module in found[0], found


def test_planted_downward_import_is_allowed(library_copy):
    (library_copy / "depth" / "_planted.py").write_text(
        "from ..io.images import load_image\nfrom stylize3d_core.geometry import camera\nfrom . import types\n",
        encoding="utf-8",
    )
    assert layer_violations(library_copy) == []


# ---------------------------------------------------------------------------- import cycles

ROOT = LIB.parent
PACKAGES = ("stylize3d_core", "app", "stylize3d")
"""The repository's folders of code (``assets/`` holds no code that imports)."""
INSTALLED_AS = {"stylize3d_app": "app"}
"""Installed package name -> the folder it is (``[tool.setuptools.package-dir]``)."""


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph(root: Path, packages: Tuple[str, ...] = PACKAGES) -> dict:
    """{module: the modules of ``packages`` it imports}, over every import statement in a module (at the
    top, inside functions, under ``if TYPE_CHECKING``), relative ones resolved, each to the deepest
    module that exists (``from .a import b`` is ``a.b`` where that is a module, else ``a``)."""
    files = {_module_name(p, root): p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))}

    def resolve(dotted: str) -> Optional[str]:
        parts = dotted.split(".")
        parts[0] = INSTALLED_AS.get(parts[0], parts[0])
        while parts:
            if ".".join(parts) in files:
                return ".".join(parts)
            parts.pop()
        return None

    graph = {}
    for name, path in files.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                found.update(resolve(a.name) for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([node.module] if node.module else []))
                else:
                    base = node.module or ""
                found.update(resolve(f"{base}.{a.name}") or resolve(base) for a in node.names)
        found.discard(None)
        found.discard(name)
        graph[name] = found
    return graph


def import_cycles(graph: dict) -> List[List[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index, low, on_stack, stack, cycles = {}, {}, set(), [], []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    cycles.append(sorted(component))
    return cycles


def test_nothing_imports_the_app_folder_by_its_folder_name():
    """``app/`` installs as ``stylize3d_app``; an ``import app`` would load a second copy from a checkout."""
    bad = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            for name in _imports(path):
                if name == "app" or name.startswith("app."):
                    bad.append(f"{path.relative_to(ROOT)}: {name}")
    assert not bad, bad


def test_no_import_cycles():
    cycles = import_cycles(import_graph(ROOT))
    assert not cycles, "import cycles (break them; an import inside a function still counts):\n" + "\n".join(
        " <-> ".join(c) for c in cycles)


def test_planted_cycles_are_found(tmp_path):
    pkg = tmp_path / "stylize3d_core"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .sub import b\n")
    (pkg / "sub" / "b.py").write_text("def f():\n    from ..c import g\n")  # inside a function
    (pkg / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from . import a\n")
    (pkg / "d.py").write_text("from . import a\n")  # imports into the cycle, not part of it
    graph = import_graph(tmp_path, ("stylize3d_core",))
    assert graph["stylize3d_core.d"] == {"stylize3d_core.a"}
    assert import_cycles(graph) == [["stylize3d_core.a", "stylize3d_core.c", "stylize3d_core.sub.b"]]
    (pkg / "c.py").write_text("import os\n")
    assert import_cycles(import_graph(tmp_path, ("stylize3d_core",))) == []


# ---------------------------------------------------------------------------- comments


HISTORY = re.compile(r"sessions? \d|until version \d|in version \d of the model|the first version of|"
                     r"was the default|\b\d+(\.\d+)? -> \d+(\.\d+)? ?(ms|dB|s)\b|issue \d+")
"""Phrases of a journal: comments and docstrings say what the code does and why, not how a number or a
default changed (measurements live in the files the bench commands write)."""


def test_comments_state_contracts_not_history():
    found = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                if HISTORY.search(line):
                    found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not found, "\n".join(found)
