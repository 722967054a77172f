"""Artifact-backed stages: run a stage, write its artifact, reuse upstream artifacts.

A :class:`Workspace` couples a config to a run directory. Each stage writes its artifact
atomically; an upstream artifact is reused only when its ``config_hash`` and quadctl
version match, otherwise it is recomputed and rewritten (never a stale result).
"""

from __future__ import annotations

from functools import cached_property
from pathlib import Path

import numpy as np

from quadctl import artifacts, pipeline
from quadctl.analysis import Checks
from quadctl.config import Config
from quadctl.decouple import Decoupled
from quadctl.discrete import realizable_frequency
from quadctl.layout import INPUT_NAMES, INPUT_UNITS, STATE_NAMES, STATE_UNITS
from quadctl.linearize import LinearModel
from quadctl.lqr import Design
from quadctl.metrics import summarize
from quadctl.simulate import SimResult
from quadctl.trim import Trim

TRIM, LINEAR, SUBSYSTEMS, CHECKS, DESIGN, SIM_NPZ, SIM_JSON = (
    "trim.json", "linear.npz", "subsystems.json", "checks.json", "design.json", "sim.npz", "sim.json")
MARGINS, DESIGN_FULL = "margins.json", "design_full.json"
_c = artifacts.complex_values  # eigenvalues: [re, im] pairs in JSON even when all are real


def default_out(cfg: Config) -> Path:
    """``runs/<config name>``."""
    return Path("runs") / cfg.name


