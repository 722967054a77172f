"""Provenance: the config as given and as resolved in every run folder; versions and compiler in
every artifact's metadata."""

from __future__ import annotations

import json
from importlib import metadata

import pytest
from typer.testing import CliRunner

import quadctl
from quadctl import artifacts, config
from quadctl.artifacts import provenance
from quadctl.artifacts.session import CONFIG_GIVEN, CONFIG_RESOLVED
from quadctl.cli.app import app
from quadctl.sim import engine
from quadctl.workspace import Workspace

runner = CliRunner()

# a config as a person writes it: comments, odd spacing, a non-ASCII character, CRLF line ends
GIVEN = ("# my hover — tuned by hand\r\n"
         "name:   mine   # the run folder\r\n"
         "lqr:\r\n"
         "  altitude: {Q: [50, 1], R: [1]}\r\n"
         "  roll:     {Q: [1, 50, 1], R: [1]}\r\n"
         "  pitch:    {Q: [1, 50, 1], R: [1]}\r\n"
         "  yaw:      {Q: [50, 1], R: [1]}\r\n"
         "simulation: {duration: 2.0}\r\n").encode()


def _invoke(*args):
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


def test_run_folder_keeps_the_users_bytes_and_the_resolved_config(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_bytes(GIVEN)
    res = _invoke("trim", "-c", path, "-o", tmp_path / "run")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "run" / CONFIG_GIVEN).read_bytes() == GIVEN
    resolved = (tmp_path / "run" / CONFIG_RESOLVED).read_text()
    cfg = config.parse(GIVEN.decode(), "mine.yaml")
    again = config.parse(resolved, CONFIG_RESOLVED)
    assert again.digest() == cfg.digest()  # the same config...
    assert again.model_fields_set >= {"vehicle", "trim", "simulation", "controller"}  # ...spelt out whole
    assert "max_samples: 20000" in resolved and "mass: 0.068" in resolved and cfg.digest() in resolved


def test_a_bundled_config_is_kept_as_its_text(tmp_path):
    assert _invoke("decouple", "-c", "hover", "-o", tmp_path).exit_code == 0
    assert (tmp_path / CONFIG_GIVEN).read_text() == config.bundled("hover").text
    assert (tmp_path / CONFIG_RESOLVED).read_text().endswith(config.load("hover").to_yaml())


def test_config_files_are_refreshed_with_the_artifacts_when_the_config_changes(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_bytes(GIVEN)
    _invoke("trim", "-c", path, "-o", tmp_path / "run")
    heavier = GIVEN.replace(b"lqr:", b"vehicle: {mass: 0.08}\r\nlqr:")
    path.write_bytes(heavier)
    _invoke("trim", "-c", path, "-o", tmp_path / "run")
    assert (tmp_path / "run" / CONFIG_GIVEN).read_bytes() == heavier
    assert "mass: 0.08\n" in (tmp_path / "run" / CONFIG_RESOLVED).read_text()
    trim = artifacts.read_json(tmp_path / "run" / "trim.json")
    assert trim["config_hash"] == config.parse(heavier.decode(), "x").digest()


def test_a_config_built_in_python_says_so(tmp_path):
    cfg = config.from_dict({**config.load("hover").model_dump(mode="json"), "name": "py"}, "<python>")
    Workspace(cfg, tmp_path).trim  # noqa: B018
    given = (tmp_path / CONFIG_GIVEN).read_text()
    assert given.startswith("# built in Python") and config.parse(given).digest() == cfg.digest()


def test_every_artifact_records_the_software_versions_and_the_compiler(tmp_path):
    Workspace(config.load("hover"), tmp_path).simulation  # noqa: B018
    expected = {"quadctl": quadctl.__version__,
                **{name: metadata.version(name) for name in ("numpy", "scipy", "casadi")}}
    metas = {p.name: (artifacts.read_npz(p)[1] if p.suffix == ".npz" else artifacts.read_json(p))
             for p in tmp_path.iterdir() if p.suffix in (".json", ".npz")}
    assert set(metas) >= {"trim.json", "linear.npz", "design.json", "sim.json", "sim.npz"}
    for name, meta in metas.items():
        assert {k: meta["software"][k] for k in expected} == expected, name
        assert meta["software"]["python"].count(".") == 2, name
    assert metas["trim.json"]["compiler"] == metas["design.json"]["compiler"] == provenance.NOT_USED
    sim = json.loads((tmp_path / "sim.json").read_text())
    if sim["backend"].startswith("compiled"):
        from quadctl.native.compile import find_compiler

        assert sim["compiler"]["path"] == find_compiler()
        assert sim["compiler"]["version"] and not sim["compiler"]["version"].startswith("unknown")
        assert metas["sim.npz"]["compiler"] == sim["compiler"]


def test_a_loop_run_in_casadis_vm_records_no_compiler(tmp_path, monkeypatch):
    monkeypatch.setenv("QUADCTL_NO_COMPILE", "1")
    engine.runner.cache_clear()
    try:
        with pytest.warns(engine.CompilerNotice):
            flight = Workspace(config.load("hover"), tmp_path).simulation
    finally:
        engine.runner.cache_clear()
    assert flight.sim.backend == "casadi"
    assert artifacts.read_json(tmp_path / "sim.json")["compiler"] == provenance.INTERPRETED == "none"


def test_the_compiler_is_asked_once_per_process(monkeypatch):
    calls = []
    real = provenance.subprocess.run

    def counting(*args, **kwargs):
        calls.append(args[0])
        return real(*args, **kwargs)

    provenance.compiler_version.cache_clear()
    monkeypatch.setattr(provenance.subprocess, "run", counting)
    assert provenance.compiler(()) == "not used" and provenance.compiler("casadi") == "none"
    assert calls == []  # nothing compiled: the compiler is never asked
    from quadctl.native.compile import find_compiler

    if find_compiler() is None:
        pytest.skip("no C compiler here")
    first = provenance.compiler("compiled")
    assert provenance.compiler(["compiled-simd", "casadi"]) == first
    assert len(calls) == 1 and calls[0][1:] == ["--version"]
