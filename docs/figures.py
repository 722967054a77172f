"""Regenerate the figures of the README sections "From the report's design to one that flies",
"Wind", "State estimation (LQG)", "Fly somewhere" and "Gain scheduling in flight".

Run from the repository root:  python docs/figures.py   (writes docs/figures/*.png, prints the numbers);
python docs/figures.py lqg   writes only the LQG figure; python docs/figures.py lag   only the lag and delay one;
python docs/figures.py schedule   only the gain schedule's envelope; python docs/figures.py transition   only the
gain schedule's transition.

Every number and curve comes from the library (the same calls the CLI makes); nothing is stored.
"""

from __future__ import annotations

import copy
import io
import sys
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from quadctl import config, motors, pipeline, plots
from quadctl.design import margins
from quadctl.layout import INPUT_NAMES, STATE_INDEX
from quadctl.problem import setup_of

OUT = Path(__file__).resolve().parent / "figures"
MAMBO = motors.Motors()


def solve(data: dict):
    setup = setup_of(config.from_dict(data, "<docs>"))
    trim = pipeline.trim_of(setup)
    linear = pipeline.linear_of(setup, trim)
    dec = pipeline.decoupled_of(setup, linear)
    des = pipeline.design_of(setup, dec, linear)
    loop = pipeline.loop_of(setup, linear, des)
    return setup, linear, dec, des, loop, pipeline.simulation_of(setup, loop)


def variant(name: str, **changes) -> dict:
    data = copy.deepcopy(config.load(name).model_dump(mode="json"))
    for key, value in changes.items():
        section, _, field = key.partition(".")
        if field:
            data[section][field] = value
        else:
            data[section] = value
    return data


def save(fig: Figure, name: str) -> None:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    OUT.mkdir(exist_ok=True)
    (OUT / name).write_bytes(buf.getvalue())
    print(f"wrote docs/figures/{name} ({len(buf.getvalue()) // 1024} KB)")


def peak_demand_figure(cases: dict) -> Figure:
    """Peak |u - u_trim| of each design over what the Mambo's rotors give from the trim."""
    fig = Figure(figsize=(8.0, 3.8), layout="constrained")
    ax = fig.subplots()
    width = 0.8 / len(cases)
    for k, (label, (ratio, _)) in enumerate(cases.items()):
        ax.bar(np.arange(4) + (k - (len(cases) - 1) / 2) * width, ratio, width, label=label)
    ax.axhline(1.0, color="k", lw=1.0, ls="--")
    ax.set_yscale("log")
    ax.set_xticks(range(4), [f"{n}" for n in INPUT_NAMES])
    ax.set_ylabel("peak |u - u_trim| / rotor headroom")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=8, frameon=False, loc="upper left")
    fig.suptitle("What each design asks of the Mambo's rotors (report's initial offset); above 1: impossible")
    return fig


def response_figure(sim, loop) -> Figure:
    fig = Figure(figsize=(8.0, 6.0), layout="constrained")
    ax = fig.subplots(3, 1, sharex=True)
    err = sim.x - sim.x_ref
    for name in ("phi", "theta", "psi"):
        ax[0].plot(sim.t, np.rad2deg(err[:, STATE_INDEX[name]]), lw=1.2, label=name)
    ax[0].set_ylabel("attitude error [deg]")
    ax[1].plot(sim.t, err[:, STATE_INDEX["pD"]], lw=1.2, label="pD error")
    ax[1].set_ylabel("pD error [m]")
    f = loop.actuators.commands(sim.u)
    for i in range(4):
        ax[2].plot(sim.t, f[:, i], lw=1.0, label=f"rotor {i + 1}")
    ax[2].axhline(MAMBO.max_thrust, color="k", ls="--", lw=1.0, label="limit")
    ax[2].set_ylabel("rotor thrust [N]")
    ax[2].set_xlabel("time [s]")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=7, frameon=False, loc="upper right", ncol=5)
    fig.suptitle("mambo-200hz: report's offset, 200 Hz discrete LQR, rotor limits, noise (seed 1)")
    return fig


