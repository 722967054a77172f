"""Artifact-backed stages: run a stage, write its artifact, reuse upstream artifacts.

A :class:`Workspace` couples a config to a run directory. Each stage writes its artifact
atomically; an upstream artifact is reused only when its ``config_hash`` and quadctl
version match, otherwise it is recomputed and rewritten (never a stale result). The first
write of a session also writes the config as given (``config.yaml``) and as resolved
(``config.resolved.yaml``), so a run directory always says what made it.
"""

from __future__ import annotations

import contextlib
import weakref
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from quadctl import __version__, artifacts, pipeline
from quadctl.analysis import Checks, check
from quadctl.config import Config
from quadctl.decouple import Decoupled
from quadctl.errors import DesignError
from quadctl.layout import INPUT_NAMES, INPUT_UNITS, N_INPUTS, STATE_NAMES, STATE_UNITS
from quadctl.linearize import LinearModel
from quadctl.lqr import Design
from quadctl.lqr.discrete import RateWarning, realizable_frequency, unstable_when_sampled
from quadctl.messages import eig_text
from quadctl.metrics import summarize
from quadctl.problem import setup_of
from quadctl.sim import schedule
from quadctl.sim.run import ClosedLoop, SimResult
from quadctl.trim import Trim

TRIM, LINEAR, SUBSYSTEMS, CHECKS, DESIGN, SIM_NPZ, SIM_JSON = (
    "trim.json", "linear.npz", "subsystems.json", "checks.json", "design.json", "sim.npz", "sim.json")
MARGINS, DESIGN_FULL = "margins.json", "design_full.json"
CONFIG_GIVEN, CONFIG_RESOLVED = "config.yaml", "config.resolved.yaml"


@dataclass(frozen=True)
class CheckReport:
    """``check``'s result: the rank checks per subsystem (and ``"full"``, and ``"estimator"`` for the
    measured set); for a continuous design run at a rate, the loops that rate cannot realize; with
    rotor lag or delay, the loop the vehicle flies."""

    checks: dict[str, Checks]
    regulated: tuple[str, ...]
    """The regulated subsystems (those whose stabilizability the verdict needs)."""
    rate: float | None
    rate_warnings: tuple[RateWarning, ...]
    vehicle_loop: pipeline.VehicleLoop | None = None
    """With rotor lag or delay configured: the design's loop flown with them (else None)."""
    undetectable: str | None = None
    """Why the estimator's measured set cannot estimate the state (else None)."""

    def __getitem__(self, name: str) -> Checks:
        return self.checks[name]

    def failures(self) -> list[str]:
        """Each reason the check stage fails, one line each (empty when it passes): a regulated
        subsystem not stabilizable, a measured set that leaves a mode that is not stable unobservable,
        a continuous design unstable sampled at the controller rate, a loop the rotors' lag and the
        delay make unstable."""
        out = []
        for name in sorted(n for n in self.regulated if not self.checks[n].stabilizable):
            mode = self.checks[name].unstabilizable_modes[0]
            out.append(f"subsystem {name} is not stabilizable: mode {eig_text(mode.eigenvalue)} in "
                       f"{', '.join(mode.states)}")
        if self.undetectable:
            out.append(self.undetectable)
        sampled = unstable_when_sampled(self.rate_warnings, self.rate or 0.0)
        if sampled:
            out.append(sampled)
        flown = self.vehicle_loop.verdict() if self.vehicle_loop is not None else None
        if flown:
            out.append(flown)
        return out

    def verdict(self) -> str | None:
        """Why the check stage fails, on one line (None when it passes): ``run`` and ``report`` stop
        on it; ``check`` prints each of :meth:`failures`."""
        return "; ".join(self.failures()) or None


@dataclass(frozen=True)
class Flight:
    """``simulate``'s result: the run, the loop it flew, its metrics and flight numbers."""

    sim: SimResult
    loop: ClosedLoop
    metrics: dict
    flight: dict
_c = artifacts.complex_values  # eigenvalues: [re, im] pairs in JSON even when all are real


def default_out(cfg: Config) -> Path:
    """``runs/<config name>``."""
    return Path("runs") / cfg.name


