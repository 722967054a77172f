"""Artifacts: provenance, byte-for-byte determinism, reuse only when fresh, atomic writes."""

from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest

from quadctl import artifacts, config
from quadctl.artifacts import writing
from quadctl.errors import ArtifactError, QuadctlNotice
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


def test_sim_npz_carries_the_units_of_t_x_and_u_beside_their_names(tmp_path):
    """t (and dt) in s, each column of x and u in its unit, in the order of the names: the layout's units, as
    the .mat export has them (``state_units``, ``input_units``)."""
    from quadctl.layout import INPUT_UNITS, STATE_UNITS

    data = config.load("hover").model_dump(mode="json")
    data["simulation"]["duration"] = 0.1
    Workspace(config.from_dict(data), tmp_path).simulation  # noqa: B018 - evaluating the stage writes it
    npz, _ = artifacts.read_npz(tmp_path / "sim.npz")
    assert str(npz["t_unit"]) == "s" and npz["state_units"].shape == (12,) and npz["input_units"].shape == (4,)
    assert dict(zip(npz["state_names"], npz["state_units"])) == STATE_UNITS
    assert dict(zip(npz["input_names"], npz["input_units"])) == INPUT_UNITS
    assert list(npz["state_units"][[0, 3, 6, 9]]) == ["m", "m/s", "rad", "rad/s"] and npz["input_units"][0] == "N"


def test_linear_npz_and_design_json_carry_the_units_of_their_states_and_inputs(tmp_path):
    """A, B, x_trim and u_trim, and design.json's gains, in the layout's units, as sim.npz gives them: linear.npz
    named its states and inputs but not their units (an angle in rad, not deg, read nowhere)."""
    from quadctl.layout import INPUT_UNITS, STATE_UNITS

    ws = Workspace(config.load("hover"), tmp_path)
    ws.design  # noqa: B018 - evaluating the stage writes it and linear.npz
    npz, _ = artifacts.read_npz(tmp_path / "linear.npz")
    assert dict(zip(npz["state_names"], npz["state_units"])) == STATE_UNITS
    assert dict(zip(npz["input_names"], npz["input_units"])) == INPUT_UNITS
    assert artifacts.read_json(tmp_path / "design.json")["units"] == {**STATE_UNITS, **INPUT_UNITS}


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
    with pytest.warns(QuadctlNotice, match=r": removed trim\.json, linear\.npz, subsystems\.json, design\.json, "
                                           r"made by another config \(config_hash "):
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


@pytest.mark.parametrize("content", ["pickled objects", "random bytes", "a truncated zip"])
def test_an_npz_numpy_cannot_read_is_not_a_valid_artifact_rerun_with_fresh(tmp_path, content):
    """NumPy's reason (its allow_pickle advice, cut off mid-word at 120 characters) gave no way out."""
    import io

    cfg = config.load("forward")
    Workspace(cfg, tmp_path).linear  # noqa: B018
    path = tmp_path / "linear.npz"
    if content == "pickled objects":
        buffer = io.BytesIO()
        np.save(buffer, np.array([object()]), allow_pickle=True)
        path.write_bytes(buffer.getvalue())
    else:
        path.write_bytes(bytes(range(256)) if content == "random bytes" else b"PK\x03\x04 truncated")
    with pytest.raises(ArtifactError) as info:
        artifacts.read_npz(path)
    assert str(info.value) == (f"{path}: corrupted artifact: not a valid quadctl artifact (an .npz of named arrays and "
                               "its meta record); rerun with --fresh to recompute it")
    assert Workspace(cfg, tmp_path, fresh=True).linear.A.shape == (12, 12)  # --fresh recovers


def test_foreign_format_is_refused(tmp_path):
    path = tmp_path / "trim.json"
    path.write_text(json.dumps({"format_version": 999, "quadctl_version": "9.9", "config_hash": "x"}))
    with pytest.raises(ArtifactError, match=r"written by quadctl 9.9 in another format"):
        artifacts.read_json(path)


