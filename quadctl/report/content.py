"""The report's sections, built from a workspace's stage results (and nothing else).

Every table and sentence of a stage is :mod:`quadctl.present`'s, the ones the terminal shows:
a value read in the report is the one the stage command prints, from the same code.
"""

from __future__ import annotations

from quadctl import artifacts, pipeline, plots, run_summary
from quadctl.layout import INPUT_NAMES, unit_of
from quadctl.plots import png_bytes
from quadctl.plots.compare import QUANTITIES
from quadctl.present import cells, loops, stages
from quadctl.present import compare as words
from quadctl.present import design as shown_design
from quadctl.present import flight as shown_flight
from quadctl.present import mission as shown_mission
from quadctl.present import schedule as shown_schedule
from quadctl.report.document import Code, Figure, Items, Row, Section, Table, Text

TOP_DROPPED = stages.TOP_DROPPED
"""Dropped coupling terms listed, per matrix (A, B), largest first (as ``quadctl decouple``)."""
SIM_DPI, MARGINS_DPI = 90, 80
"""Figure resolutions: readable on screen and in print, the whole report under a few MB."""


def _text(sentence) -> Text:
    """A presented sentence (a fragment gets its capital and full stop), its verdict as the paragraph's kind."""
    return Text(sentence if str(sentence).endswith(".") else cells.sentence(sentence), getattr(sentence, "kind", ""))


def _png(fig, dpi: int) -> bytes:

    return png_bytes(fig, dpi)


# -- sections ---------------------------------------------------------------------------------


def configuration(ws, label: str) -> Section:
    given = ws.source_text if ws.source_text is not None else "# built in Python: no YAML text given\n"
    return Section("config", "Configuration", (
        Text(f"Config {ws.cfg.name!r} read from {label}; config_hash {ws.cfg.digest()} (sha256 of the "
             "validated config). Both texts are kept in the run folder: config.yaml and config.resolved.yaml."),
        Row((Code(f"As given ({label})", given),
             Code("As resolved: validated, every default filled in", ws.cfg.to_yaml()))),
    ))


def trim(ws) -> Section:
    return Section("trim", "Trim", (Text(stages.trim_sentence(ws.trim, ws.setup.velocity_ned)),
                                    Row(stages.trim_tables(ws.trim))))


def decoupling(ws) -> Section:
    dec = ws.decoupled
    blocks = [Text(stages.dropped_sentence(dec)), stages.subsystems_table(dec)]
    if dec.dropped:
        blocks.append(stages.dropped_table(dec))
    return Section("decoupling", "Decoupling", tuple(blocks))


def checks(ws) -> Section:
    report = ws.checks
    regulated = [s.name for s in ws.decoupled.regulated]
    blocks = [_text(stages.stabilizable_sentence(report.checks, regulated)),
              stages.checks_table(report.checks, regulated)]
    if report.rate is not None:
        if report.rate_warnings:
            blocks.append(Text(f"Rate warnings: the continuous design run at {report.rate:g} Hz.", "warning"))
            blocks.append(Items(tuple(stages.rate_warning(w, report.rate) for w in report.rate_warnings)))
        else:
            blocks.append(Text(f"Controller rate {report.rate:g} Hz: no rate warning (every loop it closes is "
                               "slow enough for it, or the design is discrete at that rate)."))
    if report.vehicle_loop is not None:
        loop = report.vehicle_loop
        said = stages.vehicle_loop_summary(loop)
        blocks.append(Text(said[0].upper() + said[1:] + ".", "ok" if loop.stable else "fail"))
    return Section("checks", "Checks", tuple(blocks))


def _plant_and_timing(ws) -> Text:
    return Text(shown_design.plant_and_timing(ws.setup))


def design(ws) -> Section:

    des = ws.design
    blocks = [_plant_and_timing(ws)]
    if des.rate:
        blocks.append(Text(shown_design.discrete_sentence(des)))
    blocks += [shown_design.weights_table(des), shown_design.gains_table(des), shown_design.gain_matrix_table(des),
               _text(shown_design.stability_sentence(des)), shown_design.damp_table(des)]
    kal = pipeline.estimator_of(ws.setup, ws.linear)
    if kal is not None:
        blocks += [b if isinstance(b, cells.Table) else Text(b) for b in shown_design.estimator_blocks(ws.setup, kal)]
    return Section("design", "Design", tuple(blocks))


def schedule(ws) -> Section:
    """The gain schedule the run flew (a config with ``schedule:``): the points, the envelope, the
    frozen-point checks, as ``quadctl schedule`` prints them, and its envelope figure."""

    sched = ws.schedule
    blocks = [shown_schedule.points_table(sched), Text(shown_schedule.envelope_sentence(sched))]
    failures = shown_schedule.failures_table(sched)
    if failures is not None:
        blocks.append(failures)
    blocks.append(_text(shown_schedule.checks_sentence(sched)))
    fig = plots.schedule_figure(sched, ws.setup.actuators, title=ws.setup.name)
    blocks.append(Figure("schedule", f"The gain schedule against {sched.variable}: the gains, the frozen-point "
                                     "loops' slowest pole and least damping, the trim attitude and thrust.",
                         _png(fig, SIM_DPI)))
    return Section("schedule", "Gain schedule", tuple(blocks))


