"""quadctl writes over its own files only: a folder given by ``-o`` is taken when it is new, holds
nothing named as what quadctl writes, is marked as quadctl's, or is a run folder of a quadctl before the
mark (a file there carries quadctl's stamp); a folder whose ``config.yaml``, ``README.md``,
``quadctl_controller.c`` or ``sim.npz`` quadctl did not write is refused (one line, exit code 2) and left
byte for byte as it was."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from quadctl import artifacts, config
from quadctl.cli.app import app
from quadctl.errors import ArtifactError


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def contents(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_project_folder_whose_readme_and_makefile_an_export_would_replace_is_refused_untouched(tmp_path):
    (tmp_path / "README.md").write_text("my project\n")
    (tmp_path / "Makefile").write_text("all: mine\n")
    (tmp_path / "notes.txt").write_text("mine too\n")
    before = contents(tmp_path)
    res = invoke("export", "--to", "crazyflie", "-c", "crazyflie", "--setpoint", "velocity", "-o", tmp_path)
    assert res.exit_code == 2
    assert res.stderr == (f"quadctl: error: {tmp_path}: holds Makefile, README.md, which quadctl did not write and "
                          "would write over: give -o a new or empty folder, or one quadctl made\n")
    assert contents(tmp_path) == before  # nothing written, not even the mark


def test_a_users_own_config_yaml_is_not_written_over_by_the_config_quadctl_keeps(tmp_path):
    own = tmp_path / "config.yaml"
    own.write_text(config.load("hover").to_yaml().replace("mass: 0.068", "mass: 0.07"))
    before = contents(tmp_path)
    res = invoke("design", "-c", own, "-o", tmp_path, "--set", "simulation.duration=2")
    assert res.exit_code == 2 and "holds config.yaml, which quadctl did not write" in res.stderr
    assert contents(tmp_path) == before


def test_a_folder_with_only_other_files_is_taken_marked_and_its_files_kept(tmp_path):
    (tmp_path / "mine.yaml").write_text(config.load("hover").to_yaml())
    for _ in range(2):  # the second run finds the folder marked as quadctl's
        assert invoke("trim", "-c", tmp_path / "mine.yaml", "-o", tmp_path).exit_code == 0
    assert (tmp_path / artifacts.MARK_NAME).is_file() and (tmp_path / "trim.json").is_file()
    assert (tmp_path / "mine.yaml").read_text() == config.load("hover").to_yaml()


def test_a_run_folder_made_before_the_mark_is_taken_and_marked(tmp_path):
    out = tmp_path / "run"
    assert invoke("trim", "-c", "hover", "-o", out).exit_code == 0
    (out / artifacts.MARK_NAME).unlink()  # as an earlier quadctl left it: config.yaml beside its trim.json
    assert invoke("trim", "-c", "hover", "-o", out).exit_code == 0
    assert (out / artifacts.MARK_NAME).is_file()


@pytest.mark.parametrize("name", ["config.yaml", "README.md", "Makefile", "plots"])
def test_every_writer_is_held_to_the_claim(tmp_path, name):
    """The lock every writer takes (the workspace, the exports, a sweep's store) claims the folder first."""
    if name == "plots":  # a folder of the user's figures, one named as quadctl names one of its own
        (tmp_path / name).mkdir()
        (tmp_path / name / "roll.png").write_bytes(b"mine")
    else:
        (tmp_path / name).write_text("mine\n")
    with pytest.raises(ArtifactError, match=f"holds {name}, which quadctl did not write"):
        with artifacts.locked(tmp_path):
            pass
    assert not (tmp_path / artifacts.MARK_NAME).exists() and not (tmp_path / artifacts.LOCK_NAME).exists()
    with artifacts.locked(tmp_path / "new"):  # a new folder: taken and marked
        assert (tmp_path / "new" / artifacts.MARK_NAME).is_file()


def test_names_a_user_may_have_do_not_make_a_folder_quadctls(tmp_path):
    """A sweep.csv, a sweep.png of the user's own beside a README.md and a Makefile prove nothing: refused."""
    for name in ("README.md", "Makefile", "sweep.csv"):
        (tmp_path / name).write_text("mine\n")
    with pytest.raises(ArtifactError, match="holds Makefile, README.md, sweep.csv, which quadctl did not write"):
        with artifacts.locked(tmp_path):
            pass


def test_a_sweep_stopped_before_the_mark_is_taken_by_its_chunks(tmp_path):
    """An interrupted sweep of an earlier quadctl left only sweep.parts/chunk-*.json, with its provenance:
    --resume takes the folder. A chunk-named file without it proves nothing."""
    (tmp_path / "sweep.parts").mkdir()
    chunk = tmp_path / "sweep.parts" / "chunk-0000256.json"
    chunk.write_text("{}")
    with pytest.raises(ArtifactError, match="holds sweep.parts, which quadctl did not write"):
        with artifacts.locked(tmp_path):
            pass
    chunk.write_text('{"artifact": "sweep-chunk", "config_hash": "0", "rows": []}')
    with artifacts.locked(tmp_path):
        assert (tmp_path / artifacts.MARK_NAME).is_file()


@pytest.mark.parametrize("name, content", [
    ("quadctl_controller.c", b"/* my hand-tuned controller */\n"),
    ("sim.npz", b"PK\x03\x04 not even a zip"),
    ("identified.yaml", b"mass: 0.0291  # my scale\n"),
    ("compare.json", b'{"mine": true}'),
    ("trim.json", b'{"artifact": "trim"}'),  # half a stamp
])
def test_a_file_named_as_quadctls_but_not_stamped_by_it_is_not_written_over(tmp_path, name, content):
    """A name proves nothing: a user's own file named as quadctl names one of its own, in a folder quadctl
    never marked, blocks every writer, and the export is refused with the folder as it was."""
    (tmp_path / name).write_bytes(content)
    (tmp_path / "main.c").write_text("int main(void) { return 0; }\n")
    before = contents(tmp_path)
    res = invoke("export", "--to", "c", "-c", "crazyflie", "-o", tmp_path)
    assert res.exit_code == 2 and f"holds {name}, which quadctl did not write" in res.stderr
    assert contents(tmp_path) == before


@pytest.mark.parametrize("to, extra", [("c", []), ("mat", []), ("crazyflie", ["--setpoint", "velocity"])])
def test_an_export_folder_made_before_the_mark_is_taken_by_what_quadctl_stamped_in_it(tmp_path, to, extra):
    """An earlier quadctl's export left its files and no mark: the generated C's banner, the MAT file's
    provenance are the stamps that take it again (the Crazyflie app's README.md and Makefile are not)."""
    out = tmp_path / "export"
    assert invoke("export", "--to", to, "-c", "crazyflie", *extra, "-o", out).exit_code == 0
    (out / artifacts.MARK_NAME).unlink()
    res = invoke("export", "--to", to, "-c", "crazyflie", *extra, "-o", out)
    assert res.exit_code == 0, res.stderr
    assert (out / artifacts.MARK_NAME).is_file()


def test_every_generated_c_template_carries_the_stamp():
    """The claim knows generated C by its banner: every C template of the exports opens with it."""
    from importlib import resources

    from quadctl.artifacts.lock import GENERATED_BANNER, STAMP_HEAD

    templates = [p for p in resources.files("quadctl.export").joinpath("templates").rglob("*")
                 if p.name.endswith((".c", ".h"))]
    assert len(templates) >= 5
    for template in templates:
        assert GENERATED_BANNER in template.read_bytes()[:STAMP_HEAD], template.name


def test_a_writer_stopped_before_writing_leaves_no_mark_and_one_that_wrote_keeps_it(tmp_path):
    new, wrote = tmp_path / "new", tmp_path / "wrote"
    with pytest.raises(RuntimeError), artifacts.locked(new):
        raise RuntimeError("refused before any write")
    assert not (new / artifacts.MARK_NAME).exists()
    with pytest.raises(RuntimeError), artifacts.locked(wrote):
        artifacts.write_json(wrote / "trim.json", {"a": 1})
        raise RuntimeError("stopped after a write")
    assert (wrote / artifacts.MARK_NAME).is_file()


def test_identify_is_held_to_the_claim(tmp_path):
    """identify writes through the same lock: a figure of the user's named identify.png is not written over."""
    from _paths import ROOT

    (tmp_path / "identify.png").write_bytes(b"mine")
    logs = ROOT / "tests" / "data" / "crazyflie-flights"
    res = invoke("identify", logs / "log10", logs / "log15", "-c", "crazyflie", "--window", "8.67:38.67", "--window",
                 "15.755:50.755", "-o", tmp_path)
    assert res.exit_code == 2 and "holds identify.png, which quadctl did not write" in res.stderr
    assert contents(tmp_path) == {"identify.png": b"mine"}


def test_a_projects_own_subfolders_do_not_block_a_run(tmp_path):
    """A src/ or an empty plots/ of the user's holds nothing quadctl would write over: the folder is taken, and
    the files stay."""
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "main.c").write_text("int main(void) { return 0; }\n")
    (tmp_path / "plots").mkdir()
    assert invoke("trim", "-c", "hover", "-o", tmp_path).exit_code == 0
    assert (tmp_path / "src" / "main.c").is_file() and (tmp_path / "trim.json").is_file()


