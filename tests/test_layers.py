"""The layering rules of docs/architecture.md ("Layers"): the library never imports the viewer or a GUI toolkit."""

import ast
from pathlib import Path

import stylize3d_core

LIB = Path(stylize3d_core.__file__).parent
FORBIDDEN = ("app", "open3d.visualization", "tkinter", "PySide6", "PyQt5", "PyQt6", "wx")


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
