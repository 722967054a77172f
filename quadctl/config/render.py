"""The schema shown to people and to editors: a config as commented YAML, and the JSON Schema."""

from __future__ import annotations

import json
import re

from quadctl.config.schema import Config
from quadctl.config.schema_paths import section_model


def shown_yaml(cfg: Config, label: str) -> str:
    """:meth:`Config.to_yaml` for a reader (``quadctl configs --show``): a header pointing to
    ``quadctl init`` for a vehicle of one's own, and each key left empty (``null``) followed by what
    its absence means (the schema's description: ``motors: null   # rotor layout and thrust limits; ...``).

    Examples
    --------
    >>> from quadctl.config.loading import load
    >>> text = shown_yaml(load("hover"), "hover.yaml")
    >>> [line[:48] for line in text.splitlines() if line.startswith("motors:")]
    ['motors: null   # rotor layout and thrust limits;']
    """
    lines = [f"# {label}, validated, every default filled in. For a vehicle of your own start from",
             "# `quadctl init NAME --from crazyflie|mambo|iris`: every key with its unit, a named vehicle's values."]
    path: list[tuple[int, str]] = []
    for line in cfg.to_yaml().splitlines():
        match = re.match(r"^( *)([A-Za-z_][\w.-]*): ?(.*)$", line)
        if match is None:
            lines.append(line)
            continue
        indent, key, value = len(match.group(1)), match.group(2), match.group(3)
        path = [(i, k) for i, k in path if i < indent] + [(indent, key)]
        if value == "null":
            keys = [k for _, k in path]
            parent = section_model(keys[:-1])
            field = parent.model_fields.get(key) if parent is not None else None
            if field is not None and field.description:
                line += f"   # {field.description}{TOP_LEVEL_ABSENT.get(key, '') if len(keys) == 1 else ''}"
        lines.append(line)
    return "\n".join(lines) + "\n"


TOP_LEVEL_ABSENT = {"motors": "; absent: the inputs are not limited (`quadctl init NAME` writes motors: with units)",
                    "limits": "; absent: none"}
"""What an absent top-level section means, for :func:`shown_yaml`."""


SCHEMA_DIALECT = "http://json-schema.org/draft-07/schema#"
"""The JSON Schema draft the schema declares: draft-07, the one editors validate YAML with
(yaml-language-server); pydantic's output uses nothing newer once its ``$defs`` are renamed."""


def json_schema() -> dict:
    """The config's JSON Schema, for editors (completion, hover, checks as you type) and validators.

    Built from the schema itself (:meth:`Config.model_json_schema`): types, bounds, enums, unknown
    keys refused (``additionalProperties: false``), and each field's description with its unit.
    For editors, which show a field's description on hover but not its default, the default is
    appended to the description (``"kg; default 0.068"``); ``$defs`` become draft-07's
    ``definitions``. Rules across fields (Q's size, state names, Jxx + Jyy >= Jzz) are checked only
    when quadctl loads the config.

    Returns
    -------
    dict
        A draft-07 JSON Schema (``quadctl configs --schema`` prints it).

    Examples
    --------
    >>> json_schema()["properties"]["vehicle"]["$ref"]
    '#/definitions/VehicleConfig'
    """
    schema = Config.model_json_schema()
    schema["definitions"] = schema.pop("$defs")

    def visit(node):
        if isinstance(node, dict):
            ref = node.get("$ref")
            if isinstance(ref, str) and ref.startswith("#/$defs/"):
                node["$ref"] = "#/definitions/" + ref[len("#/$defs/"):]
            default = node.get("default")
            if isinstance(node.get("description"), str) and default not in (None, "", [], {}) \
                    and not isinstance(default, dict):
                node["description"] += f"; default {json.dumps(default)}"
            for value in node.values():
                visit(value)
        elif isinstance(node, list):
            for value in node:
                visit(value)

    visit(schema)
    schema["description"] = schema["description"].split("\n\n")[0]  # the docstring's summary, not its example
    return {"$schema": SCHEMA_DIALECT, "title": "quadctl config", **{k: v for k, v in schema.items()
                                                                     if k != "title"}}
