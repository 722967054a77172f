"""`quadctl report`: one self-contained HTML page and a Markdown twin, holding the numbers the stage
commands print (read back from the artifacts), for every bundled config and for runs that stop."""

from __future__ import annotations

import base64
import html
import json
import re
from html.parser import HTMLParser
from pathlib import Path

import pytest
from _paths import ROOT
from typer.testing import CliRunner

from quadctl import artifacts, config, report, stages
from quadctl.cli.app import app
from quadctl.config import yamlio
from quadctl.workspace import Workspace

runner = CliRunner()
MAX_BYTES = 3_000_000
"""The HTML report stays under 3 MB (figures included) so that it can be mailed and handed in."""
VOID = {"meta", "img", "br", "hr", "link", "input", "source", "col", "area", "base", "wbr"}


class Page(HTMLParser):
    """The parts of the report a test reads: tables by id, <pre> texts, attributes, nesting errors."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.stack, self.errors, self.tags = [], [], []
        self.tables: dict[str, list[list[str]]] = {}
        self.srcs, self.hrefs, self.pres, self.text = [], [], [], []
        self._table = self._cell = self._pre = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.tags.append(tag)
        if tag not in VOID:
            self.stack.append(tag)
        if "src" in attrs:
            self.srcs.append(attrs["src"])
        if "href" in attrs:
            self.hrefs.append(attrs["href"])
        if tag == "table":
            self._table = self.tables.setdefault(attrs.get("id", f"table-{len(self.tables)}"), [])
        elif tag == "tr" and self._table is not None:
            self._table.append([])
        elif tag in ("td", "th"):
            self._cell = []
        elif tag == "pre":
            self._pre = []

    def handle_endtag(self, tag):
        if tag in VOID:
            return
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes <{self.stack[-1] if self.stack else None}>")
        else:
            self.stack.pop()
        if tag in ("td", "th") and self._cell is not None:
            self._table[-1].append("".join(self._cell).strip())
            self._cell = None
        elif tag == "table":
            self._table = None
        elif tag == "pre":
            self.pres.append("".join(self._pre))
            self._pre = None

    def handle_data(self, data):
        self.text.append(data)
        if self._cell is not None:
            self._cell.append(data)
        if self._pre is not None:
            self._pre.append(data)

    def row(self, table: str, *first: str) -> list[str]:
        """The row of ``table`` whose first cells are ``first``."""
        rows = [r for r in self.tables[table] if tuple(r[:len(first)]) == first]
        assert len(rows) == 1, (table, first, self.tables[table])
        return rows[0]

    def column(self, table: str, name: str, *first: str) -> str:
        return self.row(table, *first)[self.tables[table][0].index(name)]


def _parse(path: Path) -> Page:
    page = Page()
    page.feed(path.read_text(encoding="utf-8"))
    page.close()
    assert page.errors == [] and page.stack == [], (page.errors, page.stack)
    return page


def _self_contained(page: Page, text: str) -> None:
    assert page.srcs and all(s.startswith("data:image/png;base64,") for s in page.srcs)
    for src in page.srcs:
        assert base64.b64decode(src.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    assert all(h.startswith("#") for h in page.hrefs), page.hrefs  # links inside the page only
    assert not {"script", "link", "iframe", "object", "embed"} & set(page.tags)
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:|//|file:)|url\(|@import""", text)


def _artifact(out: Path, name: str) -> dict:
    return artifacts.decode_floats(json.loads((out / name).read_text()))  # "inf" back to a float


def _report(*args):
    return runner.invoke(app, ["report", *map(str, args)])


class _Reports(dict):
    """Bundled config name -> (run folder, result) of its `quadctl report -c NAME`, made when first asked for."""

    def __init__(self, tmp_path_factory):
        super().__init__()
        self._tmp = tmp_path_factory

    def __missing__(self, name: str):
        folder = self._tmp.mktemp(name)
        self[name] = (folder, _report("-c", name, "-o", folder))
        return self[name]


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """`quadctl report -c NAME` of the bundled configs (each made once for the module's tests)."""
    return _Reports(tmp_path_factory)


EVERY_RUN = ("forward", "crazyflie-wind", "square")
"""The bundled configs whose reports the default run checks (a continuous design, a sampled one in wind,
a mission); the others' repeat them with more configs and run with the slow tests."""


def _default_run(names, chosen=EVERY_RUN):
    """``names`` as parameters, those not ``chosen`` marked slow (their repeats run with the slow tests)."""
    return [name if name in chosen else pytest.param(name, marks=pytest.mark.slow) for name in names]


