"""Command-line flags derived from the configuration dataclasses: one flag per field, one name everywhere.

A field's flag is its dotted path in the TOML file the command reads, spelled as the TOML section and key
(``[voxel] resolution`` <-> ``--voxel.resolution``; the REST body's nested keys are the same:
``{"config": {"voxel": {"resolution": 0.02}}}``). Its type comes from the annotation (int, float, bool, str,
Path, ``Literal`` choices, tuples), its help text from the field's attribute docstring (the first sentence)
and the default rendered from the dataclass itself, never written twice. A flag's default is ``None``,
"the config's default": only the flags given on the command line reach the config, by :func:`apply_flags`
through the dataclasses' own validation (``planner.config.merge``, which is ``dataclasses.replace`` per
section).

Short names that commands had before (``--views``, ``--resolution``, ``--port`` ...) are aliases: the same
destination, so either spelling sets the same field.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import inspect
import re
import textwrap
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from planner.config import merge

__all__ = [
    "ConfigField",
    "UnflaggableError",
    "add_config_flags",
    "apply_flags",
    "config_fields",
    "field_docs",
    "flag_overrides",
    "parse_bool",
    "render_value",
]


class UnflaggableError(TypeError):
    """A field whose type has no flag spelling (a matrix, a list of tables): set it in the TOML file."""


@dataclass(frozen=True)
class ConfigField:
    """One leaf field of a configuration dataclass, with everything its flag and its documentation need."""

    path: tuple[str, ...]
    """Keys from the root dataclass to the field, e.g. ``("voxel", "resolution")``."""
    annotation: Any
    """The resolved type annotation."""
    default: Any
    """The default value, from the dataclass (a default factory is called)."""
    doc: str
    """The field's attribute docstring, whitespace normalised ('' when it has none)."""
    owner: type
    """The dataclass that declares the field."""
    default_note: str = ""
    """How the default is found when a function computes it (its docstring), instead of the value found here."""

    @property
    def default_text(self) -> str:
        """The default as the documentation and the help show it."""
        return self.default_note or render_value(self.default)

    @property
    def name(self) -> str:
        """The dotted path: the TOML key under its sections, the REST body's nested keys, the flag's name."""
        return ".".join(self.path)

    @property
    def summary(self) -> str:
        """The first sentence of :attr:`doc`."""
        return first_sentence(self.doc)


# ---------------------------------------------------------------------- reading the dataclasses


@functools.cache
def field_docs(cls: type) -> dict[str, str]:
    """``{field: attribute docstring}`` of dataclass ``cls`` and its dataclass bases, read from their source
    with ``ast`` (the string literal right after the annotated assignment)."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        body = tree.body[0].body  # type: ignore[attr-defined]
        for stmt, after in zip(body, [*body[1:], None], strict=True):
            if (
                isinstance(stmt, ast.AnnAssign)
                and isinstance(stmt.target, ast.Name)
                and isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)
            ):
                docs[stmt.target.id] = " ".join(inspect.cleandoc(after.value.value).split())
    return docs


def first_sentence(text: str) -> str:
    """``text`` up to the end of its first sentence (a full stop followed by a space and a capital, or the end)."""
    match = re.search(r"\.\s+(?=[A-Z(])", text)
    return text if match is None else text[: match.start() + 1]


def _default(f: dataclasses.Field[Any]) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    raise TypeError(f"{f.name}: a configuration field needs a default")


def config_fields(cls: type, prefix: tuple[str, ...] = ()) -> list[ConfigField]:
    """The leaf fields of dataclass ``cls`` in declaration order, recursing into nested dataclass fields."""
    hints = typing.get_type_hints(cls)
    docs = field_docs(cls)
    out: list[ConfigField] = []
    for f in dataclasses.fields(cls):
        annotation = hints[f.name]
        if isinstance(annotation, type) and dataclasses.is_dataclass(annotation):
            out.extend(config_fields(annotation, (*prefix, f.name)))
            continue
        owner = next(k for k in cls.__mro__ if f.name in getattr(k, "__annotations__", {}))
        factory = f.default_factory
        note = (
            "" if factory is dataclasses.MISSING or isinstance(factory, type) else first_sentence(factory.__doc__ or "")
        )
        out.append(ConfigField((*prefix, f.name), annotation, _default(f), docs.get(f.name, ""), owner, note))
    return out


def section_doc(cls: type, path: Sequence[str]) -> tuple[type, str]:
    """The dataclass at ``path`` under ``cls`` and its docstring (the first paragraph, one line)."""
    for key in path:
        cls = typing.get_type_hints(cls)[key]
    return cls, " ".join((inspect.cleandoc(cls.__doc__ or "").split("\n\n")[0]).split())


# ---------------------------------------------------------------------- values


def parse_bool(text: str) -> bool:
    """argparse type of a bool field: true/false (also yes/no, on/off, 1/0)."""
    value = text.strip().lower()
    if value in ("true", "yes", "on", "1"):
        return True
    if value in ("false", "no", "off", "0"):
        return False
    raise argparse.ArgumentTypeError(f"expected true or false, got {text!r}")


def render_value(value: Any) -> str:
    """A value as it is written in TOML (``true``, ``"fast"``, ``[0.0, 1.0]``, ``0.01``); ``None`` as ``unset``."""
    if value is None:
        return "unset"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str | Path):
        return '"' + str(value) + '"'
    if isinstance(value, tuple | list):
        return "[" + ", ".join(render_value(v) for v in value) + "]"
    return repr(value)


def type_text(annotation: Any) -> str:
    """A short human name of a field's type: ``float``, ``int``, ``"fast" or "exhaustive"``, ``[float, ...]``."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is Literal:
        return " or ".join(render_value(a) for a in args)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"[{type_text(args[0])}, ...]"
        return "[" + ", ".join(type_text(a) for a in args) + "]"
    if origin in (typing.Union, types.UnionType):
        return " or ".join("unset" if a is type(None) else type_text(a) for a in args)
    if annotation is Path:
        return "path"
    return getattr(annotation, "__name__", str(annotation))


