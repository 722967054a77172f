"""The exported controller as a Crazyflie out-of-tree controller app.

:func:`sources` writes the app: the exported C controller (in float, taking a reference each sample),
an adapter for the firmware's out-of-tree controller interface (``controller.h``; written from its
documentation, no firmware code in it) with the frames converted (:data:`FRAMES`), the build files
and a README. :func:`check` refuses what the app cannot serve (exit 2). The firmware platform it is checked
against (:data:`quadctl.export.crazyflie_platform.FIRMWARE`) and the rotor thrusts a flight asks of it are
:mod:`quadctl.export.crazyflie_platform`'s. What the adapter does at each call is in the docs,
docs/guide/export.md ("Into the flight stack: the Crazyflie app").
"""

from __future__ import annotations

import shlex
from importlib import resources
from string import Template

import numpy as np

from quadctl.config.template import PRESETS
from quadctl.errors import ArgumentError, ConfigError
from quadctl.export import c
from quadctl.export.bundle import Export, law_text, require_export
from quadctl.export.crazyflie_platform import FIRMWARE, MODES, NUMBERING, SPINS
from quadctl.present.platform import no_setpoint_flyable, rotors_to_add, setpoint_refused
from quadctl.text.escape import c_comment
from quadctl.text.setpoints import SETPOINT_NEEDS as NEEDS
from quadctl.version import __version__

LOOP_HZ = 1000
"""The firmware's stabilizer loop (``RATE_MAIN_LOOP`` in ``stabilizer_types.h``): the controller is
called at this rate."""
SETPOINTS = tuple(NEEDS)
"""What the app follows (in the order :func:`default_setpoint` tries them): ``position`` (x, y, z and
yaw held where the commander says, the high-level commander's go-to), ``velocity`` (the hover
setpoint: vx, vy, z (or vz) and yaw rate)."""

ROTOR_LAG = PRESETS["crazyflie"].motors["time_constant"][0]
"""s: the Crazyflie 2.x's rotor lag, as the Crazyflie template of ``quadctl init`` writes it: the time constant
``quadctl identify`` finds in the bundled flight ``log10`` (docs/guide/identify.md; its 95 % interval is
checked to hold this value in tests/identify/test_identify_estimates.py). A design that leaves it out is
told so at export (:func:`lag_sentence`)."""

FRAMES = (
    ("pN, pE, pD", "state->position x, y, z (m, world x forward, y left, z up)", "pN = x, pE = -y, pD = -z"),
    ("u, v, w", "state->velocity (m/s, world) and state->attitudeQuaternion",
     "body velocity = R(q)^T velocity (FLU), then v and w negated"),
    ("phi, theta, psi", "state->attitude roll, pitch, yaw (deg; pitch in the legacy sign, nose up positive)",
     "phi = roll, theta = pitch, psi = -yaw, in rad, psi wrapped into (-pi, pi]"),
    ("p, q, r", "sensors->gyro x, y, z (deg/s, body x forward, y left, z up)", "p = x, q = -y, r = -z, in rad/s"),
)
"""Each conversion the adapter makes: (quadctl states, the firmware's fields, the conversion)."""

APP_FILES = ("Makefile", "Kbuild", "app-config", "README.md", "src/Kbuild", "src/quadctl_app.c",
             "src/quadctl_crazyflie.c", "src/quadctl_crazyflie.h")
"""The app's own files (beside ``src/quadctl_controller.h`` and ``.c``)."""
TEMPLATES = "export/templates/crazyflie"


def quadrants(positions) -> tuple[str, ...]:
    """Where each rotor is, from its body position ``(x, y)`` (FRD, m): ``front_right`` (x > 0, y > 0),
    ``rear_right``, ``rear_left``, ``front_left``; ``on_axis`` for a rotor on the x or y axis (a ``+``
    layout), which no firmware motor is.

    >>> quadrants([[0.03, 0.03], [-0.03, 0.03], [-0.03, -0.03], [0.03, -0.03]])
    ('front_right', 'rear_right', 'rear_left', 'front_left')
    """
    out = []
    for x, y in np.asarray(positions, dtype=float):
        if x == 0.0 or y == 0.0:
            out.append("on_axis")
        else:
            out.append(("front" if x > 0 else "rear") + ("_right" if y > 0 else "_left"))
    return tuple(out)


def divider(rate: float) -> int:
    """Firmware loop calls per controller sample: ``1000 / rate``.

    Raises
    ------
    ConfigError
        ``rate`` does not divide the firmware's 1 kHz loop.
    """
    n = LOOP_HZ / float(rate)
    if n < 1 or abs(n - round(n)) > 1e-9:
        near = [r for r in (1000, 500, 250, 200, 100) if r <= 2 * rate]
        raise ConfigError(f"controller.rate = {rate:g} Hz does not divide the Crazyflie's {LOOP_HZ} Hz stabilizer "
                          f"loop: set controller.rate to a divisor of {LOOP_HZ} (e.g. {near[0] if near else 100})")
    return int(round(n))


