"""Margins as rows and sentences: classical, disk and delay margins of every loop, and how they
stand against the continuous LQR guarantee.

The guarantee (gain margin [1/2, inf), i.e. -6.02 dB to +inf, phase margin >= 60 deg) is a property
of continuous state feedback. A continuous design's loops are checked against it, loop by loop. A
discrete design's loops are sampled: sampling does not keep the guarantee, so they are not held to
it; that is said once (:func:`guarantee_sentence`), and the margins the sampled loops do have are
shown instead of a verdict against it.

Each loop's findings (:class:`quadctl.design.margin_findings.Finding`: values) are worded here, one function
per ``kind`` (:func:`note`).
"""

from __future__ import annotations

import re

from quadctl.design.margins import THIN_GAIN_MARGIN_DB, THIN_PHASE_MARGIN_DEG, thin_loops
from quadctl.present.cells import UNSTABLE, Mark, Table, db, gain_range_db, num
from quadctl.sim.cascade_margins import DELAY_SCAN

GUARANTEE = "gain margin [1/2, inf), i.e. -6.02 dB to +inf, phase margin >= 60 deg"
"""The continuous LQR guarantee, in words (:data:`quadctl.design.margins.LQR_GAIN_MARGIN_DB`,
``LQR_PHASE_MARGIN_DEG``)."""


def domain(rate) -> str:
    """How the loops are evaluated: ``sampled at 200 Hz (L(z), hold included)`` or ``continuous (L(s))``."""
    return f"sampled at {rate:g} Hz (L(z), hold included)" if rate else "continuous (L(s))"


def _label(m) -> str:
    return f"{m.loop} ({m.input})"


def classical_table(margins, rate=None) -> Table:
    rows = []
    for m in margins:
        lo, hi = m.gain_margin_db
        at = " / ".join(num(w, 3) for w in m.phase_crossover_freqs if w is not None) or "-"
        rows.append((_label(m), m.model, f"{db(lo)} / {db(hi)}" if m.stable else UNSTABLE, at,
                     num(m.phase_margin_deg, 3) if m.stable else UNSTABLE, num(m.gain_crossover_freq, 3)))
    return Table("margins-table", f"Stability margins, each loop broken at its plant input; {domain(rate)}",
                 ("loop", "model", "GM dB", "at rad/s", "PM deg", "at rad/s "), tuple(rows),
                 caption="GM: lower / upper gain margin in dB (inf: no critical gain on that side), at the phase "
                         "crossovers; PM at the gain crossover; an unstable loop has no margin", align="llrrrr")


def guarantee_verdict(m) -> Mark:
    """A continuous design's loop against the guarantee: met, short, or unstable."""
    if m.meets_lqr_guarantee:
        return Mark("met", "ok")
    return Mark("unstable", "fail") if not m.stable else Mark("short", "warning")


def disk_table(margins, discrete: bool) -> Table:
    """Disk margins; a continuous design's loops also against the guarantee, a discrete design's
    with the closed loop's verdict only (the guarantee is not theirs)."""
    rows = []
    for m in margins:
        d_lo, d_hi = m.disk_gain_db
        verdict = (Mark("stable", "ok") if m.stable else Mark("unstable", "fail")) if discrete else guarantee_verdict(m)
        disk = ((num(m.disk_alpha, 3), gain_range_db(d_lo, d_hi), num(m.disk_phase_deg, 3)) if m.stable
                else (UNSTABLE,) * 3)
        rows.append((_label(m), m.model, *disk, num(m.min_return_difference, 3), verdict))
    if discrete:
        return Table("disk-table", "Disk margins of the sampled loops",
                     ("loop", "model", "alpha", "disk GM dB", "disk PM deg", "min|1+L|", "closed loop"), tuple(rows),
                     caption="alpha: balanced disk margin; the loop tolerates gain and phase changes together "
                             "within disk GM and disk PM", align="llrrrrl")
    return Table("disk-table", "Disk margins and the continuous LQR guarantee",
                 ("loop", "model", "alpha", "disk GM dB", "disk PM deg", "min|1+L|", "guarantee"), tuple(rows),
                 caption="continuous LQR guarantees GM <= -6.02 / inf dB, PM >= 60 deg, |1+L| >= 1",
                 align="llrrrrl")