class Workspace(pipeline.Stages):
    """Stages of one config in one run directory: :class:`quadctl.pipeline.Stages` that reuses
    each stage's fresh artifact and writes the ones it computes.

    Parameters
    ----------
    cfg : Config
    out : path, optional
        Run directory (default ``runs/<config name>``).
    fresh : bool
        Recompute every stage, ignoring existing artifacts.
    source_text : str, optional
        The YAML the config was read from (the file's text, or a bundled config's), kept as
        ``config.yaml``. Without it (a config built in Python) ``config.yaml`` is the validated
        config under a comment that says so.
    progress : callable, optional
        ``progress(done, total)`` in RK4 steps while the simulation stage runs (see
        :func:`quadctl.sim.run.simulate`).
    """

    def __init__(self, cfg: Config, out: Path | str | None = None, *, fresh: bool = False,
                 source_text: str | None = None, progress=None):
        super().__init__(setup_of(cfg))
        self.cfg = cfg
        self.progress = progress
        self.out = Path(out) if out is not None else default_out(cfg)
        self.fresh = fresh
        self.source_text = source_text
        self._config_written = False
        self.written: list[Path] = []
        self.reused: list[Path] = []
        self.payloads: dict[str, dict] = {}
        """JSON artifacts written or reused in this session, by file name (what ``--json`` prints);
        a reused artifact is parsed once, here."""
        self._hold = contextlib.ExitStack()
        self._hold.enter_context(artifacts.locked(self.out))  # one run writes a folder at a time
        weakref.finalize(self, self._hold.close)
        artifacts.remove_stale_temporaries(self.out)

    def close(self) -> None:
        """Release the run folder (the process's end releases it too)."""
        self._hold.close()

    def __enter__(self) -> Workspace:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def path(self, name: str) -> Path:
        return self.out / name

    def _reusable(self, name: str) -> bool:
        if self.fresh:
            return False
        if name in self.payloads:
            return True
        ok = artifacts.is_fresh(self.path(name), self.cfg)
        if ok:
            self.reused.append(self.path(name))
            if name.endswith(".json"):  # --json prints the artifact, reused or new
                self.payloads[name] = artifacts.read_json(self.path(name))
        return ok

    def _meta(self, kind: str, backends=()) -> dict:
        return artifacts.metadata(self.cfg, kind, backends)

    def _write_json(self, name: str, kind: str, payload: dict, backends=()) -> None:
        self._write_config_files()
        full = artifacts.jsonable({**self._meta(kind, backends), **payload})
        self.payloads[name] = full
        self.written.append(artifacts.write_json(self.path(name), full))

    def _write_npz(self, name: str, arrays: dict, meta: dict) -> None:
        self._write_config_files()
        self.written.append(artifacts.write_npz(self.path(name), arrays, meta))

    def _write_config_files(self) -> None:
        """``config.yaml`` (as given) and ``config.resolved.yaml``, at the session's first write."""
        if self._config_written:
            return
        resolved = self.cfg.to_yaml()
        given = self.source_text if self.source_text is not None else (
            "# built in Python, not read from a file: the validated config\n" + resolved)
        head = (f"# the config as quadctl {__version__} validated it, every default filled in "
                f"(config_hash {self.cfg.digest()})\n")
        self.written.append(artifacts.write_bytes(self.path(CONFIG_GIVEN), given.encode("utf-8")))
        self.written.append(artifacts.write_bytes(self.path(CONFIG_RESOLVED), (head + resolved).encode("utf-8")))
        self._config_written = True

    # -- stages ---------------------------------------------------------------------------

    @cached_property
    def trim(self) -> Trim:
        if self._reusable(TRIM):
            data = self.payloads[TRIM]
            return Trim(x=np.array(data["x"]), u=np.array(data["u"]), xdot=np.array(data["xdot"]),
                        residual=float(data["residual"]), iterations=int(data["iterations"]))
        trim = super().trim
        self._write_json(TRIM, "trim", {
            "x": trim.x, "u": trim.u, "xdot": trim.xdot, "residual": trim.residual,
            "iterations": trim.iterations, "velocity_ned": self.setup.velocity_ned,
            "wind_ned": self.setup.trim_wind,  # m/s: the steady wind trimmed in (trim.wind), else zero
            "state": dict(zip(STATE_NAMES, trim.x)), "input": dict(zip(INPUT_NAMES, trim.u)),
            "units": {**STATE_UNITS, **INPUT_UNITS}})
        return trim

    @cached_property
    def linear(self) -> LinearModel:
        if self._reusable(LINEAR):
            arrays, _ = artifacts.read_npz(self.path(LINEAR))
            return LinearModel(A=arrays["A"], B=arrays["B"], x_trim=arrays["x_trim"],
                               u_trim=arrays["u_trim"], x_rate=arrays["x_rate"])
        linear = super().linear
        self._write_npz(LINEAR, {
            "A": linear.A, "B": linear.B, "x_trim": linear.x_trim, "u_trim": linear.u_trim,
            "x_rate": linear.x_rate,
            "state_names": np.array(STATE_NAMES), "input_names": np.array(INPUT_NAMES)},
            self._meta("linear"))
        return linear

    @cached_property
    def decoupled(self) -> Decoupled:
        dec = super().decoupled
        self._write_json(SUBSYSTEMS, "subsystems", {
            "subsystems": {s.name: {"states": s.states, "inputs": s.inputs, "A": s.A, "B": s.B,
                                    "C": s.C, "regulated": s.regulated} for s in dec.subsystems},
            "dropped": [{"name": d.name, "matrix": d.matrix, "row": d.row, "column": d.column,
                         "value": d.value, "relative": d.relative, "unit": d.unit}
                        for d in dec.dropped]})
        return dec

    @cached_property
    def checks(self) -> CheckReport:
        """Rank checks; for a continuous design run at ``controller.rate``, the rate warnings."""
        checks = pipeline.checks_of(self.decoupled, self.linear)
        est = self.setup.estimator
        if est is not None:  # the measured set on the coupled 12-state model (what the Kalman filter sees)
            from quadctl.estimator import selector

            checks[ESTIMATOR_CHECK] = check(self.linear.A, self.linear.B, selector(est.measured), STATE_NAMES)
        regulated = {s.name for s in self.decoupled.regulated}
        timing = self.setup.timing
        warnings: list[RateWarning] = []
        vehicle = None
        if all(checks[n].stabilizable for n in regulated):
            warnings = list(self.rate_warnings)
            if self.setup.rotor_time_constant is not None or timing.delay_samples:
                des = self.__dict__.get("design") or pipeline.design_of(self.setup, self.decoupled, self.linear)
                vehicle = pipeline.vehicle_loop_of(self.setup, self.linear, des)
        self._write_json(CHECKS, "checks", {
            "subsystems": {n: _checks_payload(c, n in regulated) for n, c in checks.items()
                           if n not in ("full", ESTIMATOR_CHECK)},
            "full": _checks_payload(checks["full"], True),
            ESTIMATOR_CHECK: None if est is None else {
                "measured": est.measured, **_checks_payload(checks[ESTIMATOR_CHECK], False)},
            "rate": None if timing.rate is None else {
                "rate": timing.rate, "design": "discrete" if timing.design_rate is not None else "continuous",
                "realizable_frequency": realizable_frequency(timing.rate),
                "warnings": [{"loop": w.loop, "pole": w.pole, "factor": w.factor,
                              "sampled_spectral_radius": w.sampled_radius, "sampled_stable": w.sampled_stable,
                              "message": w.message(timing.rate)} for w in warnings]},
            "closed_loop": None if vehicle is None else {
                **_vehicle_loop_payload(vehicle), "rotor_time_constant": self.setup.rotor_time_constant,
                "rotor_lag": self.setup.rotor_lag, "delay_samples": timing.delay_samples}})
        undetectable = None
        if est is not None and not checks[ESTIMATOR_CHECK].detectable:
            from quadctl.estimator import require_detectable, selector

            try:
                require_detectable(self.linear.A, selector(est.measured), est.measured)
            except DesignError as exc:
                undetectable = str(exc)
        return CheckReport(checks=checks, regulated=tuple(sorted(regulated)), rate=timing.rate,
                           rate_warnings=tuple(warnings), vehicle_loop=vehicle, undetectable=undetectable)

    @cached_property
    def design(self) -> Design:
        des = super().design
        self._write_json(DESIGN, "design", {
            "subsystems": {s.name: {"states": s.states, "inputs": s.inputs, "Q": s.Q, "R": s.R,
                                    "K": s.K, "P": s.P, "closed_loop_eigenvalues": _c(s.eigenvalues),
                                    "riccati_residual": s.residual} for s in des.subsystems},
            "K_block": des.K_block, "Q_block": des.Q_block, "R_block": des.R_block,
            "full_closed_loop_eigenvalues": _c(des.full_eigenvalues),
            "marginal_states": des.marginal_states, "stable": des.stable,
            "rotor_lag": {"mode": self.setup.rotor_lag, "time_constant": self.setup.rotor_time_constant,
                          "design_time_constant": des.lag_time_constant,
                          "Kv_block": des.Kv_block if des.lag_time_constant is not None else None,
                          "measured": ("the controller's own model of the lag, propagated from its commands"
                                       if des.lag_time_constant is not None else None)},
            **_flight_design_payload(des), "estimator": self._estimator_payload()})
        return des

    def _estimator_payload(self) -> dict | None:
        """design.json's ``estimator``: the Kalman filter, its form stated (None without ``estimator:``)."""
        kal = pipeline.estimator_of(self.setup, self.linear)
        if kal is None:
            return None
        discrete = kal.discrete
        return {
            "form": kal.form,
            "gain_form": ("filter (measurement-update) gain M of MATLAB dlqe: x_hat[k|k] = x_hat[k|k-1] + "
                          "M (y[k] - C x_hat[k|k-1]); the law acts on x_hat[k|k]; predictor gain L = Ad M"
                          if discrete else "Kalman-Bucy gain L of MATLAB lqe: dx_hat/dt = A x_hat + B du + "
                          "L (y - C x_hat)"),
            "coordinates": "deviation from the trim reference x_ref(t), on the linear model about the trim",
            "measured": kal.measured, "sample_time": kal.sample_time,
            "A": kal.A, "B": kal.B, "C": kal.C, "G": kal.G, "Qn": kal.Qn, "Rn": kal.Rn,
            "noise_convention": ("covariance per sample (noise held over each controller period)" if discrete
                                 else "intensity sigma^2 * noise period (held noise's low-frequency spectrum)"),
            "gain": kal.gain, "predictor_gain": kal.predictor_gain,
            "P": kal.P, "Z": kal.Z,
            "covariance": ("P a priori, Z = P - M C P a posteriori" if discrete else "P = Z error covariance"),
            "eigenvalues": _c(kal.eigenvalues),
            "eigenvalues_of": "Ad - L C (z)" if discrete else "A - L C (s)",
            "riccati_residual": kal.residual,
        }

    @cached_property
    def gains(self) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], np.ndarray | None]:
        """(K_block, Ki_block, integral_states, Kv_block or None): from design.json when it is fresh,
        else a new design. ``Kv_block`` is None unless the design includes the rotors' lag."""
        if "design" not in self.__dict__ and self._reusable(DESIGN):
            data = self.payloads[DESIGN]
            ints = tuple(data.get("integral_states", ()))
            Ki = np.array(data.get("Ki_block", [[]] * N_INPUTS), dtype=float)
            Kv = (data.get("rotor_lag") or {}).get("Kv_block")
            return (np.array(data["K_block"], dtype=float), Ki.reshape(N_INPUTS, len(ints)), ints,
                    None if Kv is None else np.array(Kv, dtype=float))
        des = self.design
        return (des.K_block, des.Ki_block, des.integral_states,
                des.Kv_block if des.lag_time_constant is not None else None)

    @cached_property
    def margins(self) -> list:
        """Margins of every regulated loop (design model and coupled); writes margins.json."""
        from quadctl import margins

        des, timing, linear = self.design, self.setup.timing, self.linear
        emulated = timing.rate if timing.mode == "emulated" else None
        result = margins.all_margins(
            des, self.decoupled, linear.A, linear.B, emulated_rate=emulated,
            actuators=self.setup.actuators, u_trim=linear.u_trim,
            initial_demand=pipeline.initial_demand(self.setup, des), delay_samples=timing.delay_samples,
            rotor_time_constant=self.setup.rotor_time_constant,
            estimator=pipeline.estimator_of(self.setup, linear))
        vehicle = pipeline.vehicle_loop_of(self.setup, linear, des)
        self._write_json(MARGINS, "margins", {
            "rate": timing.rate, "design": "discrete" if des.rate else "continuous",
            "delay_samples": timing.delay_samples, "rotor_time_constant": self.setup.rotor_time_constant,
            "rotor_lag": self.setup.rotor_lag,
            "closed_loop": _vehicle_loop_payload(vehicle),
            "guarantee": {"gain_margin_db": list(margins.LQR_GAIN_MARGIN_DB),
                          "phase_margin_deg": margins.LQR_PHASE_MARGIN_DEG},
            "estimator": None if self.setup.estimator is None else {
                "measured": self.setup.estimator.measured, "model": "lqg",
                "broken": "at the plant input, Kalman filter in the loop fed the commanded input"},
            "loops": [m.as_dict() for m in result]})
        return result

    @cached_property
    def full(self):
        """``design --full``: (FullDesign, comparison); writes design_full.json."""
        fd, comparison = pipeline.compare_full(self.setup, self.linear, self.design)
        self._write_json(DESIGN_FULL, "design_full", {
            "K": fd.K, "Ki": fd.Ki, "integral_states": fd.integral_states, "states": fd.states,
            "left_out": fd.left_out, "Q": fd.Q, "R": fd.R, "P": fd.P,
            "closed_loop_eigenvalues": _c(fd.eigenvalues), "stable": fd.stable, "rate": fd.rate,
            "riccati_residual": fd.residual,
            "position": ("left out: " + ", ".join(fd.left_out) + " (no weight, no dynamics); "
                         if fd.left_out else "") + "weighted positions regulated about the moving reference",
            "comparison": comparison}, [d["backend"] for d in comparison["designs"].values()])
        return fd, comparison

    @cached_property
    def simulation(self) -> Flight:
        """The configured run with the design's gains; writes sim.npz and sim.json."""
        linear, setup = self.linear, self.setup
        K, Ki, ints, Kv = self.gains
        loop = pipeline.closed_loop_of(setup, linear, K, Ki=Ki, integral_states=ints, Kv=Kv)
        sim = pipeline.simulation_of(setup, loop, progress=self.progress)
        flight = pipeline.flight_summary(setup, loop, sim)
        summary = summarize(sim, linear.u_trim, setup.Q_block, setup.R_block, setup.regulated)
        meta = self._meta("simulation", sim.backend)
        self._write_npz(SIM_NPZ, {
            "t": sim.t, "x": sim.x, "u": sim.u, "x_ref": sim.x_ref, "dt": np.array(sim.dt),
            "stride": np.array(sim.stride),
            "status": np.array(sim.status), "state_names": np.array(STATE_NAMES),
            "input_names": np.array(INPUT_NAMES), "z": sim.z,
            "integral_states": np.array(loop.integral_states, dtype=str),
            "rotor_thrust": sim.rotor_thrust, "rotor_thrust_unit": np.array("N"),  # empty: instantaneous rotors
            "rotor_names": np.array([f"rotor {i + 1}" for i in range(sim.rotor_thrust.shape[1])], dtype=str),
            "u_ref": sim.u_ref,  # empty without simulation.reference: the feedforward input (N, N m)
            "x_hat": sim.x_hat,  # empty without an estimator: x_hat[k|k-1] held (sampled) or Kalman-Bucy's
            "wind": sim.wind, "wind_unit": np.array("m/s"),  # empty: still air
            "wind_names": np.array(["wind N", "wind E", "wind D"] if len(sim.wind) else [], dtype=str)},
            meta)
        self._write_json(SIM_JSON, "simulation", {
            "status": sim.status, "message": sim.message, "dt": sim.dt, "steps": sim.steps,
            "stride": sim.stride, "samples": len(sim.t),
            "duration": float(sim.t[-1]), "backend": sim.backend,
            "dt_auto": sim.plan.auto, "max_stable_dt": sim.plan.max_stable_dt, "method": sim.plan.method,
            "schedule": schedule.summary(sim.plan),
            "fastest_eigenvalue": sim.plan.fastest_eigenvalue,
            "fastest_subsystem": sim.plan.fastest_owner,
            "metrics": summary, "units": {**STATE_UNITS, **INPUT_UNITS}, **flight}, sim.backend)
        return Flight(sim=sim, loop=loop, metrics=summary, flight=flight)


ESTIMATOR_CHECK = "estimator"
"""checks' key of the measured set (``estimator.measure``) on the coupled model."""


def _flight_design_payload(des: Design) -> dict:
    """design.json keys of sampled and LQI designs: rate, integrators, discrete eigenvalues."""
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


def _vehicle_loop_payload(loop) -> dict:
    """margins.json's and checks.json's ``closed_loop``: the loop the vehicle flies (:class:`pipeline.VehicleLoop`)."""
    Ts, eig = loop.sample_time, loop.eigenvalues
    return {
        "what": "the coupled linear loop with the rotors' lag, the controller's lag model (include), the "
                "integrators and the delay; free positions left out",
        "domain": "z" if Ts else "s", "eigenvalues": _c(eig), "stable": loop.stable,
        "spectral_radius" if Ts else "slowest_real_part": float(np.abs(eig).max() if Ts else eig.real.max()),
        "least_damping": loop.least_damping, "design_least_damping": loop.design_least_damping}
