"""Sphinx extension: the reference pages written from the code at build time.

A page holds a marker line; when Sphinx reads the page the marker is replaced by Markdown made from
the code, so the reference cannot drift from what quadctl does:

- ``<!-- quadctl-reference: cli -->``: every command of the typer app, walked as the click command
  tree it builds: usage, help text, arguments and options (with their defaults);
- ``<!-- quadctl-reference: config -->``: every key of the config, walked from its JSON Schema
  (``quadctl.config.json_schema()``, the one ``quadctl configs --schema`` prints): type and bounds,
  default, unit and meaning from the key's description, and what its absence means;
- ``<!-- quadctl-example: NAME.py -->`` (the examples gallery): the example's title, as a heading,
  and what it shows, from the module docstring of ``examples/NAME.py``.

The functions :func:`cli_markdown`, :func:`config_markdown` and :func:`example_markdown` are plain
(no Sphinx): the tests call them too.
"""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path
from typing import Any

MARKER = re.compile(r"^<!-- quadctl-reference: (\w+) -->$", re.M)
EXAMPLE_MARKER = re.compile(r"^<!-- quadctl-example: (\w+\.py) -->$", re.M)
EXAMPLES = Path(__file__).resolve().parent.parent.parent / "examples"


# ---------------------------------------------------------------------------------------
# The command line


def _cell(text: Any) -> str:
    """Text for one cell of a Markdown table: one line, pipes escaped."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _text(text: Any) -> str:
    """Prose for a table cell: one line, and ``<`` kept as text (Markdown reads ``<name>`` as HTML)."""
    parts = re.split(r"(`[^`]*`)", _cell(text))  # inside a code span a `<` is shown as it is
    return "".join(part if part.startswith("`") else part.replace("<", "&lt;") for part in parts)


def _plain(help_text: str) -> str:
    """Typer's rich markup and click's ``\\b`` markers out of a help text."""
    text = help_text.replace("\b", "")
    return re.sub(r"\[/?(?:bold|dim|italic|red|green|yellow|cyan|magenta|blue)[^\]]*\]", "", text)


def _command_section(name: str, command, level: int) -> list[str]:
    """One command: its usage, its help, a table of its arguments and options (each as ``--help`` shows it)."""
    out = [f"{'#' * level} `{name}`", ""]
    ctx = command.context_class(command, info_name=name)
    out += ["```text", command.get_usage(ctx).strip(), "```", ""]
    if command.help:
        out += ["\n".join(_text(line) if line.strip() else "" for line in _plain(command.help).strip().split("\n")), ""]
    for kind, title in (("argument", "argument"), ("option", "option")):
        records = [(p, p.get_help_record(ctx)) for p in command.params
                   if p.param_type_name == kind and not getattr(p, "hidden", False)]
        records = [(p, r) for p, r in records if r]
        if not records:
            continue
        out += [f"| {title} | meaning |", "|---|---|"]
        for _, (names, text) in records:
            out.append(f"| `{_cell(_plain(names))}` | {_text(_plain(text))} |")
        out.append("")
    return out


def cli_markdown() -> str:
    """Every command of ``quadctl``, from the click tree typer builds: the root, then each command."""
    import typer

    from quadctl.cli.app import app

    root = typer.main.get_command(app)
    out = _command_section("quadctl", root, 2)
    for name in root.list_commands(None):
        out += _command_section(f"quadctl {name}", root.commands[name], 2)
    return "\n".join(out) + "\n"


# ---------------------------------------------------------------------------------------
# The config


def _resolve(node: dict, definitions: dict) -> dict:
    ref = node.get("$ref")
    return definitions[ref.rsplit("/", 1)[1]] if ref else node


def _type(node: dict, definitions: dict) -> str:
    """A key's type and bounds in words, from its JSON Schema."""
    if "anyOf" in node:
        kinds = [_type(n, definitions) for n in node["anyOf"] if n.get("type") != "null"]
        return " or ".join(dict.fromkeys(kinds))
    if "$ref" in node:
        return "section"
    if "enum" in node:
        return " or ".join(f"`{v}`" for v in node["enum"])
    if "const" in node:
        return f"`{node['const']}`"
    kind = node.get("type")
    if kind == "array":
        items = _type(node.get("items", {}), definitions)
        lo, hi = node.get("minItems"), node.get("maxItems")
        count = f"{lo} × " if lo is not None and lo == hi else ""
        return f"list of {count}{items}" if count else f"list of {items}"
    if kind == "object":
        extra = node.get("additionalProperties")
        if isinstance(extra, dict):
            return f"mapping to {_type(extra, definitions)}"
        return "mapping"
    words = {"number": "number", "integer": "integer", "boolean": "true or false", "string": "text"}
    text = words.get(kind, str(kind))
    bounds = []
    for key, sign in (("exclusiveMinimum", ">"), ("minimum", "≥"), ("exclusiveMaximum", "<"), ("maximum", "≤")):
        if key in node:
            bounds.append(f"{sign} {node[key]:g}" if isinstance(node[key], (int, float)) else f"{sign} {node[key]}")
    if "pattern" in node:
        bounds.append(f"matching `{node['pattern']}`")
    return f"{text} {', '.join(bounds)}".strip()