@pytest.mark.parametrize("name", _default_run(config.bundled_names()))
def test_report_of_every_bundled_config_holds_what_the_stages_print(name, reports):
    out, res = reports[name]
    assert res.exit_code == 0, res.output
    page_path = out / report.FOLDER / report.HTML
    assert f"report -> {page_path}" in res.stdout
    text = page_path.read_text(encoding="utf-8")
    assert len(text.encode()) < MAX_BYTES
    page = _parse(page_path)
    _self_contained(page, text)
    figures = sorted((out / report.FOLDER).glob("*.png"))
    assert len(page.srcs) == len(figures)  # a figure per subsystem, the inputs, a margins plot per loop
    regulated = [n for n, sub in config.load(name).partition().items() if sub.regulate]
    names = {f.name for f in figures}
    assert {f"sim-{n}.png" for n in regulated} | {"sim-inputs.png"} <= names
    # each loop's margins figure named as quadctl margins --plot names it: the loop, the model it is broken on
    assert all({f"margins-{n}-coupled.png", f"margins-{n}-design.png"} & names for n in regulated)

    trim = _artifact(out, "trim.json")  # `quadctl trim` prints the thrust with 6 digits
    assert page.column("trim-input-table", "value", "T") == f"{trim['u'][0]:.6g}"
    assert page.column("summary-table", "verdict", "simulate") == "ok"
    design = _artifact(out, "design.json")  # `quadctl design`: each subsystem's K with 4 digits
    for sub, d in design["subsystems"].items():
        k = [v for row in d["K"] for v in row]
        assert page.column("design-table", "K", sub) == "[" + ", ".join(f"{v:.4g}" for v in k) + "]"
    k_block = design["K_block"]  # a row per state, a column per input, as `quadctl design` prints it
    states = [row[0] for row in page.tables["kblock-table"][1:13]]
    assert page.tables["kblock-table"][0][1:] == ["T", "A", "E", "R"]
    assert [page.column("kblock-table", "T", s) for s in states] == [
        "·" if v == 0 else f"{v:.4g}" for v in k_block[0]]
    margins = _artifact(out, "margins.json")  # the table `quadctl margins` prints
    assert len(margins["loops"]) == len(page.tables["margins-table"]) - 1
    for m in margins["loops"]:
        loop = (f"{m['loop']} ({m['input']})", m["model"])
        pm = m["phase_margin_deg"]
        assert page.column("margins-table", "PM deg", *loop) == ("-" if pm is None else f"{pm:.3g}")
        gm = [("-" if v is None else f"{v:+.3g}") for v in (m["gain_margin_lower_db"], m["gain_margin_upper_db"])]
        assert page.column("margins-table", "GM dB", *loop) == " / ".join(gm)
        assert page.column("disk-table", "alpha", *loop) == f"{m['disk_margin_alpha']:.3g}"
        assert page.column("disk-table", "min|1+L|", *loop) == f"{m['min_return_difference']:.3g}"
    sim = _artifact(out, "sim.json")  # `quadctl simulate`'s metrics table
    for state, value in sim["metrics"]["peak_error"].items():
        settle = sim["metrics"]["settling_time"].get(state)
        assert page.column("metrics-table", "peak |error|", state) == f"{value:.4g}"
        shown = "noise" if state in sim["metrics"]["noise_limited"] else "-" if settle is None else f"{settle:.4g}"
        assert page.column("metrics-table", "settling (s)", state) == shown
    assert f"{sim['metrics']['cost']:.4g}" in "".join(page.text)
    for state, rms in sim["rms_error"].items():
        assert page.column("rms-table", "whole run", state) == f"{rms:.4g}"
    if sim["saturation"]:
        for i, actuator in enumerate(sim["saturation"]["actuators"]):
            limits = page.column("headroom-table", "limits", actuator)
            assert limits.startswith(f"{sim['saturation']['low'][i]:.4g} to {sim['saturation']['high'][i]:.4g}")
    assert {r[0]: r[1] for r in page.tables["software-table"][1:6]} == sim["software"]
    assert page.pres[0] == config.bundled(name).text  # the config as given, then as resolved
    assert page.pres[1] == config.load(name).to_yaml()
    described = next(line for line in page.pres[1].splitlines() if line.startswith("description:"))
    assert yamlio.load(described, "line")["description"] == config.load(name).description  # on one line
    assert f"Command line: quadctl report --config {name} --out {out}" in "".join(page.text)


