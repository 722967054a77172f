"""A hand-edited identified.yaml is not written over: identify refuses in one line (exit 2) saying how to keep or
discard the edits, and leaves the folder byte for byte as it was; --force (init's option) writes over it."""

from __future__ import annotations

import hashlib
import json
import shutil

import pytest
from _paths import DATA
from typer.testing import CliRunner

from quadctl.cli.app import app
from quadctl.errors import ArtifactError
from quadctl.identify.results import require_unedited

LOG10 = DATA / "crazyflie-flights" / "log10"


def snapshot(folder):
    """Every file of ``folder`` (hidden ones too) with its bytes' sha256, and its listing."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    out = tmp_path_factory.mktemp("identified") / "o"
    res = CliRunner().invoke(app, ["identify", str(LOG10), "-c", "crazyflie", "--window", "8.67:38.67",
                                   "-o", str(out)])
    assert res.exit_code == 0, res.output
    return out


def test_identified_json_records_the_sha256_of_the_yaml_it_wrote(written):
    recorded = json.loads((written / "identified.json").read_text())["identified_yaml_sha256"]
    assert recorded == hashlib.sha256((written / "identified.yaml").read_bytes()).hexdigest()
    require_unedited(written)  # what quadctl wrote: written over without a word


def identify_folder(folder):
    """A folder as identify leaves it, made without a fit: identified.yaml and identified.json recording its
    sha256 (the refusal comes before the logs are read)."""
    from quadctl.artifacts.meta import IDENTIFIED_CONFIG_HEAD
    from quadctl.config import locate

    folder.mkdir()
    text = f"{IDENTIFIED_CONFIG_HEAD} log10: see identified.json.\n" + locate("crazyflie").text
    (folder / "identified.yaml").write_text(text)
    (folder / "identified.json").write_text(json.dumps({"identified_yaml_sha256": hashlib.sha256(
        text.encode()).hexdigest()}))
    (folder / ".quadctl").write_text("mark\n")
    return folder / "identified.yaml"


@pytest.mark.parametrize("edit", ["a changed value", "a comment added", "the record lost"])
def test_an_edited_identified_yaml_is_refused_in_one_line_and_the_folder_is_left_as_it_was(tmp_path, edit):
    out = tmp_path / "o"
    yaml_file = identify_folder(out)
    require_unedited(out)  # as written: identify would write over it
    if edit == "a changed value":
        yaml_file.write_text(yaml_file.read_text().replace("mass: 0.027", "mass: 0.0291"))
    elif edit == "a comment added":
        yaml_file.write_text(yaml_file.read_text() + "# flown with the new battery\n")
    else:  # identified.json of an earlier quadctl, with no sha256: the edits cannot be told, so none is lost
        (out / "identified.json").write_text("{}")
    before = snapshot(out)
    res = CliRunner().invoke(app, ["identify", str(LOG10), "-c", "crazyflie", "--window", "8.67:38.67",
                                   "-o", str(out)])
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    found = ("quadctl has no record of writing it (identified.json beside it records no sha256 of it)"
             if edit == "the record lost" else
             "changed since quadctl identify wrote it (its bytes differ from the sha256 identified.json records)")
    assert len(lines) == 1 and lines[0].startswith(f"quadctl: error: {yaml_file}: {found}"), lines
    assert f"mv {yaml_file} my-vehicle.yaml" in lines[0] and "(-o DIR)" in lines[0]
    assert lines[0].endswith("or pass --force to write over it")
    assert res.stdout == ""
    assert snapshot(out) == before


def test_force_writes_over_the_edits(written, tmp_path):
    out = tmp_path / "o"
    shutil.copytree(written, out)
    (out / "identified.yaml").write_text((out / "identified.yaml").read_text() + "# mine\n")
    res = CliRunner().invoke(app, ["identify", str(LOG10), "-c", "crazyflie", "--window", "8.67:38.67",
                                   "-o", str(out), "--force"])
    assert res.exit_code == 0, res.output
    assert (out / "identified.yaml").read_bytes() == (written / "identified.yaml").read_bytes()
    res = CliRunner().invoke(app, ["identify", str(LOG10), "-c", "crazyflie", "--window", "8.67:38.67",
                                   "-o", str(out)])  # its own file again: written over without --force
    assert res.exit_code == 0, res.output


def test_a_folder_without_an_identified_yaml_is_written(tmp_path):
    (tmp_path / "identified.json").write_text("{}")  # nothing to lose
    require_unedited(tmp_path)
    (tmp_path / "identified.yaml").write_text("name: mine\n")
    with pytest.raises(ArtifactError, match="records no sha256 of it"):
        require_unedited(tmp_path)
    require_unedited(tmp_path, force=True)
