"""An artifact's ``meta`` record: the provenance every artifact carries, and its format's version."""

from __future__ import annotations

from datetime import datetime, timezone

from quadctl.artifacts import provenance
from quadctl.layout import INPUT_NAMES, STATE_NAMES
from quadctl.version import __version__

FORMAT_VERSION = 1
"""Bumped when the layout of an artifact changes incompatibly."""
IDENTITY_KEYS = ("artifact", "config_hash")
"""Keys of :func:`metadata` that every artifact carries and no input file has: what tells an artifact
(given where a config goes, say) apart."""
RESOLVED_CONFIG_HEAD = "# the config as quadctl"
"""How ``config.resolved.yaml`` opens (:class:`quadctl.workspace.Workspace`): a stamp of quadctl's
(:func:`quadctl.artifacts.lock.stamped`)."""
IDENTIFIED_CONFIG_HEAD = "# Identified by quadctl identify from"
"""How ``identified.yaml`` opens (:func:`quadctl.identify.config_edits.identified_config`): a stamp of quadctl's."""


def carries_provenance(data) -> bool:
    """Whether ``data``, a mapping read from a file, carries an artifact's provenance (:data:`IDENTITY_KEYS`).

    >>> carries_provenance({"artifact": "trim", "config_hash": "ab12"}), carries_provenance({"artifact": "trim"})
    (True, False)
    """
    return isinstance(data, dict) and all(key in data for key in IDENTITY_KEYS)


def metadata(cfg, kind: str, backends=()) -> dict:
    """Provenance fields every artifact carries.

    ``backends``: the simulation backends the stage ran (``SimResult.backend``), which decide the
    ``compiler`` field (see :func:`quadctl.artifacts.provenance.compiler`); empty when it ran no loop.
    """

    return {
        "artifact": kind,
        "format_version": FORMAT_VERSION,
        "quadctl_version": __version__,
        "config_name": cfg.name,
        "config_hash": cfg.digest(),
        "created": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "state_names": list(STATE_NAMES),
        "input_names": list(INPUT_NAMES),
        "software": provenance.software(),
        "compiler": provenance.compiler(backends),
    }