def delay_table(margins) -> Table:

    cascade = any(m.model == "cascade" for m in margins)
    how = ("the least extra delay of the held plant input that makes the lifted loop unstable" if cascade
           else "PM / crossover frequency")
    never = f"none within {num(DELAY_SCAN[-1], 3)} samples" if cascade else "|L| never crosses 1"
    return Table(
        "delay-margin-table", f"Delay margins: the extra delay each loop tolerates ({how})",
        ("loop", "model", "configured delay (samples)", "delay margin ms", "samples"),
        tuple((_label(m), m.model, str(m.delay_samples),
               num(None if m.delay_margin is None else m.delay_margin * 1e3, 3) if m.stable else UNSTABLE,
               num(m.delay_margin_samples, 3) if m.stable else UNSTABLE)
              for m in margins),
        caption=f"Beyond the configured delay (controller.delay), already in every loop; '-': {never}.",
        align="llrrr")


def least_margins(margins) -> str | None:
    """The smallest phase margin and the smallest disk margin of the stable loops, with their loops."""
    stable = [m for m in margins if m.stable]
    if not stable:
        return None
    pm = min(stable, key=lambda m: m.phase_margin_deg)
    disk = min(stable, key=lambda m: m.disk_alpha)
    return (f"least phase margin {num(pm.phase_margin_deg, 3)} deg ({pm.loop}, {pm.model}), least disk margin "
            f"{gain_range_db(*disk.disk_gain_db)} dB, {num(disk.disk_phase_deg, 3)} deg ({disk.loop}, {disk.model})")


def thin_sentence(margins, accepted: bool = False) -> str | None:
    """The loops below the classical requirement (6 dB, 30 deg: MIL-F-9490D), what is thin and the way out
    (or that the config accepts it: ``allow: [thin-margins]``); None when every stable loop meets it."""

    thin = thin_loops(margins)
    if not thin:
        return None
    parts = []
    for m in thin:
        lo, hi = m.gain_margin_db
        said = []
        if "gain" in m.thin:
            said.append(f"gain margin {db(lo)} / {db(hi)} dB")
        if "phase" in m.thin:
            said.append(f"phase margin {num(m.phase_margin_deg, 3)} deg")
        parts.append(f"{loop_name(m)}: {', '.join(said)}")
    way_out = ("lower the cascade's gains on that axis (controller.pid.values: its rate loop's kp and kd first)"
               if all(m.model == "cascade" for m in thin) else
               "slow the loop (larger lqr R), design with the rotors' lag (controller.rotor_lag: include) or at a "
               "faster controller.rate")
    return (f"thin margins, below {THIN_GAIN_MARGIN_DB:g} dB of gain margin or {THIN_PHASE_MARGIN_DEG:g} deg of phase "
            f"margin (MIL-F-9490D): {'; '.join(parts)}" + (" (accepted: allow: [thin-margins])" if accepted else
            f"; {way_out}; allow: [thin-margins] in the config accepts it"))


def guarantee_sentence(margins, discrete: bool) -> str:
    """What the margins are compared with, said once: the guarantee, or why a sampled design is not held to it."""
    if discrete:
        least = least_margins(margins)
        unstable = sum(not m.stable for m in margins)
        among = f" (of the stable loops; {unstable} unstable, with no margin)" if unstable else ""
        return (f"The continuous LQR guarantee ({GUARANTEE}) is a property of continuous state feedback that "
                "sampling does not keep, so a discrete design's loops are not held to it; the margins shown are "
                "those the sampled loops have" + (f": {least}{among}." if least else "."))
    met = sum(m.meets_lqr_guarantee for m in margins)
    return f"{met} of {len(margins)} loops meet the continuous LQR guarantee ({GUARANTEE})."


def summary(margins, discrete: bool) -> str:
    """One line for a report's summary: the loops' verdict, without repeating the reasons."""
    unstable = [loop_name(m) for m in margins if not m.stable]
    if discrete:
        least = least_margins(margins)
        text = f"{len(margins) - len(unstable)} of {len(margins)} sampled loops stable" + (
            f"; {least}" if least else "")
    else:
        met = sum(m.meets_lqr_guarantee for m in margins)
        text = f"{met} of {len(margins)} loops meet the continuous LQR guarantee"
    return text + (f"; unstable: {', '.join(unstable)}" if unstable else "")


def loop_name(m) -> str:
    """``roll (coupled)``; a cascade's loops, one per plant input, ``crazyflie (cascade, A)``."""
    return f"{m.loop} ({m.model}, {m.input})" if m.model == "cascade" else f"{m.loop} ({m.model})"


def unstable_sentence(margins) -> Mark | None:
    unstable = [loop_name(m) for m in margins if not m.stable]
    return Mark(f"Unstable loop(s): {', '.join(unstable)}.", "fail") if unstable else None