def margins(ws) -> Section:

    margins = ws.margins
    if ws.setup.law == "pid":
        return _cascade_margins(ws, margins)
    rate = ws.setup.timing.rate
    discrete = ws.design.rate is not None
    blocks = [_plant_and_timing(ws),
              Text(f"Each regulated loop broken at its plant input, {loops.domain(rate)}, on the subsystem it was "
                   "designed on (design) and on the coupled model with the other loops closed (coupled)."),
              loops.classical_table(margins, rate), loops.disk_table(margins, discrete),
              Text(loops.guarantee_sentence(margins, discrete)), loops.delay_table(margins),
              _text(loops.closed_loop_sentence(ws.payloads["margins.json"]))]
    thin = loops.thin_sentence(margins, accepted="thin-margins" in ws.cfg.allow)
    if thin is not None:
        blocks.append(_text(cells.Mark(thin, "warning" if "thin-margins" in ws.cfg.allow else "fail")))
    unstable = loops.unstable_sentence(margins)
    if unstable:
        blocks.append(_text(unstable))
    notes = loops.notes(margins)
    if notes:
        blocks.append(Items(notes))
    shown = {m.loop: m for m in margins if m.model == "design"}
    shown.update({m.loop: m for m in margins if m.model == "coupled"})  # the coupled loop where there is one
    for m in shown.values():
        fig = plots.margins_figure(m, title=ws.setup.name)
        blocks.append(Figure(plots.margins_figure_name(m), f"Bode and Nyquist plots of the {m.loop} loop broken "
                                                           f"at {m.input} ({m.model} model).", _png(fig, MARGINS_DPI)))
    return Section("margins", "Margins", tuple(blocks))


def _cascade_margins(ws, margins) -> Section:
    """The margins of the PID cascade that flies (``controller.flies: pid``)."""

    payload = ws.payloads["margins.json"]
    blocks = [_plant_and_timing(ws), _text(loops.cascade_sentence(payload)),
              loops.classical_table(margins, payload["rate"]), loops.disk_table(margins, True),
              loops.delay_table(margins)]
    thin = loops.thin_sentence(margins, accepted="thin-margins" in ws.cfg.allow)
    if thin is not None:
        blocks.append(_text(cells.Mark(thin, "warning" if "thin-margins" in ws.cfg.allow else "fail")))
    for m in margins:
        fig = plots.margins_figure(m, title=ws.setup.name)
        blocks.append(Figure(plots.margins_figure_name(m), f"Bode and Nyquist plots of the {m.loop} cascade "
                                                           f"broken at {m.input}.", _png(fig, MARGINS_DPI)))
    return Section("margins", "Margins", tuple(blocks))


def comparison(ws) -> Section | None:
    """The laws side by side, when ``quadctl compare`` left compare.json (and its figures) in the run folder."""

    path = ws.path("compare.json")
    if not path.exists():
        return None
    data = artifacts.read_json(path)
    made_from, current = data["config_hash"], ws.cfg.digest()
    if made_from != current:
        return Section("compare", "Laws side by side", (_text(words.stale_sentence(made_from, current)),))
    blocks = [words.table(data), _text(words.disturbance_sentence(data))]
    gyro = words.gyro_filter_sentence(data)
    if gyro is not None:
        blocks.append(_text(gyro))
    free = words.free_position_sentence(ws.setup.regulated, [law["name"] for law in data["laws"]])
    if free:
        blocks.append(Text(free))
    for stem, label in QUANTITIES:
        png = artifacts.plot_path(ws.out, f"compare-{stem}")
        if png.exists():
            blocks.append(Figure(f"compare-{stem}", f"{label} against time, the laws overlaid.", png.read_bytes()))
    return Section("compare", "Laws side by side", tuple(blocks))


def simulation(ws) -> Section:

    flown = ws.simulation
    sim, metrics, fl = flown.sim, flown.metrics, flown.flight
    blocks = [Text(f"Fixed-step {shown_flight.integrator_name(sim)} of the full nonlinear closed loop: "
                   f"{shown_flight.step_text(sim)}, {sim.steps} "
                   f"steps to t = {float(sim.t[-1]):.4g} s, {sim.backend} loop.")]
    controller = shown_flight.controller_text(fl, sim)
    if controller:
        blocks.append(_text(controller))
    blocks.append(Text(f"{sim.status}: {sim.message}", "ok" if sim.status == "ok" else "fail"))
    u_trim = ws.linear.u_trim
    blocks += [shown_flight.metrics_table(metrics), shown_flight.inputs_table(metrics, u_trim, fl["peak_delta"]),
               Text(shown_flight.cost_sentence(metrics))]
    makers = plots.simulation_figure_makers(sim, ws.setup.partition, u_trim, title=ws.setup.name,
                                            actuators=ws.setup.actuators)
    for name, make in makers.items():
        if name in REFERENCE_FIGURES:  # the reference's section shows them
            continue
        fig = make()
        limits = ", actuator limits red" if ws.setup.actuators is not None else ""
        height = ", pD drawn as the height -pD" if name in ws.setup.partition and \
            "pD" in ws.setup.partition[name].states else ""
        what = f"the four inputs against time, trim dashed{limits}" if name == "inputs" else \
            "the wind the plant felt against time (NED, m/s)" if name == "wind" else \
            f"the {name} subsystem's states and their reference against time (angles in degrees{height})"
        blocks.append(Figure(f"sim-{name}", f"Simulation: {what}.", _png(fig, SIM_DPI)))
    return Section("simulation", "Simulation", tuple(blocks))