@pytest.mark.parametrize("name", _default_run(config.bundled_names()))
def test_the_markdown_twin_shows_the_figures_beside_it(name, reports):
    out, _ = reports[name]
    folder = out / report.FOLDER
    md = (folder / report.MARKDOWN).read_text(encoding="utf-8")
    shown = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert shown and all((folder / f).is_file() for f in shown)
    assert sorted(shown) == sorted(p.name for p in folder.glob("*.png"))
    design = _artifact(out, "design.json")
    for sub, d in design["subsystems"].items():
        k = [v for row in d["K"] for v in row]
        gains = f" | {' '.join(d['inputs'])} | [" + ", ".join(f"{v:.4g}" for v in k) + "] |"
        assert any(line.startswith(f"| {sub} | ") and gains in line for line in md.splitlines()), sub
    assert "## Margins" in md and "## Flight numbers" in md and config.bundled(name).text.rstrip() in md


def test_the_terminal_and_the_report_show_the_same_rows(reports, monkeypatch):
    """The stage commands run on a report's run folder print the tables the report holds, cell for
    cell: one presenter (quadctl.present) makes both (a discrete LQI design with rotors and noise)."""
    from quadctl import present
    from quadctl.cli import render

    out, _ = reports["mambo-200hz"]
    page = _parse(out / report.FOLDER / report.HTML)
    printed = []
    show = render.show
    monkeypatch.setattr(render, "show", lambda *blocks: (printed.extend(blocks), show(*blocks)))
    for command in ("trim", "decouple", "check", "design", "margins", "simulate"):
        before = len(printed)
        res = runner.invoke(app, [command, "-c", "mambo-200hz", "-o", str(out)])
        assert res.exit_code == 0, res.output
        text = " ".join(res.stdout.split())
        for table in (t for t in printed[before:] if isinstance(t, present.Table)):
            assert table.id in page.tables, f"{command} prints {table.id}, which the report does not hold"
            assert " ".join(table.title.split()[:3]) in text  # printed, to this terminal
    tables = {t.id: t for t in printed if isinstance(t, present.Table)}
    assert set(tables) >= {"trim-state-table", "trim-input-table", "subsystems-table", "dropped-table",
                           "checks-table", "design-table", "kblock-table", "damp-table", "margins-table",
                           "disk-table", "metrics-table", "inputs-table", "headroom-table", "rms-table"}
    for name, table in tables.items():
        assert page.tables[name] == [[c.strip() for c in table.columns]] + [list(r) for r in table.rows], name
    sentences = " ".join(" ".join(page.text).split())
    for line in (b for b in printed if isinstance(b, str)):
        assert present.cells.sentence(" ".join(line.split())) in sentences or " ".join(line.split()) in sentences


def test_a_missions_report_shows_its_waypoints_and_tracking_as_the_terminal_does(reports, monkeypatch):
    """The square mission: the waypoint table and the tracking sentences `quadctl simulate` prints are
    the report's, cell for cell; the path figure is the mission's, under a caption that says what it
    shows, and sim.json's numbers are in the table."""
    from quadctl import present
    from quadctl.cli import render

    out, res = reports["square"]
    assert res.exit_code == 0, res.output
    page = _parse(out / report.FOLDER / report.HTML)
    printed = []
    show = render.show
    monkeypatch.setattr(render, "show", lambda *blocks: (printed.extend(blocks), show(*blocks)))
    res = runner.invoke(app, ["simulate", "-c", "square", "-o", str(out)])
    assert res.exit_code == 0, res.output
    table = next(b for b in printed if isinstance(b, present.Table) and b.id == "waypoints-table")
    assert page.tables["waypoints-table"] == [list(table.columns)] + [list(r) for r in table.rows]
    sentences = " ".join(" ".join(page.text).split())
    lines = [b for b in printed if isinstance(b, str) and str(b).startswith(("waypoints:", "tracking error"))]
    assert len(lines) == 2 and all(present.cells.sentence(line) in sentences for line in lines), lines
    tracking = _artifact(out, "sim.json")["reference"]
    err = tracking["position_error"]
    assert f"rms {err['rms']:.3g} m, peak {err['peak']:.3g} m, final {err['final']:.3g} m" in lines[1]
    for i, w in enumerate(tracking["waypoints"]):
        assert page.column("waypoints-table", "reached at (s)", f"waypoints[{i}]") == f"{w['reached']:.4g}"
        assert page.column("waypoints-table", "closest approach (m)", f"waypoints[{i}]") == (
            f"{w['closest']:.3g} at {w['closest_at']:.4g} s")
    md = (out / report.FOLDER / report.MARKDOWN).read_text(encoding="utf-8")
    assert "## Mission" in md and "subsystem's states" not in md.split("## Mission")[1].split("## Flight")[0]
    assert re.search(r"!\[The path flown \(blue\) over the reference \(wide, grey\): left, north against east, "
                     r"the start ringed green, the end a blue dot, the waypoints numbered in the order flown "
                     r"\(filled: reached within 0\.05 m, .*\]\(sim-path\.png\)", md)
    assert re.search(r"!\[The position tracking error p - p_ref against time: .*\]\(sim-tracking\.png\)", md)
    assert "the path subsystem" not in md and "the tracking subsystem" not in md