def lqi_figure(runs: dict) -> Figure:
    fig = Figure(figsize=(8.0, 3.4), layout="constrained")
    ax = fig.subplots()
    for label, sim in runs.items():
        pd = STATE_INDEX["pD"]
        ax.plot(sim.t, (sim.x[:, pd] - sim.x_ref[:, pd]) * 100, lw=1.4, label=label)
    ax.axhline(0.0, color="0.3", lw=0.8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("altitude error pD [cm] (positive: low)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, frameon=False)
    fig.suptitle("Vehicle 10 % heavier than the design model (hover, mambo-200hz weights, no noise)")
    return fig


def lqg_figure(full, lqg) -> Figure:
    """The same gains with full-state feedback and through the Kalman filter: attitude and altitude
    errors, and the filter's estimation error on w (a state it does not measure)."""
    fig = Figure(figsize=(9.0, 5.6), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True).ravel()
    for ax, name, scale, unit in zip(axes[:3], ("pD", "phi", "theta"), (100.0, 180 / np.pi, 180 / np.pi),
                                     ("cm", "deg", "deg")):
        i = STATE_INDEX[name]
        for label, sim, style in (("full-state LQR (measured x)", full, "-"),
                                  ("LQG (Kalman filter on imu + mocap)", lqg, "--")):
            ax.plot(sim.t, (sim.x[:, i] - sim.x_ref[:, i]) * scale, style, lw=1.0, label=label)
        ax.set_ylabel(f"{name} error [{unit}]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8, frameon=False)
    w = STATE_INDEX["w"]
    axes[3].plot(lqg.t, (lqg.x[:, w] - lqg.x_hat[:, w]) * 100, lw=0.8, color="C2")
    axes[3].set_ylabel("w - w_hat [cm/s] (not measured)")
    axes[3].grid(True, alpha=0.3)
    for ax in axes[2:]:
        ax.set_xlabel("time [s]")
    fig.suptitle("mambo-200hz: the same gains, full state against LQG (same noise seed)")
    return fig


def make_lqg_figure() -> None:
    """docs/configs/mambo-lqg.yaml against mambo-200hz (same gains, same noise)."""
    from quadctl.noise import rms_deviation

    full = solve(variant("mambo-200hz"))
    lqg_data = config.load(str(Path(__file__).resolve().parent / "configs" / "mambo-lqg.yaml")).model_dump(
        mode="json")
    lqg = solve(lqg_data)
    for label, (setup, _, _, _, loop, sim) in (("full state", full), ("LQG", lqg)):
        half = sim.t[-1] / 2
        rms = rms_deviation(sim.t, sim.x, sim.x_ref, half)
        print(f"{label}: {sim.status}; RMS second half: pD {rms['pD'] * 100:.3g} cm, phi "
              f"{np.degrees(rms['phi']):.3g} deg, theta {np.degrees(rms['theta']):.3g} deg")
    sim = lqg[-1]
    err = rms_deviation(sim.t, sim.x, sim.x_hat, sim.t[-1] / 2)
    print("LQG estimation error RMS (second half): " + ", ".join(f"{k} {v:.3g}" for k, v in err.items()))
    save(lqg_figure(full[-1], sim), "lqg-vs-lqr.png")


def gust_figure(runs: dict) -> Figure:
    """The Crazyflie trimmed in its 9.7 m/s east wind, hit by the 2 m/s north gust of crazyflie-wind."""
    fig = Figure(figsize=(8.0, 6.0), layout="constrained")
    ax = fig.subplots(3, 1, sharex=True)
    for label, sim in runs.items():
        ls = "-" if "turbulence" not in label else ":"
        ax[0].plot(sim.t, sim.wind[:, 0], lw=1.2, ls=ls, label=f"wind N, {label}")
        err = sim.x - sim.x_ref
        ax[1].plot(sim.t, err[:, STATE_INDEX["pN"]], lw=1.2, ls=ls, label=f"pN, {label}")
        ax[2].plot(sim.t, np.rad2deg(err[:, STATE_INDEX["theta"]]), lw=1.2, ls=ls, label=f"theta, {label}")
    ax[0].set_ylabel("wind N [m/s]")
    ax[1].set_ylabel("pN drift [m]")
    ax[2].set_ylabel("pitch from trim [deg]")
    ax[2].set_xlabel("time [s]")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=7, frameon=False, loc="upper left")
    fig.suptitle("crazyflie-wind: 1-cosine gust (MIL-F-8785C), 2 m/s north rising over 0.5 s, in a 9.7 m/s east wind")
    return fig


def gust_runs() -> dict:
    """crazyflie-wind with its gust alone, and with the moderate turbulence too; prints the peaks."""
    runs = {}
    for label, turbulence in (("gust", False), ("gust and turbulence", True)):
        data = variant("crazyflie-wind")
        if not turbulence:
            data["simulation"]["wind"]["turbulence"] = None
        setup, _, _, _, loop, sim = solve(data)
        runs[label] = sim
        err = sim.x - sim.x_ref
        ground, air = pipeline.speeds(sim)
        print(f"crazyflie-wind, {label}: status {sim.status}; peak |pN drift| {np.abs(err[:, 0]).max():.3g} m, "
              f"peak |theta - trim| {np.rad2deg(np.abs(err[:, 7]).max()):.3g} deg, "
              f"ground speed max {ground.max():.3g} m/s, airspeed max {air.max():.3g} m/s")
    return runs


def uncertainty_figure() -> Figure:
    """The rotor_lag include design flown on the 64 vehicles of examples/uncertainty-sweep.yaml (README, 10)."""
    from quadctl import sweep
    from quadctl.sweep.outputs import montecarlo_bands
    from quadctl.sweep.runner import base_of

    root = Path(__file__).resolve().parent.parent
    cfg = config.parse((root / "docs/configs/mambo-rotor-lag-include.yaml").read_text(), "mambo-rotor-lag-include")
    spec = sweep.load(root / "examples/uncertainty-sweep.yaml", cfg)
    result = sweep.run(cfg, spec, jobs=1)
    duration = base_of(cfg, spec)["simulation"]["duration"]  # with the sweep's set: values
    bands = montecarlo_bands(result.traces, sweep.regulated_states(cfg), duration, [r["case"] for r in result.rows])
    phi = bands.states.index("phi")
    half = bands.t >= bands.t[-1] / 2
    spread = np.degrees(bands.bands[-1, half, phi] - bands.bands[0, half, phi]).max()
    print(f"uncertainty: {len(bands.cases)} cases, {sum(r['pass'] for r in result.rows)} pass; phi 5-95 % band "
          f"(second half) at most {spread:.3g} deg wide")
    groups = {name: list(cfg.partition()[name].states) for name in ("altitude", "roll")}  # the mass and Jxx errors
    return plots.montecarlo_figure(bands, groups, title=cfg.name, varied=tuple(spec.names))


def lag_delay_figure(runs: dict) -> Figure:
    """mambo-200hz's weights on four plants (the include run is its own design): roll and pitch from the trim,
    and rotor 1's thrust."""
    fig = Figure(figsize=(8.0, 6.4), layout="constrained")
    ax = fig.subplots(3, 1, sharex=True)
    for label, sim in runs.items():
        err = sim.x - sim.x_ref
        ax[0].plot(sim.t, np.rad2deg(err[:, STATE_INDEX["phi"]]), lw=1.1, label=label)
        ax[1].plot(sim.t, np.rad2deg(err[:, STATE_INDEX["theta"]]), lw=1.1, label=label)
        thrust = sim.rotor_thrust[:, 0] if sim.rotor_thrust.size else motors.actuators_of(MAMBO).commands(sim.u)[:, 0]
        ax[2].plot(sim.t, thrust, lw=1.1, label=label)
    ax[0].set_ylabel("phi from trim [deg]")
    ax[1].set_ylabel("theta from trim [deg]")
    ax[2].set_ylabel("rotor 1 thrust [N]")
    ax[2].set_xlabel("time [s]")
    for a in ax:
        a.grid(True, alpha=0.3)
    ax[0].legend(fontsize=8, frameon=False, loc="upper right")
    ax[0].set_xlim(0.0, 1.5)
    fig.suptitle("mambo-200hz weights: instantaneous rotors, a 30 ms lag ignored or included, 5 ms of delay")
    return fig


def lag_delay_runs() -> dict:
    """mambo-200hz and the docs configs that add a rotor lag (ignored, included) or a delay."""
    folder = Path(__file__).resolve().parent / "configs"
    runs = {}
    for label, source in (("instantaneous rotors", "mambo-200hz"),
                          ("30 ms rotor lag, ignored by the design", folder / "mambo-rotor-lag.yaml"),
                          ("30 ms rotor lag, included in the design", folder / "mambo-rotor-lag-include.yaml"),
                          ("one sample (5 ms) of delay", folder / "mambo-delay.yaml")):
        sim = solve(config.load(str(source)).model_dump(mode="json"))[-1]
        runs[label] = sim
        err = np.rad2deg(np.abs(sim.x - sim.x_ref)[:, STATE_INDEX["phi"]])
        print(f"{label}: status {sim.status}; peak |phi - trim| after 0.2 s {err[sim.t > 0.2].max():.3g} deg")
    return runs


def mission_figure() -> Figure:
    """The bundled square mission: the path in the horizontal plane and the altitude."""
    setup, *_, sim = solve(config.load("square").model_dump(mode="json"))
    summary = pipeline.tracking_summary(setup, sim)
    error = summary["position_error"]
    print("square: reached " + ", ".join(f"{w['reached']:.3f} s" for w in summary["waypoints"])
          + f"; tracking error rms {error['rms']:.3g} m, peak {error['peak']:.3g} m")
    return plots.path_figure(sim, [w["position"] for w in summary["waypoints"]],
                             reached=[w["reached"] for w in summary["waypoints"]], tolerance=summary["tolerance"],
                             title="square")


def schedule_figure() -> Figure:
    """The bundled schedule's envelope: gains, frozen-point loops, trim attitude and rotor thrust against speed."""
    from quadctl.scheduling import schedule_of

    setup = setup_of(config.load("schedule"))
    sched = schedule_of(setup)
    print(f"schedule: envelope {sched.envelope} m/s, frozen-point checks passed {sched.checks.passed}, least damping "
          f"{np.nanmin(sched.checks.least_damping):.3g}")
    return plots.schedule_figure(sched, setup.actuators, title="schedule")


def transition_figure() -> Figure:
    """The bundled crazyflie-speed-schedule: hover to 20 m/s and back with the schedule and with the hover design."""
    from quadctl.transition import fly_transition, transition_lines

    result = fly_transition(setup_of(config.load("crazyflie-speed-schedule")))
    print("\n".join(transition_lines(result.summary)))
    print("fixed:", result.fixed.message)
    return plots.transition_figure(result, title="crazyflie-speed-schedule")


def main() -> int:
    if sys.argv[1:] == ["schedule"]:
        save(schedule_figure(), "schedule-envelope.png")
        return 0
    if sys.argv[1:] == ["transition"]:
        save(transition_figure(), "speed-schedule-transition.png")
        return 0
    if sys.argv[1:] == ["mission"]:
        save(mission_figure(), "square-mission.png")
        return 0
    if sys.argv[1:] == ["lqg"]:
        make_lqg_figure()
        return 0
    if sys.argv[1:] == ["lag"]:
        save(lag_delay_figure(lag_delay_runs()), "lag-and-delay.png")
        return 0
    cases = {}

    def demand(label, data):
        cfg, linear, _, des, loop, sim = solve(data)
        act = motors.actuators_of(MAMBO)
        room = motors.headroom(act, linear.u_trim)
        peak = np.abs(sim.u - linear.u_trim).max(axis=0)
        ratio = np.array([peak[j] / min(room[n]) for j, n in enumerate(INPUT_NAMES)])
        sat = motors.saturation_fraction(loop.actuators, sim.u) if loop.actuators is not None else None
        cases[label] = (ratio, sat)
        print(f"{label}: status {sim.status} ({sim.message}); peak |du| = "
              + ", ".join(f"{n} {peak[j]:.4g}" for j, n in enumerate(INPUT_NAMES))
              + "; / headroom = " + ", ".join(f"{r:.3g}" for r in ratio)
              + (f"; saturated {max(sat.values()) * 100:.3g} % (worst rotor)" if sat else ""))
        return cfg, linear, des, loop, sim

    demand("report, continuous", variant("forward"))
    demand("report weights, lqrd 200 Hz", variant("forward", controller={"rate": 200.0}))
    demand("report weights, lqrd 200 Hz, rotor limits", variant("forward", controller={"rate": 200.0}, motors={}))
    cfg, linear, des, loop, sim = demand("mambo-200hz", variant("mambo-200hz"))
    emulated = variant("forward", controller={"rate": 200.0, "design": "continuous"})
    print("report gains run at 200 Hz:", solve(emulated)[-1].message)
    save(peak_demand_figure(cases), "peak-demand.png")
    save(response_figure(sim, loop), "mambo-response.png")
    result = margins.all_margins(des, solve(variant("mambo-200hz"))[2], linear.A, linear.B)
    roll = next(m for m in result if m.loop == "roll" and m.model == "design")
    save(plots.margins_figure(roll, title="mambo-200hz"), "mambo-roll-margins.png")
    runs = {}
    for label, weights in (("plain LQR", {"Q": [4.0, 4.0], "R": [25.0]}),
                           ("LQI (integral of pD)", {"Q": [4.0, 4.0, 1.0], "R": [25.0], "integral": ["pD"]})):
        data = variant("mambo-200hz", trim={"velocity_ned": [0.0, 0.0, 0.0], "position_ned": [0.0, 0.0, -1.0],
                                            "yaw": 0.0})
        data["lqr"]["altitude"] = weights
        data["simulation"].update({"duration": 15.0, "initial_offset": {}, "noise": None,
                                   "plant": {"mass": 0.068 * 1.1}})
        runs[label] = solve(data)[-1]
        pd = STATE_INDEX["pD"]
        print(f"{label}: final pD error {(runs[label].x[-1, pd] - runs[label].x_ref[-1, pd]) * 1000:.4g} mm")
    save(lqi_figure(runs), "lqi-mass-error.png")
    save(lag_delay_figure(lag_delay_runs()), "lag-and-delay.png")
    save(uncertainty_figure(), "uncertainty-bands.png")
    save(gust_figure(gust_runs()), "crazyflie-gust.png")
    make_lqg_figure()
    save(mission_figure(), "square-mission.png")
    save(schedule_figure(), "schedule-envelope.png")
    save(transition_figure(), "speed-schedule-transition.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
