"""Settings fields with their own help and ranges (stylize3d_core/options.py) and the command-line options
derived from them (app/options.py), as both entry points use them."""

from __future__ import annotations

import argparse
import dataclasses
from typing import Literal, Optional

import pytest

from stylize3d_app.options import add_options, from_args
from stylize3d_app.viewer import build_parser as viewer_parser
from stylize3d_app.viewer import main as viewer_main
from stylize3d_app.viewer.state import VIEWER_MAX_SIZE
from stylize3d_core.errors import InputError
from stylize3d_core.options import check_options, documented, option
from stylize3d_core.pipeline import PhotoSpec


@documented
@dataclasses.dataclass(frozen=True)
class Inner:
    """Inner settings."""

    level: int = option(3, low=1, high=5, help="how much.")

    def __post_init__(self) -> None:
        check_options(self)


@documented
@dataclasses.dataclass(frozen=True)
class Toy:
    """A toy job."""

    name: Optional[str] = option(None, help="what to read.")
    mode: Literal["fast", "slow"] = option("fast", help="how.")
    ratio: float = option(0.5, low=0.0, high=1.0, help="a fraction.")
    count: int = option(2, low=1, high=10, flags=("-n", "--count"), metavar="N", help="how many.")
    kind: Optional[str] = option(None, choices=("a", "b"), metavar="KIND", default_text="neither", help="a or b.")
    inner: Inner = option(default_factory=Inner, help="nested settings.")
    hidden: Inner = option(default_factory=Inner, cli=False, help="not on the command line.")

    def __post_init__(self) -> None:
        check_options(self)


@pytest.mark.parametrize("kwargs, needle", [
    (dict(ratio=float("nan")), "ratio: must be a finite number from 0 to 1"),
    (dict(ratio=float("inf")), "ratio: must be a finite number"),
    (dict(ratio=1.5), "ratio: must be a number from 0 to 1, got 1.5"),
    (dict(ratio="0.5"), "ratio: must be a finite number"),
    (dict(count=0), "count: must be an integer from 1 to 10, got 0"),
    (dict(count=2.5), "count: must be an integer"),
    (dict(count=True), "count: must be an integer"),
    (dict(mode="medium"), "mode: must be one of 'fast', 'slow'"),
    (dict(kind="c"), "kind: must be one of 'a', 'b'"),
    (dict(name=""), "name: must be a non-empty text"),
    (dict(inner="x"), "inner: must be a Inner"),
])
def test_check_options_refuses_bad_values_naming_the_field(kwargs, needle):
    with pytest.raises(InputError) as e:
        Toy(**kwargs)
    assert needle in str(e.value)


def test_good_values_and_none_for_optional_fields_pass():
    t = Toy(name="x", mode="slow", ratio=1, count=10, kind="b", inner=Inner(5))
    assert t.ratio == 1 and t.inner.level == 5 and Toy().name is None
    with pytest.raises(InputError, match="level"):
        Inner(6)


def test_documented_lists_every_option_with_its_default():
    doc = Toy.__doc__
    assert doc.startswith("A toy job.") and "Attributes:" in doc
    assert "    ratio: a fraction. Default: 0.5." in doc
    assert "    kind: a or b. Default: neither." in doc
    assert "    inner: nested settings." in doc


def test_options_are_derived_from_the_fields_and_build_the_dataclass_back():
    p = argparse.ArgumentParser()
    add_options(p, Toy, defaults={"ratio": 0.25}, positional={"name": None})
    flags = {s for a in p._actions for s in a.option_strings}
    assert {"--mode", "--ratio", "-n", "--count", "--kind", "--level"} <= flags
    assert "--hidden" not in flags and "--inner" not in flags and "--name" not in flags
    args = p.parse_args(["in.txt", "-n", "4", "--level", "2", "--mode", "slow"])
    t = from_args(Toy, args)
    assert t == Toy(name="in.txt", mode="slow", ratio=0.25, count=4, inner=Inner(2))
    with pytest.raises(InputError, match="count"):
        from_args(Toy, p.parse_args(["in.txt", "-n", "11"]))  # the dataclass validates, not argparse
    with pytest.raises(SystemExit):
        p.parse_args(["in.txt", "--mode", "medium"])  # Literal choices are argparse choices
    help_text = p.format_help()
    assert "a fraction (default: 0.25)" in help_text and "a or b (default: neither)" in help_text


def test_the_viewer_takes_the_same_photo_options_with_its_own_max_size():
    args = viewer_parser().parse_args(["p.jpg", "--depth", "prior", "--refine-depth", "guided", "--fov", "50"])
    spec = from_args(PhotoSpec, args)
    assert spec == PhotoSpec("p.jpg", "prior", refine_depth="guided", max_size=VIEWER_MAX_SIZE, fov=50.0)
    assert from_args(PhotoSpec, viewer_parser().parse_args([])).photo is None


@pytest.mark.parametrize("argv, needle", [
    (["--max-size", "4"], "max_size: must be an integer from 32 to 8192"),
    (["--fov", "nan"], "fov: must be a finite number"),
    (["--fov", "500"], "fov: must be a number from 1 to 170"),
])
def test_the_viewer_refuses_bad_photo_options_before_opening_a_window(argv, needle, capsys):
    assert viewer_main(argv) == 2
    assert needle in capsys.readouterr().err