UNSTABILIZABLE = """name: swapped
subsystems:  # A drives pitch and E roll: neither input reaches its subsystem's angle
  altitude: {states: [pD, w], inputs: [T]}
  roll:     {states: [v, phi, p], inputs: [E]}
  pitch:    {states: [u, theta, q], inputs: [A]}
  yaw:      {states: [psi, r], inputs: [R]}
  guidance: {states: [pN, pE], inputs: [u, psi], regulate: false}
lqr:
  altitude: {Q: [50, 1], R: [1]}
  roll:     {Q: [1, 50, 1], R: [1]}
  pitch:    {Q: [1, 50, 1], R: [1]}
  yaw:      {Q: [50, 1], R: [1]}
"""


def test_a_failed_check_exits_1_after_reporting_what_was_computed(tmp_path):
    path = tmp_path / "swapped.yaml"
    path.write_text(UNSTABILIZABLE)
    res = _report("-c", path, "-o", tmp_path / "run")
    assert res.exit_code == 1
    why = "subsystem pitch is not stabilizable: mode 0 in q; subsystem roll is not stabilizable: mode 0 in p"
    assert f"quadctl: check failed: check: {why}" in res.stderr
    page = _parse(tmp_path / "run" / report.FOLDER / report.HTML)
    text = "".join(page.text)
    assert f"Stopped at check: {why}. Not run: design, margins, simulate." in text
    assert [r[1] for r in page.tables["summary-table"][1:]] == ["ok"] * 3 + ["failed"] + ["not run"] * 3
    assert page.column("checks-table", "stabilizable", "roll") == "no"
    assert page.column("checks-table", "staircase", "roll") == "0, 3"  # E, the pitch torque, reaches no roll state
    assert "design-table" not in page.tables and "metrics-table" not in page.tables and not page.srcs
    assert page.pres[0] == UNSTABILIZABLE


def test_an_error_in_a_stage_keeps_its_exit_code_and_still_reports(tmp_path):
    path = tmp_path / "sinking.yaml"  # a 10 m/s climb whose rotor drag outgrows the thrust
    weights = "lqr:" + UNSTABILIZABLE.split("lqr:")[1]
    path.write_text("name: sinking\nvehicle: {mass: 0.068, inertia: [6.9e-5, 7.75e-5, 1.5e-4], "
                    "drag: [0.22, 0.22, 0.5]}\ntrim: {velocity_ned: [0, 0, -10]}\n" + weights)
    res = _report("-c", path, "-o", tmp_path / "run")
    assert res.exit_code == 2  # bad input, as every command says it
    assert re.search(r"quadctl: error: .*sinking\.yaml: no equilibrium at velocity_ned \[0, 0, -10\]", res.stderr)
    page = _parse(tmp_path / "run" / report.FOLDER / report.HTML)
    assert page.column("summary-table", "verdict", "trim") == "failed"
    assert "Stopped at trim: no equilibrium" in "".join(page.text)


def test_the_report_reuses_fresh_artifacts_and_drops_stale_figures(tmp_path, reports):
    """A figure the earlier report showed (its report.md names it) and this one does not goes; a
    .png of the user's in the same folder stays."""
    import shutil

    cfg = config.load("forward")
    shutil.copytree(reports["forward"][0], tmp_path, dirs_exist_ok=True)  # a report of every stage
    (tmp_path / report.FOLDER / "margins-old.png").write_bytes(b"stale")
    with open(tmp_path / report.FOLDER / report.MARKDOWN, "a", encoding="utf-8") as fh:
        fh.write("\n![an earlier report's figure](margins-old.png)\n")
    (tmp_path / report.FOLDER / "mine.png").write_bytes(b"the user's")
    again = Workspace(cfg, tmp_path)
    outcome = stages.run_stages(again)
    assert outcome.done == stages.NAMES and outcome.stopped_at is None
    assert {p.name for p in again.reused} >= {"trim.json", "linear.npz"}
    report.write(report.build(again, outcome), tmp_path / report.FOLDER)
    assert not (tmp_path / report.FOLDER / "margins-old.png").exists()
    assert (tmp_path / report.FOLDER / "mine.png").read_bytes() == b"the user's"
    page = _parse(tmp_path / report.FOLDER / report.HTML)
    assert "Command line: (library call)" in "".join(page.text)
    assert html.unescape(page.pres[0]).startswith("# built in Python")  # no YAML text was given


