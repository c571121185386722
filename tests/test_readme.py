"""The README is true against the code: its documented defaults are the command line's, every
command it shows parses, its imports exist, its layout names every folder, its links resolve and
its performance figures are those of the bench file it names."""

from __future__ import annotations

import importlib
import re
import shlex
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```", README, flags=re.S | re.M)


def _table(header: str) -> list[list[str]]:
    """The rows of the Markdown table whose header line starts with ``header``."""
    lines = README.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(header))
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    return rows


def _render_parser():
    from stylize3d_app.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return parser, sub.choices["render"]


def _commands() -> list[list[str]]:
    """Every ``stylize3d`` / ``stylize3d-viewer`` command line of the README's bash blocks."""
    found = []
    for block in _blocks("bash"):
        for line in block.splitlines():
            line = line.split(" #")[0].strip()
            line = line.removeprefix("bash setup.sh && ").strip()
            if not line:
                continue
            words = shlex.split(line)
            if Path(words[0]).name in ("stylize3d", "stylize3d-viewer"):
                found.append(words)
    return found


def test_documented_render_defaults_are_the_code_defaults():
    _, render = _render_parser()
    by_flag = {flag: action for action in render._actions for flag in action.option_strings}
    rows = _table("| option | default |")
    assert len(rows) >= 10
    for row in rows:
        flags = re.findall(r"`(-[-\w]+)`", row[0])
        assert flags, row
        action = by_flag.get(flags[-1])
        assert action is not None, f"README documents {flags[-1]}, which `stylize3d render` lacks"
        assert set(flags) <= set(action.option_strings), row
        documented = row[1].strip("`")
        if documented == "none":
            assert action.default is None, (flags, action.default)
        else:
            assert documented == str(action.default), (flags, documented, action.default)


def test_documented_render_defaults_match_render_job():
    from stylize3d_core.pipeline import RenderJob

    import dataclasses

    fields = {f.name: f.default for f in dataclasses.fields(RenderJob)
              if f.default is not dataclasses.MISSING}
    rows = {re.findall(r"`(-[-\w]+)`", row[0])[-1]: row[1].strip("`") for row in _table("| option | default |")}
    for flag, name in (("--frames", "frames"), ("--fps", "fps"), ("--size", "size"),
                       ("--points-per-pixel", "points_per_pixel"), ("--trajectory", "trajectory")):
        assert name in fields, name
        assert rows[flag] == str(fields[name]), (flag, rows[flag], fields[name])


def test_viewer_max_size_as_documented():
    from stylize3d_app.viewer import build_parser

    documented = re.search(r"`--max-size (\d+)` by default", README)
    assert documented, "README states the viewer's --max-size default"
    assert build_parser().parse_args([]).max_size == int(documented.group(1))


def test_every_command_shown_parses():
    from stylize3d_app.cli import build_parser as cli_parser
    from stylize3d_app.viewer import build_parser as viewer_parser

    commands = _commands()
    assert len(commands) >= 15
    assert ["bash", "setup.sh"] not in commands
    for words in commands:
        parser = cli_parser() if Path(words[0]).name == "stylize3d" else viewer_parser()
        try:
            parser.parse_args(words[1:])
        except SystemExit as e:  # argparse's way of refusing a command line
            pytest.fail(f"README command does not parse (exit {e.code}): {' '.join(words)}")


def test_the_two_commands_are_ci_s():
    first, second = (b.strip() for b in _blocks("bash")[:2])
    assert first == ("bash setup.sh && .venv/bin/stylize3d render assets/samples/coffee.jpg "
                     "--style assets/styles/vangogh_starry_night.jpg -o coffee_stylized.mp4")
    assert second == "bash setup.sh && .venv/bin/python -m pytest"
    assert second in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


def test_library_example_names_exist():
    (block,) = _blocks("python")
    imports = re.findall(r"^from ([\w.]+) import (.+)$", block, flags=re.M)
    assert imports
    for module, names in imports:
        mod = importlib.import_module(module)
        for name in names.split(","):
            assert hasattr(mod, name.strip()), (module, name)
    for path in re.findall(r'"((?:assets)/[^"]+)"', block):
        assert (ROOT / path).is_file(), path


def test_layout_names_every_folder():
    documented = " ".join(row[0] for row in _table("| path | what |"))
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    top = {p.split("/")[0] for p in tracked.splitlines() if "/" in p and not p.startswith(".")}
    subpackages = {p.parent.name for p in (ROOT / "stylize3d_core").glob("*/__init__.py")}
    assert {"app", "tests", "tools", "docs"} <= top
    for folder in sorted(top):
        assert f"`{folder}/`" in documented, f"the README's layout leaves out {folder}/"
    for sub in sorted(subpackages):
        assert f"`stylize3d_core/{sub}`" in documented, f"the README's layout leaves out stylize3d_core/{sub}"


def test_links_and_pictures_resolve():
    targets = re.findall(r"\]\(([^)#]+)\)", README)
    assert "docs/stylized_sheet.png" in targets
    for target in targets:
        assert (ROOT / target).exists(), target


def test_performance_figures_come_from_the_named_bench_file():
    source = re.search(r"From \[`(docs/bench/[^`]+\.md)`\]", README)
    assert source, "the performance table names the bench file it copies"
    bench = (ROOT / source.group(1)).read_text(encoding="utf-8")
    rows = _table("| what | target | measured |")
    assert rows
    for row in rows:
        number = re.match(r"[\d.]+", row[2]).group(0)
        assert re.search(rf"\| {re.escape(number)} \|", bench), (row, source.group(1))


def test_front_door_not_a_journal():
    assert len(README.splitlines()) <= 250
    for word in ("Latest", "Noticed", "Session ", "session "):
        assert word not in README, word
    assert not re.search(r"\b20\d\d-\d\d-\d\d\b", README)
    assert "shared/" not in README
