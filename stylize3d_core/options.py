"""Settings fields that carry their own documentation, allowed values and command-line spelling.

A dataclass field made with :func:`option` keeps in its metadata the help text
(which is both the field's documentation and its command-line help), the range
or the choices it allows, and how a command line spells it. Then

* :func:`check_options` validates every option field of an instance in one place
  (call it from ``__post_init__``): the type, finiteness, the range, the choices;
* :func:`documented` appends an "Attributes" section built from the help texts
  to the class docstring, so ``help(cls)`` shows them;
* ``app/options.py`` derives argparse options from the same fields,

so a new setting is written once: its field.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import typing
from typing import Any, Dict, Literal, Optional, Sequence, Tuple, Type, get_args, get_origin

from .errors import InputError

_KEY = "stylize3d_option"


@dataclasses.dataclass(frozen=True)
class OptionInfo:
    """What :func:`option` records about a field.

    Attributes:
        help: what the field means, in plain words (documentation and command-line help).
        low, high: inclusive bounds of a number (None: unbounded on that side).
        choices: the allowed values (besides None for an Optional field), or None.
        metavar: the value's name in the command-line usage, or None.
        flags: the command-line spellings, or () for ``--field-name``.
        cli: False keeps the field off the command line.
        default_text: how the help describes the default, when printing the value would not help.
    """

    help: str
    low: Optional[float] = None
    high: Optional[float] = None
    choices: Optional[Tuple[Any, ...]] = None
    metavar: Optional[str] = None
    flags: Tuple[str, ...] = ()
    cli: bool = True
    default_text: Optional[str] = None


def option(default: Any = dataclasses.MISSING, *, help: str, low: Optional[float] = None,
           high: Optional[float] = None, choices: Optional[Sequence[Any]] = None, metavar: Optional[str] = None,
           flags: Sequence[str] = (), cli: bool = True, default_text: Optional[str] = None,
           default_factory: Any = dataclasses.MISSING) -> Any:
    """A dataclass field with its documentation and allowed values (see the module docstring)."""
    info = OptionInfo(help, low, high, None if choices is None else tuple(choices), metavar, tuple(flags), cli,
                      default_text)
    return dataclasses.field(default=default, default_factory=default_factory, metadata={_KEY: info})


def option_info(f: dataclasses.Field) -> Optional[OptionInfo]:
    """The :class:`OptionInfo` of a field made with :func:`option`, else None."""
    return f.metadata.get(_KEY)


class FieldType(typing.NamedTuple):
    """A field's annotation, resolved: the base type, whether None is allowed, Literal choices."""

    base: Any  # int, float, str, bool, a dataclass type, or Literal's first value's type
    optional: bool
    literal: Optional[Tuple[Any, ...]]


@functools.lru_cache(maxsize=None)
def field_types(cls: Type) -> Dict[str, FieldType]:
    """The resolved annotation of every field of the dataclass ``cls``."""
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        t = hints[f.name]
        optional = False
        if get_origin(t) is typing.Union:
            args = [a for a in get_args(t) if a is not type(None)]
            optional = len(args) < len(get_args(t))
            t = args[0] if len(args) == 1 else t
        literal = None
        if get_origin(t) is Literal:
            literal = get_args(t)
            t = type(literal[0])
        out[f.name] = FieldType(t, optional, literal)
    return out


def _describe_range(kind: str, low: Optional[float], high: Optional[float]) -> str:
    if low is not None and high is not None:
        return f"{kind} from {low:g} to {high:g}"
    if low is not None:
        return f"{kind} >= {low:g}"
    if high is not None:
        return f"{kind} <= {high:g}"
    return kind


def check_value(name: str, value: Any, ft: FieldType, info: OptionInfo) -> None:
    """Raise :class:`InputError` naming ``name`` unless ``value`` fits the field's type and metadata."""
    if value is None:
        if ft.optional:
            return
        raise InputError(name, "is required")
    choices = ft.literal if ft.literal is not None else info.choices
    if choices is not None:
        if value not in choices:
            raise InputError(name, f"must be one of {', '.join(map(repr, choices))}; got {value!r}")
        return
    if ft.base is bool:
        if not isinstance(value, bool):
            raise InputError(name, f"must be True or False, got {value!r}")
    elif ft.base is int:
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise InputError(name, f"must be an {_describe_range('integer', info.low, info.high)}, got {value!r}")
    elif ft.base is float:
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
            raise InputError(name, f"must be a finite {_describe_range('number', info.low, info.high)}, "
                                   f"got {value!r}")
    elif ft.base is str:
        if not isinstance(value, str) or value == "":
            raise InputError(name, f"must be a non-empty text, got {value!r}")
    elif dataclasses.is_dataclass(ft.base):
        if not isinstance(value, ft.base):
            raise InputError(name, f"must be a {ft.base.__name__}, got {type(value).__name__}")
    if ft.base in (int, float) and ((info.low is not None and value < info.low)
                                    or (info.high is not None and value > info.high)):
        kind = "an integer" if ft.base is int else "a number"
        raise InputError(name, f"must be {_describe_range(kind, info.low, info.high)}, got {value!r}")


def check_options(obj: Any) -> None:
    """Validate every :func:`option` field of the dataclass instance ``obj`` (the InputError names the field)."""
    types = field_types(type(obj))
    for f in dataclasses.fields(obj):
        info = option_info(f)
        if info is not None:
            check_value(f.name, getattr(obj, f.name), types[f.name], info)


def documented(cls: Type) -> Type:
    """Class decorator: append an "Attributes" section made of the option fields' help to the docstring."""
    lines = []
    for f in dataclasses.fields(cls):
        info = option_info(f)
        if info is None:
            continue
        if f.default is not dataclasses.MISSING:
            default = info.default_text or repr(f.default)
            lines.append(f"    {f.name}: {info.help} Default: {default}.")
        else:
            lines.append(f"    {f.name}: {info.help}")
    if lines:
        cls.__doc__ = (cls.__doc__ or "").rstrip() + "\n\nAttributes:\n" + "\n".join(lines) + "\n"
    return cls