def test_atomic_write_leaves_old_file_whole_on_failure(tmp_path, monkeypatch):
    path = tmp_path / "trim.json"
    artifacts.write_json(path, {"v": 1})

    def boom(*_):
        raise KeyboardInterrupt

    monkeypatch.setattr(writing.os, "replace", boom)
    with pytest.raises(KeyboardInterrupt):
        artifacts.write_json(path, {"v": 2})
    assert json.loads(path.read_text()) == {"v": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["trim.json"]  # no temporary left behind


def test_unwritable_out_folder_is_a_clear_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(ArtifactError, match=r"cannot write artifacts there .*choose another --out folder"):
        artifacts.write_json(blocker / "sub" / "trim.json", {})


def test_a_run_folder_in_a_current_folder_that_was_deleted_is_bad_input(tmp_path, monkeypatch):
    """`quadctl trim` in a shell whose folder was removed under it was an internal error (exit 3, "please
    report it") at os.path.abspath: now one line, exit 2."""
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    gone = tmp_path / "gone"
    gone.mkdir()
    monkeypatch.chdir(gone)
    gone.rmdir()
    res = CliRunner().invoke(app, ["trim", "-c", "hover"])
    assert res.exit_code == 2, res.output
    assert res.stderr.strip() == ("quadctl: error: runs/hover: cannot write artifacts there (the current folder no "
                                  "longer exists: deleted or moved); cd to a folder that exists, or give -o an "
                                  "absolute path")


def test_artifacts_follow_the_umask_not_mkstemps_0600(tmp_path):
    old = os.umask(0o022)
    try:
        path = artifacts.write_json(tmp_path / "trim.json", {})
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


@pytest.mark.parametrize("fchmod", [True, False], ids=["os.fchmod", "no os.fchmod (Windows, Python < 3.13)"])
def test_artifacts_follow_the_umask_with_or_without_fchmod(tmp_path, monkeypatch, fchmod):
    if not fchmod:
        monkeypatch.delattr(writing.os, "fchmod", raising=False)
    old = os.umask(0o027)
    try:
        path = artifacts.write_json(tmp_path / "trim.json", {"v": 1})
    finally:
        os.umask(old)
    assert path.stat().st_mode & 0o777 == 0o640
    assert json.loads(path.read_text()) == {"v": 1} and [p.name for p in tmp_path.iterdir()] == ["trim.json"]


# ---------------------------------------------------------------------------------------
# Names: constants, and never a path out of the run directory


def test_every_name_the_stages_write_is_registered():
    from quadctl import report
    from quadctl.artifacts import session
    from quadctl.export import c, data
    from quadctl.sweep import outputs, store

    names = {session.CONFIG_GIVEN, session.CONFIG_RESOLVED, c.HEADER, c.SOURCE, data.MAT_FILE, data.JSON_FILE,
             "sweep.csv", "sweep.json", "sweep.png", *outputs.MC_FILES}
    assert names <= artifacts.ARTIFACT_NAMES, names - artifacts.ARTIFACT_NAMES
    assert store.PARTS in artifacts.SUBFOLDER_NAMES and artifacts.PLOTS in artifacts.SUBFOLDER_NAMES
    assert all(artifacts.SUBFOLDER_NAMES[report.FOLDER].fullmatch(n) for n in (report.HTML, report.MARKDOWN))


@pytest.mark.parametrize("name", ["notes.json", "plots/../../x.png", "sweep.parts/a.json", "plots/trim.png/x",
                                  "plots/trim.png.json", "sweep.parts/chunk-1.json.png", "report/report.html.json"])
def test_a_name_quadctl_does_not_write_is_refused_before_writing(tmp_path, name):
    with pytest.raises(ValueError, match="not an artifact name quadctl writes"):
        artifacts.write_json(tmp_path / "out" / name, {})
    assert not any(tmp_path.rglob("*.json"))


@pytest.mark.parametrize("stem", ["../../x/roll", "a/b", "..", ".hidden", "a\\b", "roll.png/x", "roll.png/../../x",
                                  "roll\n", "roll.png\x00"])
def test_a_figure_name_from_a_config_cannot_leave_the_run_directory(tmp_path, stem):
    """The whole name is matched: ``roll.png/x`` starts like a figure's name and is none."""
    with pytest.raises(ArtifactError, match=r"cannot name a figure in .*plots .*rename it in the config"):
        artifacts.plot_path(tmp_path, stem)


def test_a_subsystem_named_like_a_path_writes_no_figure_outside(tmp_path):
    """A subsystem key is any string the YAML allows; its figure must not land outside -o."""
    import yaml
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    data = config.load("hover").model_dump(mode="json")
    data["subsystems"]["../escaped"] = data["subsystems"].pop("yaw")
    data["lqr"]["../escaped"] = data["lqr"].pop("yaw")
    data["simulation"]["duration"] = 0.05
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(data))
    res = CliRunner().invoke(app, ["simulate", "-c", str(path), "-o", str(tmp_path / "out"), "--plot"])
    assert res.exit_code in (2, 0), res.output  # refused as a config or as a figure name, never exit 3
    assert not (tmp_path / "out" / "escaped.png").exists() and not (tmp_path / "escaped.png").exists()
    if res.exit_code == 2:
        assert "rename it in the config" in res.output or "subsystems" in res.output