def test_an_identify_folder_from_before_the_mark_is_taken_by_its_yaml_header(tmp_path):
    """An earlier identify wrote identified.json without its provenance, and no mark: identified.yaml's
    opening line is quadctl's stamp; a YAML file of the user's with that name is not."""
    (tmp_path / "identified.json").write_text('{"values": {}}')
    (tmp_path / "identify.png").write_bytes(b"png")
    (tmp_path / "identified.yaml").write_text("name: mine\n")
    with pytest.raises(ArtifactError, match="which quadctl did not write"):
        with artifacts.locked(tmp_path):
            pass
    (tmp_path / "identified.yaml").write_text(f"{artifacts.meta.IDENTIFIED_CONFIG_HEAD} log10: see identified.json\n"
                                              "name: crazyflie-identified\n")
    with artifacts.locked(tmp_path):
        assert (tmp_path / artifacts.MARK_NAME).is_file()


def test_the_report_template_carries_the_stamp_the_claim_reads():
    """The claim knows a report by its generator: the template writes it as the claim reads it."""
    from importlib import resources
    from string import Template

    from quadctl.artifacts.lock import REPORT_GENERATOR, STAMP_HEAD

    template = resources.files("quadctl.report").joinpath("templates", "report.html").read_text(encoding="utf-8")
    page = Template(template).safe_substitute(generator="quadctl 1.2.3").encode()
    assert REPORT_GENERATOR in page[:STAMP_HEAD]
