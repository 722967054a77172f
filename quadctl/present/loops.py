"""Margins as rows and sentences: classical, disk and delay margins of every loop, and how they
stand against the continuous LQR guarantee.

The guarantee (gain margin [1/2, inf), i.e. -6.02 dB to +inf, phase margin >= 60 deg) is a property
of continuous state feedback. A continuous design's loops are checked against it, loop by loop. A
discrete design's loops are sampled: sampling does not keep the guarantee, so they are not held to
it; that is said once (:func:`guarantee_sentence`), and the margins the sampled loops do have are
shown instead of a verdict against it.
"""

from __future__ import annotations

import re

from quadctl.present.cells import Mark, Table, db, gain_range_db, num

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
        rows.append((_label(m), m.model, f"{db(lo)} / {db(hi)}", at, num(m.phase_margin_deg, 3),
                     num(m.gain_crossover_freq, 3)))
    return Table("margins-table", f"Stability margins, each loop broken at its plant input; {domain(rate)}",
                 ("loop", "model", "GM dB", "at rad/s", "PM deg", "at rad/s "), tuple(rows),
                 caption="GM: lower / upper gain margin in dB (inf: no critical gain on that side), at the phase "
                         "crossovers; PM at the gain crossover; an unstable loop has no margin (0)", align="llrrrr")


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
        rows.append((_label(m), m.model, num(m.disk_alpha, 3), gain_range_db(d_lo, d_hi), num(m.disk_phase_deg, 3),
                     num(m.min_return_difference, 3), verdict))
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
    from quadctl.sim.cascade_margins import DELAY_SCAN

    cascade = any(m.model == "cascade" for m in margins)
    how = ("the least extra delay of the held plant input that makes the lifted loop unstable" if cascade
           else "PM / crossover frequency")
    never = f"none within {num(DELAY_SCAN[-1], 3)} samples" if cascade else "|L| never crosses 1"
    return Table(
        "delay-margin-table", f"Delay margins: the extra delay each loop tolerates ({how})",
        ("loop", "model", "configured delay (samples)", "delay margin ms", "samples"),
        tuple((_label(m), m.model, str(m.delay_samples),
               num(None if m.delay_margin is None else m.delay_margin * 1e3, 3), num(m.delay_margin_samples, 3))
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
    from quadctl.design.margins import THIN_GAIN_MARGIN_DB, THIN_PHASE_MARGIN_DEG, thin_loops

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
        which = f"{m.model}, {m.input}" if m.model == "cascade" else m.model
        parts.append(f"{m.loop} ({which}): {', '.join(said)}")
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
        return (f"The continuous LQR guarantee ({GUARANTEE}) is a property of continuous state feedback that "
                "sampling does not keep, so a discrete design's loops are not held to it; the margins shown are "
                "those the sampled loops have" + (f": {least}." if least else "."))
    met = sum(m.meets_lqr_guarantee for m in margins)
    return f"{met} of {len(margins)} loops meet the continuous LQR guarantee ({GUARANTEE})."


def summary(margins, discrete: bool) -> str:
    """One line for a report's summary: the loops' verdict, without repeating the reasons."""
    unstable = [f"{m.loop} ({m.model})" for m in margins if not m.stable]
    if discrete:
        least = least_margins(margins)
        text = f"{len(margins) - len(unstable)} of {len(margins)} sampled loops stable" + (
            f"; {least}" if least else "")
    else:
        met = sum(m.meets_lqr_guarantee for m in margins)
        text = f"{met} of {len(margins)} loops meet the continuous LQR guarantee"
    return text + (f"; unstable: {', '.join(unstable)}" if unstable else "")


def unstable_sentence(margins) -> Mark | None:
    unstable = [f"{m.loop} ({m.model})" for m in margins if not m.stable]
    return Mark(f"Unstable loop(s): {', '.join(unstable)}.", "fail") if unstable else None


def notes(margins) -> tuple[str, ...]:
    """Each loop's notes; a coupled loop's only where they differ from its design loop's (numbers aside)."""
    def shape(lines):
        return tuple(re.sub(r"[-+]?\d[\d.e+-]*", "#", n) for n in lines)

    design = {(m.loop, m.input): shape(m.notes) for m in margins if m.model == "design"}
    lines = [f"{m.loop} ({m.model}, {m.input}): {note}" for m in margins
             if not (m.model == "coupled" and design.get((m.loop, m.input)) == shape(m.notes)) for note in m.notes]
    if lines and any(m.model == "coupled" for m in margins):
        lines.append("coupled loops not listed read as their design loops (the same verdict and causes)")
    return tuple(lines)


def closed_loop_sentence(payload: dict) -> Mark:
    """margins.json's ``closed_loop``: the loop the vehicle has (lag, lag model, delay), stable or not."""
    cl = payload["closed_loop"]
    parts = []
    if payload.get("rotor_time_constant"):
        lag = payload.get("rotor_lag", "ignore")
        parts.append(f"a {payload['rotor_time_constant'] * 1e3:.4g} ms rotor lag ({lag}d by the design)")
    if payload.get("delay_samples"):
        parts.append(f"{payload['delay_samples']} sample{'s' if payload['delay_samples'] != 1 else ''} of delay")
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