# ---------------------------------------------------------------------------------------
# Reading: provenance intact, content broken


def _break(path, kind):
    """Rewrite an artifact with its provenance intact and its content broken."""
    if path.suffix == ".npz":
        arrays, meta = artifacts.read_npz(path)
        arrays["A"] = arrays["A"][:3, :3]
        artifacts.write_npz(path, arrays, meta)
    else:
        data = json.loads(path.read_text())
        if kind == "missing x":
            del data["x"]
        else:
            data["K_block"] = data["K_block"][:3]
        path.write_text(json.dumps(data))


BROKEN = [("trim.json", "missing x", r"x is missing"),
          ("design.json", "K_block 3 x 12", r"K_block is 3×12, expected 4×12"),
          ("linear.npz", "A 3 x 3", r"A is 3×3, expected 12×12")]


@pytest.mark.parametrize("name, kind, problem", BROKEN, ids=[b[1] for b in BROKEN])
def test_a_broken_artifact_with_intact_provenance_is_invalid_not_fresh(tmp_path, name, kind, problem):
    cfg = config.load("forward")
    ws = Workspace(cfg, tmp_path)
    ws.design  # noqa: B018 - writes trim.json, linear.npz, design.json
    path = tmp_path / name
    assert artifacts.is_fresh(path, cfg)
    _break(path, kind)
    if name.endswith(".npz"):
        with np.load(path) as npz:
            meta = json.loads(str(npz["meta"]))
    else:
        meta = json.loads(path.read_text())
    assert meta["config_hash"] == cfg.digest() and meta["quadctl_version"]  # provenance intact
    reader = artifacts.read_npz if name.endswith(".npz") else artifacts.read_json
    with pytest.raises(artifacts.InvalidArtifact, match=rf"{name}: invalid artifact: {problem}; "
                                                        "delete it or rerun with --fresh"):
        reader(path)
    with pytest.warns(QuadctlNotice) as notes:
        assert not artifacts.is_fresh(path, cfg)
    assert [str(n.message) for n in notes] == [f"{name} in {tmp_path} is damaged ({problem}); recomputed"]


