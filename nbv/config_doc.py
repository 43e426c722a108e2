"""docs/configuration.md and docs/configuration-server.md, generated from the configuration dataclasses:
``python -m nbv.config_doc docs``.

Every section and setting with its type, default (rendered from the dataclass), description (the field's
attribute docstring) and the names that set it: the TOML key, the REST body's keys and the command-line
flags (read from the ``nbv`` parser itself, so the page lists exactly the flags that exist). A test compares
the committed page with this output, so it cannot drift from the code.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from app.settings import AppSettings
from devices.config import DeviceConfig
from devices.faults import FaultConfig
from nbv.flags import ConfigField, config_fields, section_doc, type_text
from planner.config import REMOVED, PlannerConfig

__all__ = ["PAGES", "TABLES", "Table", "command_flags", "render", "render_pages"]


@dataclass(frozen=True)
class Table:
    """One top-level table of the configuration and where each of its settings can be given."""

    title: str
    cls: type
    prefix: tuple[str, ...]
    """The path of its settings in a server file (``("server",)``: ``[server] port``)."""
    intro: str
    skip: tuple[str, ...] = ()
    """Top-level fields documented by another table."""


TABLES: tuple[Table, ...] = (
    Table(
        "Planner",
        PlannerConfig,
        ("planner",),
        "The method's settings (`planner/config.py`). In a planner file (`nbv scan --config FILE`, also `nbv "
        "profile` and `nbv bench`) a section is a top-level table, `[voxel]`; in a server file (`nbv serve "
        "--config FILE`) it sits under `[planner]`, `[planner.voxel]`, and sets the default of every new session. "
        'Over REST, `POST /api/sessions` takes any subset under `config` with the same keys, `{"config": {"voxel": '
        '{"resolution": 0.02}}}`; `PATCH /api/sessions/{id}/config` changes the sections a session may change '
        "while it runs. Flags: `--voxel.resolution` for scan, profile and bench (some with an older short alias), "
        "`--planner.voxel.resolution` for serve.",
    ),
    Table(
        "Server",
        AppSettings,
        ("server",),
        "How `nbv serve` runs its sessions and where it listens (`workbench/settings.py`, `app/settings.py`): the "
        "`[server]` table of a server file, or `--server.KEY` flags. Not settable over REST: they belong to the "
        "server, not to a session.",
        skip=("planner", "devices", "faults"),
    ),
    Table(
        "Devices",
        DeviceConfig,
        ("devices",),
        "The simulated camera, the cell and the default object of new simulated sessions (`devices/config.py`, "
        "`devices/arm/config.py`): `[devices]` of a server file or `--devices.KEY` flags of `nbv serve`. A session "
        "created over REST chooses its `model`, `seed` and `camera` (`sensor`, `calibration`) in the body's own "
        "fields; the rest is the server's.",
    ),
    Table(
        "Faults",
        FaultConfig,
        ("faults",),
        "Faults injected into the simulated devices, for testing the workbench (`devices/faults.py`): `[faults]` of "
        "a server file, or `faults` in the body of `POST /api/sessions` on a server started with `[server] "
        "fault_api = true`. No flags.",
    ),
)


def command_flags(command: str) -> dict[str, list[str]]:
    """``{dotted setting: [option strings]}`` of an ``nbv`` sub-command, read from its parser."""
    from nbv.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    out: dict[str, list[str]] = {}
    for action in sub.choices[command]._actions:
        if action.option_strings:
            out.setdefault(action.dest, []).extend(action.option_strings)
    return out


def _cell(text: str) -> str:
    """``text`` fit for a Markdown table cell: one line, pipes escaped, Sphinx roles (``:class:``) dropped."""
    return re.sub(r":(?:class|meth|func|data|attr|mod):", "", text).replace("|", "\\|").replace("\n", " ")


def _code(text: str) -> str:
    return f"`{text}`" if text else ""


def _default(f: ConfigField) -> str:
    """The default as a code span, or the sentence that says how it is found."""
    return _cell(f.default_note) if f.default_note else _code(_cell(f.default_text))


def _flags(f: ConfigField, table: Table, scan: dict[str, list[str]], serve: dict[str, list[str]]) -> str:
    """The flags that set ``f``, as the page shows them."""
    names: list[str] = []
    if table.cls is PlannerConfig:
        names += scan.get(f.name, [])  # serve's `--planner.KEY` for each: the rule the table's intro states
    else:
        names += serve.get(".".join((*table.prefix, f.name)), [])
    return ", ".join(f"`{n}`" for n in names) or "(file only)"


def _fields(table: Table) -> Iterator[tuple[tuple[str, ...], list[ConfigField]]]:
    """The table's fields grouped by section path (relative to the table), in declaration order."""
    groups: dict[tuple[str, ...], list[ConfigField]] = {}
    for f in config_fields(table.cls):
        if f.path[0] in table.skip:
            continue
        groups.setdefault(f.path[:-1], []).append(f)
    yield from sorted(groups.items(), key=lambda item: len(item[0]) > 0)  # the table's own keys first


