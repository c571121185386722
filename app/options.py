"""Command-line options derived from the library's settings dataclasses (``stylize3d_core.options``).

:func:`add_options` adds one argparse option per :func:`~stylize3d_core.options.option`
field of a dataclass (a nested settings dataclass adds its own fields, without
a prefix; fields marked ``cli=False`` are left out), with the field's help,
choices, metavar and default. :func:`from_args` builds the dataclass back from
the parsed namespace. Values are validated by the dataclass itself, so a bad
value is an ``InputError`` naming the setting (exit status 2), not an argparse
error.

Both ``stylize3d render`` and ``stylize3d-viewer`` take their photo options from
``PhotoSpec`` this way, so a new photo option is written once, in its field.
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import Any, Dict, Iterator, Mapping, Optional, Tuple, Type

from stylize3d_core.options import FieldType, OptionInfo, field_types, option_info


def _cli_fields(cls: Type) -> Iterator[Tuple[dataclasses.Field, FieldType, OptionInfo]]:
    types = field_types(cls)
    for f in dataclasses.fields(cls):
        info = option_info(f)
        if info is not None and info.cli:
            yield f, types[f.name], info


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        return f.default_factory()  # type: ignore[misc]
    return None


def _help(info: OptionInfo, default: Any) -> str:
    text = info.help.rstrip(".")
    if info.default_text is not None:
        return f"{text} (default: {info.default_text})"
    if default is None or isinstance(default, bool):
        return text
    return f"{text} (default: %(default)s)"


def add_options(parser: argparse.ArgumentParser, cls: Type, *, defaults: Mapping[str, Any] = {},
                positional: Mapping[str, Optional[str]] = {}) -> None:
    """Add an option per command-line field of the dataclass ``cls`` (recursively) to ``parser``.

    Args:
        parser: the parser or sub-parser.
        cls: a dataclass whose fields were made with ``stylize3d_core.options.option``.
        defaults: field name -> default to use instead of the field's own (e.g. a smaller ``max_size``).
        positional: field name -> argparse ``nargs`` (None: required) for fields given as positional arguments.
    """
    for f, ft, info in _cli_fields(cls):
        default = defaults.get(f.name, _default(f))
        if dataclasses.is_dataclass(ft.base):
            add_options(parser, ft.base, defaults=defaults, positional=positional)
            continue
        kwargs: Dict[str, Any] = {"help": _help(info, default)}
        choices = ft.literal if ft.literal is not None else info.choices
        if ft.base is bool:
            kwargs.update(action=argparse.BooleanOptionalAction, default=default)
        else:
            kwargs.update(type=ft.base, default=default)
            if choices is not None:
                kwargs["choices"] = choices
            if info.metavar is not None and (choices is None or f.name not in positional):
                kwargs["metavar"] = info.metavar
        if f.name in positional:
            nargs = positional[f.name]
            if nargs is not None:
                kwargs["nargs"] = nargs
            kwargs.pop("metavar", None)
            parser.add_argument(f.name, **kwargs)
        else:
            flags = info.flags or ("--" + f.name.replace("_", "-"),)
            parser.add_argument(*flags, dest=f.name, **kwargs)


def from_args(cls: Type, args: argparse.Namespace, **overrides: Any) -> Any:
    """The dataclass ``cls`` made from the parsed ``args`` (fields not on the command line keep their
    defaults; ``overrides`` win). Raises the dataclass's ``InputError`` for a bad value."""
    values: Dict[str, Any] = {}
    for f, ft, _info in _cli_fields(cls):
        if dataclasses.is_dataclass(ft.base):
            values[f.name] = from_args(ft.base, args)
        elif hasattr(args, f.name):
            values[f.name] = getattr(args, f.name)
    values.update(overrides)
    return cls(**values)