def test_help_lists_the_report():
    res = runner.invoke(app, ["--help"])
    assert res.exit_code == 0 and "report" in res.output
    res = runner.invoke(app, ["report", "--help"])
    assert "report.html" in res.output and "--config" in res.output


def test_report_stops_where_run_does_on_a_loop_unstable_at_its_rate(tmp_path):
    """The report's gains at 200 Hz: `run` stops at its check stage; `report` gives the same verdict."""
    config_path = ROOT / "docs" / "configs" / "report-at-200hz.yaml"
    verdict = "check: sampled at 200 Hz the continuous design's loop(s) roll, pitch, yaw, coupled are UNSTABLE"
    ran = runner.invoke(app, ["run", "-c", str(config_path), "-o", str(tmp_path / "run")])
    reported = _report("-c", config_path, "-o", tmp_path / "report")
    assert ran.exit_code == reported.exit_code == 1
    for res in (ran, reported):
        assert f"quadctl: check failed: {verdict}" in " ".join(res.stderr.split()), res.stderr
    text = "".join(_parse(tmp_path / "report" / report.FOLDER / report.HTML).text)
    assert "Stopped at check: sampled at 200 Hz" in " ".join(text.split())


@pytest.mark.parametrize("path, lag, delay", [
    ("docs/configs/mambo-rotor-lag-include.yaml", "Rotor time constant 30 ms (motors.time_constant), included in the "
                                                  "design (controller.rotor_lag: include", "no delay"),
    pytest.param("docs/configs/mambo-rotor-lag.yaml", "Rotor time constant 30 ms (motors.time_constant), ignored by "
                 "the design (controller.rotor_lag: ignore)", "no delay", marks=pytest.mark.slow),
    ("docs/configs/mambo-delay.yaml", "Rotors: instantaneous", "delay 1 sample (5 ms) from measurement to actuation"),
])
def test_the_report_shows_the_rotor_lag_the_delay_and_the_delay_margins(path, lag, delay, tmp_path):
    res = _report("-c", ROOT / path, "-o", tmp_path)
    thin = "ignored" in lag  # the lag the design ignores leaves 17.4 deg of phase margin: a failed check
    assert res.exit_code == (1 if thin else 0), res.output
    assert ("check failed: margins: thin margins" in " ".join(res.output.split())) == thin
    page = _parse(tmp_path / report.FOLDER / report.HTML)
    text = " ".join(" ".join(page.text).split())
    assert lag in text and delay in text
    margins = _artifact(tmp_path, "margins.json")
    for m in margins["loops"]:
        loop = (f"{m['loop']} ({m['input']})", m["model"])
        dm = m["delay_margin"]
        assert page.column("delay-margin-table", "delay margin ms", *loop) == f"{dm['s'] * 1e3:.3g}"
        assert page.column("delay-margin-table", "samples", *loop) == f"{dm['samples']:.3g}"
        assert page.column("delay-margin-table", "configured delay (samples)", *loop) == str(m["delay_samples"])
    if "include" in path:
        design = _artifact(tmp_path, "design.json")
        assert design["rotor_lag"]["mode"] == "include" and page.tables["design-table"][0][3:6] == ["K", "Ki", "Kv"]