HEADER = (
    "<!-- Generated by `python -m nbv.config_doc docs` from the configuration dataclasses; edit their field "
    "docstrings, not this page. -->"
)

NAMES = (
    "Every setting has one name: its dotted path, the same in a TOML file (the section and the key), in the "
    "REST body's nested objects and in the command-line flag (`[voxel] resolution = 0.02`, "
    '`{"voxel": {"resolution": 0.02}}`, `--voxel.resolution 0.02`). Flags win over the file given with '
    "`--config`, which wins over the defaults below. A name that does not exist is refused with an error "
    "listing the known ones. Lengths are in metres, angles in degrees, times in seconds."
)


def _table_lines(table: Table, scan: dict[str, list[str]], serve: dict[str, list[str]]) -> list[str]:
    lines = [f"## {table.title}", "", table.intro, ""]
    for section, fields in _fields(table):
        _, doc = section_doc(table.cls, section)
        if section:
            name = ".".join(section)
            where = ".".join((*table.prefix, *section))
            head = f"[{name}]" if table.cls is PlannerConfig else f"[{where}]"
            lines += [f"### `{head}`", ""]
            if table.cls is PlannerConfig:
                lines += [f"In a server file: `[{where}]`. Over REST: `config.{name}`.", ""]
            lines += [_cell(doc), ""]
        elif table.cls is not PlannerConfig:
            lines += [f"### `[{'.'.join(table.prefix)}]`", "", _cell(doc), ""]
        lines += ["| Key | Type | Default | Flags | Description |", "| --- | --- | --- | --- | --- |"]
        for f in fields:
            lines.append(
                f"| `{f.path[-1]}` | {_code(_cell(type_text(f.annotation)))} | {_default(f)} "
                f"| {_flags(f, table, scan, serve)} | {_cell(f.doc) or '(undocumented)'} |"
            )
        lines.append("")
    return lines


def render(tables: Sequence[Table] = TABLES[:1]) -> str:
    """docs/configuration.md (Markdown): the names, the planner's settings and the removed settings."""
    scan, serve = command_flags("scan"), command_flags("serve")
    lines = ["# Configuration", "", HEADER, "", NAMES, ""]
    lines += [
        "This page lists the planner's settings; the server's, the devices' and the injected faults' are on "
        "[Server and devices](configuration-server.md).",
        "",
    ]
    for table in tables:
        lines += _table_lines(table, scan, serve)
    lines += [
        "## Removed settings",
        "",
        "Journals written before their removal still resume (the key is ignored there); a file, a flag or a "
        "request that sets one is refused with the reason.",
        "",
        "| Setting | Why |",
        "| --- | --- |",
        *(f"| `{name}` | {_cell(why)} |" for name, why in REMOVED.items()),
        "",
    ]
    return "\n".join(lines)


def render_server(tables: Sequence[Table] = TABLES[1:]) -> str:
    """docs/configuration-server.md (Markdown): the server's, the devices' and the faults' settings."""
    scan, serve = command_flags("scan"), command_flags("serve")
    lines = ["# Configuration: server and devices", "", HEADER, "", NAMES, ""]
    lines += ["The planner's settings are on [Configuration](configuration.md).", ""]
    for table in tables:
        lines += _table_lines(table, scan, serve)
    return "\n".join(lines)


PAGES = {"configuration.md": render, "configuration-server.md": render_server}
"""The generated pages, by file name under docs/."""


def render_pages() -> dict[str, str]:
    """Every generated page's text, by file name."""
    return {name: fn() for name, fn in PAGES.items()}


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m nbv.config_doc [DIR]``: write the pages into DIR (default: print docs/configuration.md)."""
    from pathlib import Path

    args = list(sys.argv[1:] if argv is None else argv)
    if not args:
        sys.stdout.write(render())
        return 0
    for name, text in render_pages().items():
        (Path(args[0]) / name).write_text(text)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