def notes(margins) -> tuple[str, ...]:
    """Each loop's notes (:func:`loop_notes`); a coupled loop's only where they differ from its design loop's
    (numbers aside)."""
    def shape(lines):
        return tuple(re.sub(r"[-+]?\d[\d.e+-]*", "#", n) for n in lines)

    said = {id(m): loop_notes(m) for m in margins}
    design = {(m.loop, m.input): shape(said[id(m)]) for m in margins if m.model == "design"}
    lines = [f"{m.loop} ({m.model}, {m.input}): {note}" for m in margins
             if not (m.model == "coupled" and design.get((m.loop, m.input)) == shape(said[id(m)]))
             for note in said[id(m)]]
    if lines and any(m.model == "coupled" for m in margins):
        lines.append("coupled loops not listed read as their design loops (the same verdict and causes)")
    return tuple(lines)


def loop_notes(m) -> tuple[str, ...]:
    """A loop's findings (:attr:`quadctl.design.margins.LoopMargins.findings`), a sentence each (:func:`note`)."""
    return tuple(note(f) for f in m.findings)


def note(finding) -> str:
    """One finding (:class:`quadctl.design.margin_findings.Finding`) in words: the function of its ``kind``."""
    return _WORDS[finding.kind](finding)


def unstable_note(f) -> str:
    lag = getattr(f, "ignored_rotor_lag_s", None)
    cause = (f"the design leaves out the rotors' {lag * 1e3:.3g} ms lag this loop has (controller.rotor_lag: "
             "include designs with it), or the gains are too high for this loop" if lag else
             "the gains are too high for this loop")
    return ("the closed loop is UNSTABLE: no margin; " + cause
            + (" at this rate" if f.sampled else "")
            + (f" with {f.delay_samples} samples of delay" if f.delay_samples else ""))


def hold_phase_note(f) -> str:
    return (f"sampled loop: the hold's half-sample delay is {f.hold_phase_deg:.3g} deg of phase at the "
            f"{f.crossover_rad_s:.4g} rad/s crossover")


def guarantee_met_note(f) -> str:
    return "meets the continuous LQR guarantee (gain margin -6 dB to inf, phase margin >= 60 deg)"


def guarantee_short_note(f) -> str:
    short = []
    if f.upper_gain_margin_db is not None:
        short.append(f"upper gain margin {f.upper_gain_margin_db:.3g} dB (guarantee: inf)")
    if f.lower_gain_margin_db is not None:
        short.append(f"lower gain margin {f.lower_gain_margin_db:.3g} dB (guarantee: <= -6.02 dB)")
    if f.phase_margin_deg is not None:
        short.append(f"phase margin {f.phase_margin_deg:.3g} deg (guarantee: >= 60 deg)")
    return "short of the continuous LQR guarantee: " + "; ".join(short)


def emulated_hold_note(f) -> str:
    lag = (f"; the hold's half-sample delay alone costs {f.hold_phase_deg:.3g} deg at the {f.crossover_rad_s:.4g} "
           "rad/s crossover" if f.crossover_rad_s else "")
    return (f"cause: continuous gains run at {f.rate_hz:g} Hz (sample and hold); the guarantee assumes "
            f"instantaneous continuous feedback{lag}")


def coupling_note(f) -> str:
    return "cause: couplings the decoupled design ignores (the guarantee holds on the subsystem it was designed on)"


def gyro_filter_note(f) -> str:
    return f"gyro filter ({f.gyro_filter}): {f.phase_lag_deg:.3g} deg of phase lag at the {f.crossover_rad_s:.4g} " \
           "rad/s crossover"


def saturation_note(f) -> str:
    text = (f"saturation: {f.input} has {f.headroom:.3g} {f.unit} of headroom from trim (other inputs at trim); the "
            f"disk margin keeps the loop stable (circle criterion) while the effective gain stays above "
            f"{f.disk_gain_min:.3g}, i.e. for commands up to {f.covered_command:.3g} {f.unit}")
    if f.initial_demand is not None:
        verdict = ("within it" if f.within else
                   "BEYOND it: the margins no longer guarantee stability during that saturation")
        text += f"; the initial offset asks for {f.initial_demand:.3g} {f.unit}, {verdict}"
    return text


def lqg_unstable_note(f) -> str:
    return f"LQG (Kalman filter on {' '.join(f.measured)}): the closed loop is UNSTABLE: no margin"


def lqg_estimator_note(f) -> str:
    return ("LQG: the LQR guarantee (gain margin -6 dB to inf, phase margin >= 60 deg) does not hold with an "
            f"estimator in the loop (Doyle 1978); Kalman filter ({f.filter_form}) on {' '.join(f.measured)}"
            + (f", the rates through the gyro filter ({f.gyro_filter}) in its model" if f.gyro_filter else "")
            + ("; meets it anyway" if f.meets_guarantee else ""))


