"""Laws side by side (:mod:`quadctl.compare`): one table, metric by metric, and what the runs shared."""

from __future__ import annotations

from quadctl.compare import METRICS, Comparison
from quadctl.present.cells import Mark, Table, num


def table(comparison: Comparison) -> Table:
    """One row per metric, one column per law."""
    rows = []
    for name, unit, _ in METRICS:
        label = f"{name.replace('_', ' ')} [{unit}]" if unit != "1" else name.replace("_", " ")
        rows.append((label, *[_cell(law.metrics.get(name)) for law in comparison.laws]))
    rows.append(("rate [Hz]", *[num(law.rate) if law.rate else "continuous" for law in comparison.laws]))
    rows.append(("run", *[Mark(law.run.status, "ok" if law.run.status == "ok" else "fail")
                          for law in comparison.laws]))
    return Table("compare-table", f"{comparison.config}: laws side by side over {num(comparison.duration)} s",
                 ("metric", *[law.name for law in comparison.laws]), tuple(rows),
                 caption="the same plant, initial offset, reference, wind and noise for every law; cost on the "
                         "config's LQR weights; settling '-': never within 2 % of the peak position error")


def _cell(value) -> str:
    return "-" if value is None else num(value)


def disturbance_sentence(comparison: Comparison) -> Mark:
    """Whether every law read the same noise and wind (their rows' digests)."""
    seeds = []
    if comparison.noise_seed is not None:
        seeds.append(f"noise seed {comparison.noise_seed}")
    if comparison.wind_seed is not None:
        seeds.append(f"turbulence seed {comparison.wind_seed}")
    what = " and ".join(seeds) or "no random disturbances"
    if comparison.identical_disturbances:
        return Mark(f"Every law flew through the same disturbances ({what}; rows every "
                    f"{num(comparison.exo_period)} s, one digest {comparison.laws[0].disturbances[:12]}).", "ok")
    return Mark("The laws read different disturbance rows: the comparison is not like for like.", "fail")


def free_position_sentence(regulated: tuple[str, ...]) -> str | None:
    """A note when the LQR design leaves the horizontal position free (the PID cascades hold it)."""
    if "pN" in regulated and "pE" in regulated:
        return None
    return ("The LQR design leaves pN and pE free (its guidance subsystem is not regulated): its position "
            "error drifts where the PID cascades' position loops hold theirs.")