def _lqg_in_wind(tmp_path: Path) -> Path:
    """crazyflie-wind with a 20 ms rotor lag (ignored), noise and a Kalman filter on imu + mocap."""
    import yaml

    data = config.load("crazyflie-wind").model_dump(mode="json")
    data.update(name="cf-lqg", estimator={"measure": ["imu", "mocap"]}, allow=["thin-margins"])
    data["motors"]["time_constant"] = 0.02
    data["simulation"].update(duration=3.0, noise={"seed": 3, "force": [0.002] * 3, "torque": [1e-5] * 3, "sensor": {
        "pN": 0.01, "pE": 0.01, "pD": 0.01, "phi": 0.002, "theta": 0.002, "psi": 0.005, "p": 0.005, "q": 0.005,
        "r": 0.005}})
    path = tmp_path / "cf-lqg.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_the_report_shows_the_filter_the_wind_and_the_loop_with_the_lag(tmp_path):
    res = _report("-c", _lqg_in_wind(tmp_path), "-o", tmp_path / "run")
    assert res.exit_code == 0, res.output
    out = tmp_path / "run"
    page = _parse(out / report.FOLDER / report.HTML)
    text = " ".join(" ".join(page.text).split())
    closed = _artifact(out, "checks.json")["closed_loop"]
    assert (f"With the rotors' 20 ms lag (ignored by the design) and the Kalman filter included (plant and "
            f"estimator) the design's closed loop stays stable: least "
            f"damping {closed['least_damping']:.3g} ({closed['design_least_damping']:.3g} as designed).") in text
    assert "The law closes through a steady-state Kalman filter (LQG), the discrete filter at 500 Hz" in text
    design = _artifact(out, "design.json")["estimator"]
    assert [row[0] for row in page.tables["estimator-table"][1:]] == design["measured"]
    sim = _artifact(out, "sim.json")
    est, wind = sim["estimation"], sim["wind"]
    for state in ("pN", "phi", "w"):
        assert page.column("estimation-table", "RMS whole run", state) == f"{est['rms_error'][state]:.4g}"
        assert page.column("estimation-table", "predicted std", state) == f"{est['predicted_std'][state]:.4g}"
    assert page.column("speeds-table", "max", "airspeed") == f"{wind['airspeed']['max']:.4g}"
    assert page.column("speeds-table", "RMS", "ground speed") == f"{wind['ground_speed']['rms']:.4g}"
    assert "Wind: steady [0, 9.7, 0] m/s NED, 1 gust, Dryden turbulence" in text


def test_report_stops_where_run_does_when_the_lag_destabilizes_the_design(tmp_path):
    import yaml

    data = config.load("mambo-200hz").model_dump(mode="json")
    data["motors"]["time_constant"] = 0.03
    data["controller"].update(rotor_lag="ignore", delay={"samples": 2})
    path = tmp_path / "lag.yaml"
    path.write_text(yaml.safe_dump(data))
    ran = runner.invoke(app, ["run", "-c", str(path), "-o", str(tmp_path / "run")])
    reported = _report("-c", path, "-o", tmp_path / "report")
    assert ran.exit_code == reported.exit_code == 1
    verdict = "check: with the rotors' 30 ms lag (ignored by the design) and 2 samples of delay the design's closed"
    for res in (ran, reported):
        assert f"quadctl: check failed: {verdict}" in " ".join(res.stderr.split()), res.stderr


@pytest.mark.parametrize("name", _default_run([n for n in config.bundled_names()
                                               if config.load(n).schedule is not None], chosen=("schedule",)))
def test_the_report_shows_the_gain_schedule_the_run_flew(name, reports):
    """A config with schedule: reports its points as `quadctl schedule` prints them (schedule.json's
    gains, 4 digits), its frozen-point verdict and its envelope figure."""
    out, res = reports[name]
    assert res.exit_code == 0, res.output
    page = _parse(out / report.FOLDER / report.HTML)
    sched = _artifact(out, "schedule.json")
    header = page.tables["schedule-table"][0]
    for p in sched["points"]:
        row = page.row("schedule-table", f"{p['value']:.4g}")
        assert row[header.index("K[T,pD]")] == f"{p['K'][0][2]:.4g}"
        assert row[header.index("stable")] == ("yes" if p["stable"] else "no")
    assert any("Frozen-point checks" in t for t in page.text)
    assert (out / report.FOLDER / "schedule.png").is_file()


def test_the_reports_text_wraps_a_word_longer_than_a_phones_page():
    """The Configuration section's config_hash is 64 hex digits with no break: without a rule that breaks it,
    the paragraph stuck out of a 420-pixel-wide page and the whole report scrolled sideways on a phone
    (the tables scroll in their own boxes)."""
    import re
    from pathlib import Path

    import quadctl.report

    css = (Path(quadctl.report.__file__).parent / "templates" / "report.css").read_text(encoding="utf-8")
    paragraph_rules = [body for sels, body in re.findall(r"([^{}@]+)\{([^}]*)\}", css)
                       if "p" in (sel.strip() for sel in sels.split(","))]
    assert any(re.search(r"overflow-wrap:\s*(break-word|anywhere)", body) for body in paragraph_rules)