@pytest.mark.parametrize("name, kind, problem", BROKEN, ids=[b[1] for b in BROKEN])
def test_a_later_stage_names_a_damaged_artifact_then_recomputes_it(tmp_path, name, kind, problem):
    """Each of these crashed a later stage (exit 3) before; now the stage that reads it recomputes it
    (`simulate` reads the linear model and the gains; the trim is read by `trim` and `linearize`)."""
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    cfg = config.load("hover")
    Workspace(cfg, tmp_path).design  # noqa: B018
    reader = artifacts.read_npz if name.endswith(".npz") else artifacts.read_json
    before = reader(tmp_path / name)
    _break(tmp_path / name, kind)
    command = "trim" if name == "trim.json" else "simulate"
    res = CliRunner().invoke(app, [command, "-c", "hover", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert f"quadctl: note: {name} in {tmp_path} is damaged ({problem}); recomputed" in res.stderr.splitlines()
    assert res.stderr.count("is damaged") == 1  # named once, then recomputed
    after = reader(tmp_path / name)  # rewritten whole, with the same numbers (nothing else changes)
    key = {"trim.json": "x", "design.json": "K_block", "linear.npz": "A"}[name]
    first, second = (r[0] if name.endswith(".npz") else r for r in (before, after))
    assert np.array_equal(np.asarray(first[key]), np.asarray(second[key]))
    assert artifacts.is_fresh(tmp_path / name, cfg)


@pytest.mark.parametrize("value, problem", [
    ([0.0] * 11, "x is 11, expected 12"), ([[0.0] * 12], "x is 1×12, expected 12"),
    ([None] + [0.0] * 11, "x has values that are not finite"), (["1.5"] + [0.0] * 11, "x is not an array of numbers"),
    ("x", "x is not an array of numbers")])
def test_the_reader_names_what_is_wrong(value, problem):
    data = {"x": value, "u": [0.6, 0, 0, 0], "xdot": [0.0] * 12, "residual": 0.0, "iterations": 3}
    with pytest.raises(artifacts.InvalidArtifact, match=re.escape(problem)):
        artifacts.validate("trim.json", data)


def test_integrators_set_the_shape_of_ki_block():
    ok = {"K_block": [[0.0] * 12] * 4, "integral_states": ["pD"], "Ki_block": [[1.0]] * 4}
    artifacts.validate("design.json", ok)
    with pytest.raises(artifacts.InvalidArtifact, match="Ki_block is 4×0, expected 4×1"):
        artifacts.validate("design.json", {**ok, "Ki_block": [[]] * 4})
    with pytest.raises(artifacts.InvalidArtifact, match="integral_states is not a list of state names"):
        artifacts.validate("design.json", {**ok, "integral_states": ["altitude"]})


# ---------------------------------------------------------------------------------------
# Writing into a folder that cannot take it: bad input (exit 2), never a traceback


def _cli(*args):
    from typer.testing import CliRunner

    from quadctl.cli.app import app

    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.mark.parametrize("fresh", [False, True], ids=["reuse", "--fresh"])
def test_an_artifact_path_that_is_a_directory_is_bad_input(tmp_path, fresh):
    (tmp_path / artifacts.MARK_NAME).write_text(artifacts.lock.MARK_TEXT)  # quadctl's folder: the claim takes it
    (tmp_path / "trim.json").mkdir()
    res = _cli("trim", "-c", "hover", "-o", tmp_path, *(["--fresh"] if fresh else []))
    assert res.exit_code == 2, res.output
    line = " ".join(res.output.split())
    assert f"quadctl: error: {tmp_path / 'trim.json'}: is a directory, not a file quadctl can write; remove it " \
           "or choose another --out folder" in line
    assert "internal error" not in line and not list(tmp_path.glob(".*.tmp"))


def test_a_folder_that_refuses_writes_is_bad_input(tmp_path, monkeypatch):
    """What a read-only folder does to mkstemp (simulated: root may write anywhere)."""
    def refuse(*_, **__):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(writing.tempfile, "mkstemp", refuse)
    res = _cli("trim", "-c", "hover", "-o", tmp_path)
    assert res.exit_code == 2, res.output
    assert f"quadctl: error: {tmp_path}: cannot write artifacts there (Permission denied); choose another " \
           "--out folder" in " ".join(res.output.split())


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_folder_is_bad_input(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        res = _cli("trim", "-c", "hover", "-o", folder)
    finally:
        folder.chmod(0o755)
    assert res.exit_code == 2, res.output
    line = " ".join(res.output.split())
    assert "cannot write artifacts there (Permission denied); choose another --out folder" in line


def test_a_failing_disk_is_bad_input_naming_the_artifact(tmp_path, monkeypatch):
    def full(*_):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(writing.os, "fsync", full)
    with pytest.raises(ArtifactError, match=r"trim.json: cannot write the artifact \(No space left on device\); "
                                            "free the space or the permission it needs, or choose another --out"):
        artifacts.write_json(tmp_path / "trim.json", {})
    assert list(tmp_path.iterdir()) == []
