"""What a file quadctl reads is, told by its top-level keys: a config, a sweep file or an artifact.

A file given to the wrong option (a sweep file to ``-c``, a config to ``-s``, ``design.json`` to
``-c``) is named for what it is, with the way to pass it, instead of a list of unknown keys. The
loaders ask :func:`misplaced` only once the file has failed as what they expected, so a valid file
never pays for it.

Each kind is told by the keys it cannot lack: a config's required keys (the schema's), a sweep
file's (:data:`SWEEP_KEYS`), an artifact's provenance (:data:`quadctl.artifacts.meta.IDENTITY_KEYS`).
"""

from __future__ import annotations

from typing import Any

from quadctl.artifacts.meta import carries_provenance
from quadctl.config.schema import Config

SWEEP_KEYS = ("parameters",)
"""The keys every sweep file has (the values to vary)."""


def config_keys() -> tuple[str, ...]:
    """The keys every config has: the schema's required ones (``name``, ``lqr``)."""

    return tuple(name for name, field in Config.model_fields.items() if field.is_required())


def kind_of(data: Any) -> str | None:
    """``"artifact"``, ``"sweep"``, ``"config"`` or None: what the top-level keys of ``data`` say it is.

    >>> kind_of({"parameters": {"vehicle.mass": [0.06, 0.07]}}), kind_of({"name": "x", "lqr": {}})
    ('sweep', 'config')
    >>> kind_of({"artifact": "design", "config_hash": "ab12"}), kind_of({"mode": "grid"})
    ('artifact', None)
    """

    if not isinstance(data, dict):
        return None
    if carries_provenance(data):
        return "artifact"
    config, sweep = (all(key in data for key in keys) for keys in (config_keys(), SWEEP_KEYS))
    if sweep and not config:
        return "sweep"
    if config and not sweep:
        return "config"
    return None


def misplaced(data: Any, label: str, expected: str) -> str | None:
    """The one line for a file ``label`` given where a ``expected`` (``"config"`` or ``"sweep"``) file
    goes that is another kind of file, naming the way to pass it; None when it is not one.

    >>> misplaced({"parameters": {"vehicle.mass": [1]}}, "s.yaml", "config")
    's.yaml: is a sweep file, not a config: run it with quadctl sweep -s s.yaml (-c names the config it varies)'
    """
    kind = kind_of(data)
    if kind is None or kind == expected:
        return None
    what = "a config" if expected == "config" else "a sweep file"
    if kind == "artifact":
        fix = ("pass the config it came from (its config.yaml beside it)" if expected == "config"
               else "give a sweep file (`parameters:` and the values to vary, as examples/ci-sweep.yaml)")
        return f"{label}: is a quadctl {data['artifact']} artifact, not {what}: {fix}"
    if kind == "sweep":
        return (f"{label}: is a sweep file, not a config: run it with quadctl sweep -s {label} "
                "(-c names the config it varies)")
    return f"{label}: is a config, not a sweep file: give it to -c (quadctl sweep -c {label} -s SWEEP_FILE)"