class Workspace:
    """Stages of one config in one run directory.

    Parameters
    ----------
    cfg : Config
    out : path, optional
        Run directory (default ``runs/<config name>``).
    fresh : bool
        Recompute every stage, ignoring existing artifacts.
    """

    def __init__(self, cfg: Config, out: Path | str | None = None, *, fresh: bool = False):
        self.cfg = cfg
        self.out = Path(out) if out is not None else default_out(cfg)
        self.fresh = fresh
        self.written: list[Path] = []
        self.reused: list[Path] = []
        self.payloads: dict[str, dict] = {}
        """JSON artifacts written in this session, by file name (what ``--json`` prints)."""
        artifacts.remove_stale_temporaries(self.out)

    def path(self, name: str) -> Path:
        return self.out / name

    def _reusable(self, name: str) -> bool:
        if self.fresh:
            return False
        ok = artifacts.is_fresh(self.path(name), self.cfg)
        if ok:
            self.reused.append(self.path(name))
            if name.endswith(".json"):  # --json prints the artifact, reused or new
                self.payloads[name] = artifacts.read_json(self.path(name))
        return ok

    def _meta(self, kind: str) -> dict:
        return artifacts.metadata(self.cfg, kind)

    def _write_json(self, name: str, kind: str, payload: dict) -> None:
        full = artifacts.jsonable({**self._meta(kind), **payload})
        self.payloads[name] = full
        self.written.append(artifacts.write_json(self.path(name), full))

    # -- stages ---------------------------------------------------------------------------

    @cached_property
    def trim(self) -> Trim:
        if self._reusable(TRIM):
            data = artifacts.read_json(self.path(TRIM))
            return Trim(x=np.array(data["x"]), u=np.array(data["u"]), xdot=np.array(data["xdot"]),
                        residual=float(data["residual"]), iterations=int(data["iterations"]))
        trim = pipeline.trim_of(self.cfg)
        self._write_json(TRIM, "trim", {
            "x": trim.x, "u": trim.u, "xdot": trim.xdot, "residual": trim.residual,
            "iterations": trim.iterations, "velocity_ned": self.cfg.trim.velocity_ned,
            "state": dict(zip(STATE_NAMES, trim.x)), "input": dict(zip(INPUT_NAMES, trim.u)),
            "units": {**STATE_UNITS, **INPUT_UNITS}})
        return trim

    @cached_property
    def linear(self) -> LinearModel:
        if self._reusable(LINEAR):
            arrays, _ = artifacts.read_npz(self.path(LINEAR))
            return LinearModel(A=arrays["A"], B=arrays["B"], x_trim=arrays["x_trim"],
                               u_trim=arrays["u_trim"])
        linear = pipeline.linear_of(self.cfg, self.trim)
        self.written.append(artifacts.write_npz(self.path(LINEAR), {
            "A": linear.A, "B": linear.B, "x_trim": linear.x_trim, "u_trim": linear.u_trim,
            "x_rate": pipeline.reference_rate(self.trim),
            "state_names": np.array(STATE_NAMES), "input_names": np.array(INPUT_NAMES)},
            self._meta("linear")))
        return linear

    @cached_property
    def decoupled(self) -> Decoupled:
        dec = pipeline.decoupled_of(self.cfg, self.linear)
        self._write_json(SUBSYSTEMS, "subsystems", {
            "subsystems": {s.name: {"states": s.states, "inputs": s.inputs, "A": s.A, "B": s.B,
                                    "C": s.C, "regulated": s.regulated} for s in dec.subsystems},
            "dropped": [{"name": d.name, "matrix": d.matrix, "row": d.row, "column": d.column,
                         "value": d.value, "relative": d.relative, "unit": d.unit}
                        for d in dec.dropped]})
        return dec

    @cached_property
    def checks(self) -> dict[str, Checks]:
        checks = pipeline.checks_of(self.decoupled, self.linear)
        regulated = {s.name for s in self.decoupled.regulated}
        self.rate_warnings = self._rate_warnings(checks, regulated)
        rate = self.cfg.controller.rate
        self._write_json(CHECKS, "checks", {
            "subsystems": {n: _checks_payload(c, n in regulated) for n, c in checks.items() if n != "full"},
            "full": _checks_payload(checks["full"], True),
            "rate": None if rate is None else {
                "rate": rate, "design": self.cfg.controller.design,
                "realizable_frequency": realizable_frequency(rate),
                "warnings": [{"loop": w.loop, "pole": w.pole, "factor": w.factor,
                              "sampled_spectral_radius": w.sampled_radius, "sampled_stable": w.sampled_stable,
                              "message": w.message(rate)} for w in self.rate_warnings]}})
        return checks

    def _rate_warnings(self, checks, regulated) -> list:
        """A continuous design run at ``controller.rate``: the loops that rate cannot realize."""
        ctl = self.cfg.controller
        if ctl.rate is None or ctl.design != "continuous" or any(
                not checks[n].stabilizable for n in regulated):
            return []
        return pipeline.rate_warnings_of(self.cfg, self.decoupled, self.linear, ctl.rate)

    @cached_property
    def design(self) -> Design:
        des = pipeline.design_of(self.cfg, self.decoupled, self.linear)
        self._write_json(DESIGN, "design", {
            "subsystems": {s.name: {"states": s.states, "inputs": s.inputs, "Q": s.Q, "R": s.R,
                                    "K": s.K, "P": s.P, "closed_loop_eigenvalues": _c(s.eigenvalues),
                                    "riccati_residual": s.residual} for s in des.subsystems},
            "K_block": des.K_block, "Q_block": des.Q_block, "R_block": des.R_block,
            "full_closed_loop_eigenvalues": _c(des.full_eigenvalues),
            "marginal_states": des.marginal_states, "stable": des.stable,
            **_flight_design_payload(des)})
        return des

    @cached_property
    def gain(self) -> np.ndarray:
        """K_block: from design.json when it is fresh, else from a new design."""
        return self.gains[0]

    @cached_property
    def gains(self) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
        """(K_block, Ki_block, integral_states): from design.json when it is fresh, else a new design."""
        if self._reusable(DESIGN):
            data = artifacts.read_json(self.path(DESIGN))
            ints = tuple(data.get("integral_states", ()))
            Ki = np.array(data.get("Ki_block", [[]] * len(INPUT_NAMES)), dtype=float)
            return (np.array(data["K_block"], dtype=float), Ki.reshape(len(INPUT_NAMES), len(ints)), ints)
        des = self.design
        return des.K_block, des.Ki_block, des.integral_states

    @cached_property
    def margins(self) -> list:
        """Margins of every regulated loop (design model and coupled); writes margins.json."""
        from quadctl import margins

        des, ctl, linear = self.design, self.cfg.controller, self.linear
        emulated = ctl.rate if ctl.rate is not None and des.rate is None else None
        result = margins.all_margins(
            des, self.decoupled, linear.A, linear.B, emulated_rate=emulated,
            actuators=pipeline.actuators_of_config(self.cfg), u_trim=linear.u_trim,
            initial_demand=pipeline.initial_demand(self.cfg, linear, des))
        self._write_json(MARGINS, "margins", {
            "rate": ctl.rate, "design": "discrete" if des.rate else "continuous",
            "guarantee": {"gain_margin_db": list(margins.LQR_GAIN_MARGIN_DB),
                          "phase_margin_deg": margins.LQR_PHASE_MARGIN_DEG},
            "loops": [m.as_dict() for m in result]})
        return result

    @cached_property
    def full(self):
        """``design --full``: (FullDesign, comparison); writes design_full.json."""
        fd, comparison = pipeline.compare_full(self.cfg, self.linear, self.trim, self.design)
        self._write_json(DESIGN_FULL, "design_full", {
            "K": fd.K, "Ki": fd.Ki, "integral_states": fd.integral_states, "states": fd.states,
            "left_out": fd.left_out, "Q": fd.Q, "R": fd.R, "P": fd.P,
            "closed_loop_eigenvalues": _c(fd.eigenvalues), "stable": fd.stable, "rate": fd.rate,
            "riccati_residual": fd.residual,
            "position": ("left out: " + ", ".join(fd.left_out) + " (no weight, no dynamics); "
                         if fd.left_out else "") + "weighted positions regulated about the moving reference",
            "comparison": comparison})
        return fd, comparison

    @cached_property
    def simulation(self) -> SimResult:
        linear = self.linear
        K, Ki, ints = self.gains
        loop = pipeline.closed_loop_of(self.cfg, linear, K, pipeline.reference_rate(self.trim),
                                       Ki=Ki, integral_states=ints)
        sim = pipeline.simulation_of(self.cfg, loop)
        self.flight = pipeline.flight_summary(self.cfg, loop, sim)
        regulated = [s for sub in self.cfg.partition().values() if sub.regulate for s in sub.states]
        Q, R = pipeline.weights_block(self.cfg)
        summary = summarize(sim, linear.u_trim, Q, R, regulated)
        meta = self._meta("simulation")
        self.written.append(artifacts.write_npz(self.path(SIM_NPZ), {
            "t": sim.t, "x": sim.x, "u": sim.u, "x_ref": sim.x_ref, "dt": np.array(sim.dt),
            "stride": np.array(sim.stride),
            "status": np.array(sim.status), "state_names": np.array(STATE_NAMES),
            "input_names": np.array(INPUT_NAMES), "z": sim.z,
            "integral_states": np.array(loop.integral_states, dtype=str)}, meta))
        self._write_json(SIM_JSON, "simulation", {
            "status": sim.status, "message": sim.message, "dt": sim.dt, "steps": sim.steps,
            "stride": sim.stride, "samples": len(sim.t),
            "duration": float(sim.t[-1]), "backend": sim.backend,
            "dt_auto": sim.plan.auto, "max_stable_dt": sim.plan.max_stable_dt,
            "fastest_eigenvalue": sim.plan.fastest_eigenvalue,
            "fastest_subsystem": sim.plan.fastest_owner,
            "metrics": summary, "units": {**STATE_UNITS, **INPUT_UNITS}, **self.flight})
        self.metrics = summary
        return sim


