"""Artifacts: provenance, byte-for-byte determinism, reuse only when fresh, atomic writes."""

from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest

from quadctl import artifacts, config
from quadctl.errors import ArtifactError
from quadctl.workspace import Workspace

ALL = ("trim.json", "linear.npz", "subsystems.json", "checks.json", "design.json", "sim.npz", "sim.json")
_CREATED = re.compile(rb'"created": ?"[^"]*"')


def _run_all(cfg, out):
    ws = Workspace(cfg, out)
    ws.checks, ws.design, ws.simulation  # noqa: B018 - evaluating the stages writes them
    return ws


def test_same_config_gives_identical_artifacts_apart_from_created(tmp_path):
    cfg = config.load("hover")
    _run_all(cfg, tmp_path / "a")
    _run_all(cfg, tmp_path / "b")
    for name in ALL:
        a, b = (_without_created(tmp_path / d / name) for d in ("a", "b"))
        assert a == b, name


def _without_created(path):
    """File bytes with the JSON ``created`` field blanked (NPZ files carry none)."""
    return _CREATED.sub(b"", path.read_bytes())


def test_every_artifact_records_provenance(tmp_path):
    cfg = config.load("forward")
    _run_all(cfg, tmp_path)
    for name in ALL:
        meta = (artifacts.read_npz(tmp_path / name)[1] if name.endswith(".npz")
                else artifacts.read_json(tmp_path / name))
        assert meta["config_hash"] == cfg.digest(), name
        assert meta["state_names"][:3] == ["pN", "pE", "pD"] and meta["input_names"] == ["T", "A", "E", "R"]
        assert meta["quadctl_version"]


def test_upstream_reused_only_when_config_hash_matches(tmp_path):
    cfg = config.load("forward")
    Workspace(cfg, tmp_path).linear  # noqa: B018
    ws = Workspace(cfg, tmp_path)
    ws.design  # noqa: B018
    assert tmp_path / "linear.npz" in ws.reused
    # a different config in the same folder: recomputed, never stale
    other = config.from_dict({**cfg.model_dump(mode="json"), "vehicle": {"mass": 0.08}}, "x")
    ws2 = Workspace(other, tmp_path)
    assert ws2.trim.u[0] == pytest.approx(0.08 * 9.81 * np.cos(ws2.trim.x[7]))
    ws2.linear  # noqa: B018
    assert tmp_path / "linear.npz" not in ws2.reused
    assert artifacts.read_npz(tmp_path / "linear.npz")[1]["config_hash"] == other.digest()


def test_corrupted_artifact_is_a_clear_error(tmp_path):
    cfg = config.load("forward")
    Workspace(cfg, tmp_path).linear  # noqa: B018
    (tmp_path / "trim.json").write_text("{not json")
    with pytest.raises(ArtifactError, match=r"trim.json: corrupted artifact .*delete it or rerun with --fresh"):
        Workspace(cfg, tmp_path).trim  # noqa: B018
    assert Workspace(cfg, tmp_path, fresh=True).trim.residual < 1e-12  # --fresh recovers


def test_foreign_format_is_refused(tmp_path):
    path = tmp_path / "trim.json"
    path.write_text(json.dumps({"format_version": 999, "quadctl_version": "9.9", "config_hash": "x"}))
    with pytest.raises(ArtifactError, match=r"written by quadctl 9.9 in another format"):
        artifacts.read_json(path)


def test_atomic_write_leaves_old_file_whole_on_failure(tmp_path, monkeypatch):
    path = tmp_path / "a.json"
    artifacts.write_json(path, {"v": 1})

    def boom(*_):
        raise KeyboardInterrupt

    monkeypatch.setattr(artifacts.os, "replace", boom)
    with pytest.raises(KeyboardInterrupt):
        artifacts.write_json(path, {"v": 2})
    assert json.loads(path.read_text()) == {"v": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]  # no temporary left behind


def test_unwritable_out_folder_is_a_clear_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(ArtifactError, match=r"cannot write artifacts there .*choose another --out folder"):
        artifacts.write_json(blocker / "sub" / "x.json", {})


def test_artifacts_follow_the_umask_not_mkstemps_0600(tmp_path):
    old = os.umask(0o022)
    try:
        path = artifacts.write_json(tmp_path / "a.json", {})
    finally:
        os.umask(old)
    assert path.stat().st_mode & 0o777 == 0o644


def test_json_keeps_infinity_apart_from_nan_and_complex_as_pairs():
    value = {"e": np.array([1 + 2j, -3 + 0j]), "n": float("nan"), "gm": (-np.inf, 6.0, np.float32(np.inf)),
             "none": None}
    coded = artifacts.jsonable(value)
    assert coded == {"e": [[1.0, 2.0], [-3.0, 0.0]], "n": None, "gm": ["-inf", 6.0, "inf"], "none": None}
    json.dumps(coded, allow_nan=False)  # strict JSON
    assert artifacts.decode_floats(coded)["gm"] == [-np.inf, 6.0, np.inf]


def _eigenvalue_fields(value, path=""):
    """(path, value) of every key naming eigenvalues, anywhere in a JSON document."""
    if isinstance(value, dict):
        for key, item in value.items():
            if "eigenvalue" in key:
                yield f"{path}.{key}", item
            else:
                yield from _eigenvalue_fields(item, f"{path}.{key}")
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from _eigenvalue_fields(item, f"{path}[{i}]")


def _is_pair(value) -> bool:
    number = (float, int, str)  # a part may be "inf" / "-inf" (a deadbeat mode's ln(0) / Ts)
    return isinstance(value, list) and len(value) == 2 and all(isinstance(v, number) for v in value)


def test_every_eigenvalue_in_every_json_artifact_is_a_pair(tmp_path):
    """design.json used to mix plain floats (all real) and [re, im] pairs (some complex)."""
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    runs = {"forward": ["design", "--full"], "mambo-200hz": ["design", "--full"], "hover": ["check"]}
    for name, command in runs.items():
        res = CliRunner().invoke(app, [*command, "-c", name, "-o", str(tmp_path / name)])
        assert res.exit_code == 0, res.output
    fields = [(f"{path.relative_to(tmp_path)}{where}", v) for path in sorted(tmp_path.rglob("*.json"))
              for where, v in _eigenvalue_fields(json.loads(path.read_text()))]
    assert {f.split(".json")[0] for f, _ in fields} >= {"forward/design", "forward/design_full", "hover/checks",
                                                       "mambo-200hz/design", "mambo-200hz/design_full"}
    for where, value in fields:
        if value is None:  # a continuous design has no z eigenvalues: not applicable
            assert where.endswith("_z"), where
            continue
        assert _is_pair(value) or (isinstance(value, list) and value and all(_is_pair(v) for v in value)), \
            (where, value)
    altitude = dict(fields)["forward/design.json.subsystems.altitude.closed_loop_eigenvalues"]
    assert len(altitude) == 2 and all(im == 0.0 for _, im in altitude)  # all real: still pairs