def lqg_full_state_note(f) -> str:
    (lo, hi), (flo, fhi) = f.gain_margin_db, f.full_state_gain_margin_db
    return (f"against full-state feedback: phase margin {f.phase_margin_deg:.3g} deg "
            f"(full state {f.full_state_phase_margin_deg:.3g}), gain margin {lo:.3g} / {hi:.3g} dB "
            f"(full state {flo:.3g} / {fhi:.3g}), disk alpha {f.disk_alpha:.3g} "
            f"(full state {f.full_state_disk_alpha:.3g})")


def lqg_left_out_note(f) -> str:
    left = [what for what, on in (("the rotors' lag", f.rotor_lag),
                                  (f"{f.delay_samples} samples of delay", bool(f.delay_samples))) if on]
    return "not in this loop: " + " and ".join(left) + " (the full-state loops include them)"


_WORDS = {
    "unstable": unstable_note, "hold_phase": hold_phase_note, "guarantee_met": guarantee_met_note,
    "guarantee_short": guarantee_short_note, "cause_emulated_hold": emulated_hold_note,
    "cause_coupling": coupling_note, "gyro_filter_lag": gyro_filter_note, "saturation": saturation_note,
    "lqg_unstable": lqg_unstable_note, "lqg_estimator": lqg_estimator_note,
    "lqg_vs_full_state": lqg_full_state_note, "lqg_left_out": lqg_left_out_note,
}
"""Each finding's ``kind`` (:class:`quadctl.design.margin_findings.Finding`) and the function that words it."""


def closed_loop_sentence(payload: dict) -> Mark:
    """margins.json's ``closed_loop``: the loop the vehicle has (lag, lag model, delay, the Kalman filter),
    stable or not."""
    cl = payload["closed_loop"]
    parts = []
    if payload.get("rotor_time_constant"):
        lag = payload.get("rotor_lag", "ignore")
        parts.append(f"a {payload['rotor_time_constant'] * 1e3:.4g} ms rotor lag ({lag}d by the design)")
    if payload.get("delay_samples"):
        parts.append(f"{payload['delay_samples']} sample{'s' if payload['delay_samples'] != 1 else ''} of delay")
    if cl.get("estimator"):
        parts.append("the Kalman filter included (plant and estimator)")
    what = "closed loop" + (" with " + " and ".join(parts) if parts else "")
    size = (f"spectral radius {cl['spectral_radius']:.6g}" if cl["domain"] == "z" else
            f"slowest pole {cl['slowest_real_part']:.4g} rad/s")
    verdict = "stable" if cl["stable"] else "UNSTABLE"
    return Mark(f"{what}: {verdict} ({len(cl['eigenvalues'])} eigenvalues, {size})", "ok" if cl["stable"] else "fail")


def cascade_sentence(payload: dict) -> Mark:
    """margins.json of a PID cascade (:func:`quadctl.payloads.cascade_margins`): what its loops are, the
    lifted closed loop's verdict, and which margins are exact."""
    cl = payload["closed_loop"]
    n_att, n_pos = payload["samples_per_update"]["attitude"], payload["samples_per_update"]["position"]
    inner = "its rate and attitude loops at every sample" if n_att == 1 else \
        f"its rate loop at every sample, its attitude loop every {n_att}"
    rates = f"{inner}, its position and velocity loops every {n_pos} samples" if n_pos > 1 else \
        "every loop at every sample"
    verdict = "stable" if cl["stable"] else "UNSTABLE"
    n = payload.get("delay_samples", 0)
    delayed = (f", with its {n} sample{'s' if n != 1 else ''} of delay (controller.delay) in every loop before the "
               "break" if n else "")
    how = ("every margin exact: the gain margins from the lifted loop's poles, the phase and disk margins from "
           "its characteristic loci (a constant gain on the input is that gain on each sample of the frame, "
           "outer loops' aliases included), the delay margin the least extra delay of the held input that puts a "
           "pole of the lifted loop on the unit circle; frequencies at the base rate, of the strongest of the "
           "frame's aliases")
    return Mark(f"{payload['title']} at {payload['rate']:g} Hz, {rates}: each input's loop broken at the plant with "
                f"the whole cascade closed around it{delayed}, linearized about hover and lifted to its "
                f"{cl['sample_time'] * 1e3:.4g} ms frame (every hold exact). Closed loop {verdict} "
                f"({len(cl['eigenvalues'])} eigenvalues, spectral radius {cl['spectral_radius']:.6g}); {how}.",
                "ok" if cl["stable"] else "fail")