def unregulated(exp: Export) -> dict[str, list[str]]:
    """``{setpoint: the states it needs (:data:`NEEDS`) that the partition leaves free}``, for each of
    :data:`SETPOINTS` in order."""
    return {s: [x for x in NEEDS[s] if x not in exp.setup.regulated] for s in SETPOINTS}


def flyable_setpoints(exp: Export) -> tuple[str, ...]:
    """The setpoints (:data:`SETPOINTS`, in order) whose states (:data:`NEEDS`) the partition all regulates."""
    return tuple(s for s, free in unregulated(exp).items() if not free)


def default_setpoint(exp: Export) -> str:
    """The setpoint the app follows when none is asked: the first of :data:`SETPOINTS` the config can
    fly (:func:`flyable_setpoints`: ``position`` when the partition regulates pN, pE, pD and psi,
    ``velocity`` when it leaves the position free, as the bundled ``crazyflie`` does), else
    ``position`` (which :func:`check` refuses, naming what each setpoint needs regulated).

    >>> from quadctl import config, export, setup
    >>> default_setpoint(export.prepare(setup.setup_of(config.load("crazyflie"))))
    'velocity'
    """
    require_export(exp, "default_setpoint")
    return (flyable_setpoints(exp) or SETPOINTS)[0]


def check(exp: Export, setpoint: str | None = None, mode: str = "force") -> None:
    """Refuse what the app cannot serve (:class:`~quadctl.errors.ConfigError`, exit 2).

    Parameters
    ----------
    exp : Export
        Prepared with a rate.
    setpoint : {"position", "velocity"}, optional
        What the commander gives (:data:`SETPOINTS`); default :func:`default_setpoint`.
    mode : {"force", "force-torque"}

    Raises
    ------
    ConfigError
        The rate does not divide 1 kHz; force mode without rotors (``motors:``) or with a rotor
        numbering other than the firmware's; a Kalman filter (``estimator:``; the firmware estimates
        the state); a trim that is not a hover (the commander's setpoints are about a hover); a
        setpoint that needs a state the partition leaves free.
    ArgumentError
        An unknown ``setpoint`` or ``mode``.
    """
    require_export(exp, "check")
    asked, setpoint = setpoint, default_setpoint(exp) if setpoint is None else setpoint
    if setpoint not in SETPOINTS:
        raise ArgumentError(f"setpoint must be one of {SETPOINTS}, got {setpoint!r}")
    if mode not in MODES:
        raise ArgumentError(f"mode must be one of {MODES}, got {mode!r}")
    divider(exp.rate)
    loop = exp.loop
    act = loop.actuators
    if mode == "force":
        if act is None or act.mode != "motors":
            raise ConfigError("motors: is absent: force mode writes each rotor's thrust, so the config needs its "
                              f"rotors: add them, {rotors_to_add(FIRMWARE)}, or export with --mode force-torque")
        motors = act.motors
        where, spins = quadrants(motors.positions()), tuple(float(v) for v in motors.rotor_spins())
        if where != NUMBERING or spins != SPINS:
            turn = ", ".join("ccw" if v > 0 else "cw" for v in spins)
            raise ConfigError(
                f"motors.numbering: rotors 1-4 are {', '.join(where)} spinning {turn}, not the Crazyflie's "
                "motors M1-M4 (front_right, rear_right, rear_left, front_left spinning ccw, cw, ccw, cw): set "
                "motors.layout: x and motors.numbering: crazyflie (and no motors.spin)")
    filt = loop.rate_filter
    if filt is not None and not firmware_gyro_filter(filt):
        raise ConfigError(
            f"controller.filters: {filt.describe()}, but the firmware's sensor driver low-passes the gyro itself "
            f"({FIRMWARE.gyro_lowpass()}, {FIRMWARE.gyro_source}) before the app "
            f"reads it, and the app flies that filter alone: set {FIRMWARE.gyro_filter()}, the filter the vehicle "
            "has, or remove controller.filters")
    if loop.estimator is not None:
        raise ConfigError("estimator: the app takes the firmware's state estimate (its Kalman filter): remove "
                          "estimator: from the config to export the full-state law for the Crazyflie")
    if np.any(np.asarray(loop.x_rate) != 0.0):
        raise ConfigError("trim.velocity_ned is not zero: the commander's setpoints are positions and velocities "
                          "about a hover; trim at velocity_ned: [0, 0, 0]")
    free = unregulated(exp)
    if free[setpoint] and asked is None:  # none asked, and none flyable
        raise ConfigError(no_setpoint_flyable(free))
    if free[setpoint]:
        raise ConfigError(setpoint_refused(setpoint, free[setpoint], flyable_setpoints(exp)))


def firmware_gyro_filter(filt) -> bool:
    """Whether ``filt`` (:class:`quadctl.linear.filters.RateFilter`) is the firmware's sensor driver's gyro
    low-pass (:attr:`~quadctl.export.crazyflie_platform.Platform.gyro_cutoff`,
    :attr:`~quadctl.export.crazyflie_platform.Platform.gyro_order`), alone."""
    return (len(filt.sections) == 1 and filt.sections[0].kind == "lowpass"
            and filt.sections[0].order == FIRMWARE.gyro_order
            and abs(filt.sections[0].frequency - FIRMWARE.gyro_cutoff) <= 1e-9 * FIRMWARE.gyro_cutoff)