REFERENCE_FIGURES = ("path", "tracking")
"""The figures of a flown reference, shown in its section (:func:`mission`), not among the simulation's."""


def mission(ws) -> Section | None:
    """A flown reference: for a mission, its waypoints (reached at, closest approach) in a sentence and a
    table; the tracking error; the path with the waypoints marked, and the tracking error against
    time. None without ``simulation.reference``."""

    tracking = ws.simulation.flight.get("reference")
    if not tracking:
        return None
    blocks = []
    if "waypoints" in tracking:
        blocks += [_text(shown_mission.waypoints_sentence(tracking)), shown_mission.waypoints_table(tracking)]
    blocks.append(_text(shown_mission.tracking_sentence(tracking)))
    ignored = shown_mission.ignored_steps_text(run_summary.ignored_position_steps(ws.setup))
    if ignored:
        blocks.append(Text(f"{ignored}.", "warning"))  # a config key: no capital
    makers = plots.simulation_figure_makers(ws.simulation.sim, ws.setup.partition, title=ws.setup.name,
                                            tracking=tracking)
    marks = "the start ringed green, the end a blue dot"
    if "waypoints" in tracking:
        marks += (f", the waypoints numbered in the order flown (filled: reached within {tracking['tolerance']:g} m, "
                  "its circle dotted; a red cross: missed)")
    blocks.append(Figure("sim-path", f"The path flown (blue) over the reference (wide, grey): left, north against "
                                     f"east, {marks}; right, the altitude -pD against time"
                                     + (", each waypoint where it was reached." if "waypoints" in tracking else "."),
                         _png(makers["path"](), SIM_DPI)))
    blocks.append(Figure("sim-tracking", "The position tracking error p - p_ref against time: north, east and down, "
                                         "and its norm |p - p_ref| (m).", _png(makers["tracking"](), SIM_DPI)))
    return Section("mission", "Mission" if "waypoints" in tracking else "Reference", tuple(blocks))


def flight(ws) -> Section:

    fl = ws.simulation.flight
    blocks = []
    headroom = shown_flight.headroom_table(fl, ws.linear.u_trim)
    if headroom is not None:
        saturates = shown_flight.saturation_text(fl)
        blocks += [headroom, Text(cells.sentence(saturates), "warning") if saturates else
                   Text("No actuator is at a limit for long: the design flies within its actuators.", "ok")]
    else:
        peaks = ", ".join(f"{n} {cells.num(fl['peak_delta'][n])} {unit_of(n)}" for n in INPUT_NAMES)
        blocks.append(Text(f"No actuator limits in this config (motors: or limits:): the inputs are not clipped. "
                           f"Peak |u - u_trim|: {peaks}."))
    blocks.append(shown_flight.rms_table(fl))
    estimation = shown_flight.estimation_table(fl)
    if estimation is not None:
        blocks.append(estimation)
    if fl.get("wind"):
        blocks += [_text(shown_flight.wind_line(fl["wind"])), shown_flight.speeds_table(fl)]
    integral = shown_flight.integral_text(fl)
    if integral:
        blocks.append(_text(integral))
    if fl.get("plant"):
        blocks.append(Text("Simulated plant differs from the design model: " + ", ".join(
            f"{k} = {v}" for k, v in fl["plant"].items()) + "."))
    return Section("flight", "Flight numbers", tuple(blocks))


def software(meta: dict, command_line: str, out) -> Section:
    sw = meta.get("software", {})
    rows = [(name, version) for name, version in sw.items()]
    comp = meta.get("compiler")
    compiler = (f"{comp['path']}: {comp['version']}" if isinstance(comp, dict) else
                {"none": "none: the loop ran in CasADi's virtual machine",
                 "not used": "not used: no closed loop was simulated"}.get(comp, str(comp)))
    rows.append(("C compiler", compiler))
    return Section("software", "Software and command", (
        Table("software-table", "Software versions", ("component", "version"), tuple(rows), align="ll"),
        Items((f"Command line: {command_line}", f"Run folder: {out}", f"quadctl {meta.get('quadctl_version')}, "
               f"artifact format {meta.get('format_version')}, created {meta.get('created')} (UTC)")),
    ))