def _flag_kwargs(f: ConfigField) -> dict[str, Any]:
    """argparse keywords (type, choices, nargs, metavar) for field ``f``; UnflaggableError when it has none."""
    annotation = f.annotation
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin in (typing.Union, types.UnionType):
        rest = [a for a in args if a is not type(None)]
        if len(rest) != 1:
            raise UnflaggableError(f"{f.name}: a union of {args}")
        annotation = rest[0]
        origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if annotation is bool:
        return {"type": parse_bool, "metavar": "{true,false}"}
    if annotation in (int, float, str):
        return {"type": annotation, "metavar": annotation.__name__.upper()}
    if annotation is Path:
        return {"type": Path, "metavar": "PATH"}
    if origin is Literal:
        return {"choices": list(args)}
    if origin is tuple and args:
        item = args[0]
        if item not in (int, float, str) or any(a not in (item, Ellipsis) for a in args):
            raise UnflaggableError(f"{f.name}: a tuple of {args}")
        if len(args) == 2 and args[1] is Ellipsis:
            return {"type": item, "nargs": "*", "metavar": item.__name__.upper()}
        return {"type": item, "nargs": len(args), "metavar": item.__name__.upper()}
    raise UnflaggableError(f"{f.name}: no flag for the type {annotation!r}")


def flag_help(f: ConfigField) -> str:
    """The help text of ``f``'s flag: the first sentence of its docstring and its default (argparse-escaped)."""
    text = f"{f.summary} (default: {f.default_text})".strip()
    return text.replace("%", "%%")


# ---------------------------------------------------------------------- the parser


def add_config_flags(
    parser: argparse.ArgumentParser,
    cls: type,
    *,
    prefix: Sequence[str] = (),
    aliases: Mapping[str, Sequence[str]] | None = None,
    types_: Mapping[str, Callable[[str], Any]] | None = None,
    exclude: Callable[[ConfigField], bool] | None = None,
    title: str | None = None,
) -> list[ConfigField]:
    """Add one flag per leaf field of dataclass ``cls`` to ``parser`` (one argument group per section) and
    return the fields that got one.

    prefix: path segments before the fields' own (``("planner",)``: ``--planner.voxel.resolution``).
    aliases: extra option strings of a field, by its full dotted name (``{"voxel.resolution": ["--resolution"]}``);
        a bool field's alias is a switch that sets it true (``--dry-run``).
    types_: an argparse type replacing the annotation's for a field (by its full dotted name).
    exclude: fields that get no flag (a matrix, a list of tables; TOML only).
    """
    aliases = aliases or {}
    types_ = types_ or {}
    done: list[ConfigField] = []
    groups: dict[tuple[str, ...], argparse._ArgumentGroup] = {}
    for f in config_fields(cls, tuple(prefix)):
        if exclude is not None and exclude(f):
            continue
        try:
            kwargs: dict[str, Any] = _flag_kwargs(f)
        except UnflaggableError:
            continue
        if f.name in types_:
            kwargs = {k: v for k, v in kwargs.items() if k != "choices"}
            kwargs["type"] = types_[f.name]
        section = f.path[:-1]
        if section not in groups:
            _, doc = section_doc(cls, section[len(prefix) :])
            heading = ".".join(section) or (title or cls.__name__)
            groups[section] = parser.add_argument_group(f"[{heading}]" if section else heading, first_sentence(doc))
        group = groups[section]
        names = [a for a in aliases.get(f.name, ()) if kwargs.get("type") is not parse_bool]
        group.add_argument(f"--{f.name}", *names, dest=f.name, default=None, help=flag_help(f), **kwargs)
        if kwargs.get("type") is parse_bool:
            for alias in aliases.get(f.name, ()):
                group.add_argument(
                    alias, dest=f.name, action="store_const", const=True, help=f"the same as --{f.name} true"
                )
        done.append(f)
    return done


def flag_overrides(args: argparse.Namespace, fields: Sequence[ConfigField], drop: int = 0) -> dict[str, Any]:
    """The nested dict of the flags given on the command line (lists as tuples), keyed without the first
    ``drop`` path segments."""
    out: dict[str, Any] = {}
    for f in fields:
        value = getattr(args, f.name, None)
        if value is None:
            continue
        if isinstance(value, list):
            value = tuple(value)
        node = out
        for key in f.path[drop:-1]:
            node = node.setdefault(key, {})
        node[f.path[-1]] = value
    return out


def apply_flags(config: Any, args: argparse.Namespace, fields: Sequence[ConfigField], drop: int = 0) -> Any:
    """``config`` with the given flags' values, through the dataclasses' own validation (ValueError naming the
    field for a bad value)."""
    changes = flag_overrides(args, fields, drop)
    return merge(config, changes) if changes else config