def _default(node: dict, path: tuple[str, ...]) -> str:
    """The default column: the value an absent key takes, ``absent`` where there is none."""
    from quadctl.config.schema_paths import default_at

    inside = "[i]" in path or "<name>" in path  # a key of a list item or a named entry: the schema's own
    if "default" not in node:  # a default_factory: an empty list or mapping
        empty = [] if node.get("type") == "array" else {}
        value = empty if inside else default_at({}, path)
    elif node["default"] is None:
        return "absent"
    else:
        value = node["default"] if inside else default_at({}, path)
    if value is None:
        return "absent"
    if isinstance(value, dict) and value and "$ref" in json.dumps(node) or isinstance(value, dict) and len(value) > 3:
        return "its keys' defaults"
    return f"`{json.dumps(value)}`"


def _meaning(node: dict, definitions: dict, default: str, path: tuple[str, ...] = ()) -> str:
    """The unit and meaning from the key's description, without the default it repeats, and what its
    absence means where the description does not say."""
    from quadctl.config.schema_paths import PLANT

    text = node.get("description", "") or _resolve(node, definitions).get("description", "")
    if tuple(path[:2]) == tuple(PLANT) and len(path) == 3:  # the simulated vehicle: the design vehicle's value
        text = f"{text}; absent: the design vehicle's `vehicle.{path[2]}`"
    if tuple(path) == tuple(PLANT):
        text = f"{text}; absent: the simulated vehicle is the design vehicle"
    if default.startswith("`"):
        text = re.sub(r";? ?default " + re.escape(default.strip("`")) + r"$", "", text)
    if default == "absent" and "absent" not in text and "default" not in text:
        text = f"{text}; absent: not used" if text else "absent: not used"
    return text


def _keys(properties: dict, required: set, definitions: dict, path: tuple[str, ...]) -> list[tuple]:
    rows = []
    for name, node in properties.items():
        here = (*path, name)
        rows.append((here, node, name in required))
        target = node
        if "anyOf" in node:
            target = next((n for n in node["anyOf"] if n.get("type") != "null"), node)
        if target.get("type") == "array" and "$ref" in target.get("items", {}):
            target = target["items"]
            here = (*here, "[i]")
        elif target.get("type") == "object" and isinstance(target.get("additionalProperties"), dict) \
                and "$ref" in target["additionalProperties"]:
            target = target["additionalProperties"]
            here = (*here, "<name>")
        if "$ref" in target:
            section = _resolve(target, definitions)
            rows += _keys(section.get("properties", {}), set(section.get("required", [])), definitions, here)
    return rows


def config_markdown() -> str:
    """Every key of the config: the top-level keys, then a table per section (nested keys dotted)."""
    from quadctl import config

    schema = config.json_schema()
    definitions = schema.get("definitions", schema.get("$defs", {}))
    rows = _keys(schema["properties"], set(schema.get("required", [])), definitions, ())
    header = ["| key | type | default | unit and meaning |", "|---|---|---|---|"]
    sections = {path[0] for path, _, _ in rows if len(path) > 1}
    rows = [r for r in rows if r[0][0] not in sections] + [r for r in rows if r[0][0] in sections]
    out: list[str] = ["### Top level", "", *header]
    for path, node, required in rows:
        top = path[0]
        default = "required" if required else _default(node, path)
        if top in sections and len(path) == 1:  # a section: its sentence and what its absence means, then its keys
            described = _meaning(node, definitions, default, path)
            absence = {"required": " Required.", "its keys' defaults": " Absent: each key below takes its default."}
            out += ["", f"### `{top}`", "", _text(described[:1].upper() + described[1:]).rstrip(".") + "."
                    + absence.get(default, ""), "", *header]
            continue
        key = ".".join(path).replace(".[i]", "[i]")
        out.append(f"| `{key}` | {_text(_type(node, definitions))} | {_cell(default)} "
                   f"| {_text(_meaning(node, definitions, default, path))} |")
    return "\n".join(out) + "\n"


# ---------------------------------------------------------------------------------------
# The examples gallery


def example_markdown(name: str, level: int = 2) -> str:
    """An example's entry in the gallery: its docstring's title line as a heading, the rest as prose
    (the docstrings write code as ````code````, which Markdown reads as code too)."""
    doc = ast.get_docstring(ast.parse((EXAMPLES / name).read_text(encoding="utf-8")))
    if not doc:
        raise ValueError(f"examples/{name} has no docstring: its first line is its title in the gallery")
    title, _, description = doc.partition("\n")
    return f"{'#' * level} {title.strip().rstrip('.')}\n\n{description.strip()}\n"


# ---------------------------------------------------------------------------------------
# Sphinx


GENERATORS = {"cli": cli_markdown, "config": config_markdown}


def _source_read(app, docname: str, source: list[str]) -> None:
    def replace(match: re.Match) -> str:
        name = match.group(1)
        if name not in GENERATORS:
            raise ValueError(f"{docname}: no generated reference named {name!r} (known: {sorted(GENERATORS)})")
        return GENERATORS[name]()

    source[0] = EXAMPLE_MARKER.sub(lambda match: example_markdown(match.group(1)), MARKER.sub(replace, source[0]))


API_PAGES = {"reference/python"}
"""Pages whose Python cross-references come from the docstrings: those name modules and helpers
that the reference does not document (the docstrings are written for readers of the code too)."""


def _docstring_reference(app, env, node, contnode):
    """A docstring's reference to a name the reference does not document reads as code, not a
    broken link; a page's own reference that does not resolve still fails the build (-n)."""
    if node.get("refdomain") == "py" and node.get("refdoc") in API_PAGES:
        return contnode
    return None


def setup(app):
    app.connect("source-read", _source_read)
    app.connect("missing-reference", _docstring_reference)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