def gyro_sentence(exp: Export) -> str | None:
    """What the export says when the design reads raw rates, though the firmware filters the gyro the app reads:
    the margins, the simulation and the comparison with the PID cascade have no filter the vehicle has."""
    require_export(exp, "gyro_sentence")
    if exp.loop.rate_filter is not None:
        return None
    return (f"the firmware low-passes the gyro ({FIRMWARE.gyro_lowpass()}, {FIRMWARE.gyro_source}) before the "
            "app's law reads it, but the config has no controller.filters: its "
            "margins, simulation and comparison read raw rates, which the vehicle does not have; set "
            f"{FIRMWARE.gyro_filter()} to check the design behind the filter (the app leaves it to the firmware)")


def lag_sentence(exp: Export, config: str, sets=()) -> str | None:
    """What the export says when the config has no rotor lag at all (``motors.time_constant``): its design,
    margins and simulation take the rotors as instantaneous, though the Crazyflie's lag (:data:`ROTOR_LAG`)
    is long enough to unsettle a design made without it; ``config`` and ``sets`` are how the user named the
    config (``-c``, each ``--set`` as given), for the command that checks the design exported."""
    require_export(exp, "lag_sentence")
    if exp.setup.rotor_time_constant is not None:
        return None
    check = shlex.join(["quadctl", "margins", "-c", config, *(w for s in sets for w in ("--set", s)),
                        "--set", f"motors.time_constant={ROTOR_LAG:g}"])
    return (f"the config gives the rotors no lag (motors.time_constant), but a Crazyflie's rotors lag about "
            f"{1e3 * ROTOR_LAG:.0f} ms (quadctl identify on its flight logs): check the design on it before you fly, "
            f"{check}, and design with it (controller.rotor_lag: include) if it does not hold")


def law(exp: Export, setpoint: str) -> str:
    """The app's control law in one paragraph (:func:`quadctl.export.bundle.law_text`): the reference is the
    commander's ``setpoint`` setpoints, through the app's adapter, about the hover trim."""
    return law_text(exp.loop, exp.sample_time, reference=True,
                    source=f"the commander's {setpoint} setpoints, through the app's adapter",
                    feedforward="the hover trim's roll, pitch and input")


def _mass(exp: Export) -> float:
    return float(exp.setup.vehicle.mass)


def _c_float(v: float) -> str:
    return f"{float(v)!r}f"


def sources(exp: Export, setpoint: str | None = None, mode: str = "force") -> dict[str, str]:
    """The app's files: ``{path relative to the app folder: text}``; ``setpoint`` default
    :func:`default_setpoint`.

    The controller is :func:`quadctl.export.c.sources` with the reference as an input
    (``quadctl_step_ref``): the commander's setpoint is the law's reference.

    Raises
    ------
    ConfigError
        What :func:`check` refuses.
    """

    setpoint = default_setpoint(exp) if setpoint is None else setpoint
    check(exp, setpoint, mode)
    loop = exp.loop
    ctrl = c.sources(exp, reference=True,  # the firmware filters the gyro the adapter reads: once (check)
                     gyro_filtered_by=f"the firmware's sensor driver's ({FIRMWARE.gyro_source})")
    n = divider(exp.rate)
    x_trim = np.asarray(loop.x_trim, dtype=float)
    u_trim = np.asarray(loop.u_trim, dtype=float)
    values = {
        "CONFIG": c_comment(exp.name), "VERSION": __version__, "CONFIG_HASH": exp.config_hash or "not recorded",
        "RATE": f"{float(exp.rate):g}", "DIVIDER": str(n), "LOOP_HZ": str(LOOP_HZ),
        "MODE": mode, "MODE_MACRO": "QUADCTL_CF_FORCE_TORQUE" if mode == "force-torque" else "QUADCTL_CF_FORCE",
        "SETPOINT": setpoint,
        "HOLDS_POSITION": "1" if all(s in exp.setup.regulated for s in ("pN", "pE")) else "0",
        "TRIM_PN": _c_float(x_trim[0]), "TRIM_PE": _c_float(x_trim[1]), "TRIM_PD": _c_float(x_trim[2]),
        "TRIM_PSI": _c_float(x_trim[8]), "TRIM_T": _c_float(u_trim[0]),
        "COMMIT": FIRMWARE.commit, "PLATFORM_SOURCE": FIRMWARE.source,
        "FW_ARM": f"{FIRMWARE.arm_length:g}", "FW_TORQUE": f"{FIRMWARE.torque_coefficient:g}",
        "FW_MAX": f"{FIRMWARE.max_thrust:g}", "MASS": f"{_mass(exp):g}",
    }
    files = {}
    base = resources.files("quadctl").joinpath(TEMPLATES)
    for name in APP_FILES:
        text = base.joinpath(name.replace("/", "__")).read_text(encoding="utf-8")
        files[name] = Template(text).substitute(values)
    for name, text in ctrl.items():
        files[f"src/{name}"] = text
    return files