def _flight_design_payload(des: Design) -> dict:
    """design.json keys of issue 5: rate, integrators, discrete eigenvalues."""
    return {
        "rate": des.rate, "discrete": des.rate is not None,
        "Ki_block": des.Ki_block, "integral_states": des.integral_states,
        "full_closed_loop_eigenvalues_z": _c(des.full_eigenvalues_z),
        "subsystem_integrals": {s.name: {"integral": s.integral, "Ki": s.Ki,
                                         "closed_loop_eigenvalues_z": _c(s.eigenvalues_z)}
                                for s in des.subsystems},
    }


def _checks_payload(c: Checks, regulated: bool) -> dict:
    return {
        "n_states": c.n, "regulated": regulated,
        "ctrb_rank": c.ctrb.rank, "obsv_rank": c.obsv.rank,
        "ctrb_singular_values": c.ctrb.singular_values, "obsv_singular_values": c.obsv.singular_values,
        "tolerance": {"ctrb": c.ctrb.tolerance, "obsv": c.obsv.tolerance,
                      "rule": "singular values > max(shape) * eps * sigma_max"},
        "controllable": c.controllable, "observable": c.observable,
        "stabilizable": c.stabilizable, "detectable": c.detectable,
        "pbh": [{"eigenvalue": m.eigenvalue, "ctrb_rank": m.rank, "controllable": m.passed,
                 "states": m.states} for m in c.pbh_ctrb],
        "pbh_obsv": [{"eigenvalue": m.eigenvalue, "obsv_rank": m.rank, "observable": m.passed,
                      "states": m.states} for m in c.pbh_obsv],
    }
