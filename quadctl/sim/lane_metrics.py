"""A run's metrics summed in the lanes as they step (``driver.c``'s ``qc_metric``), and read back.

A sweep needs of each run its metrics (:func:`quadctl.metrics.summarize_errors`) and tracking
(:func:`quadctl.run_summary.tracking_of`), not its trajectory: the lanes keep per case running sums
(:data:`PER_STATE`, :data:`SCALARS`: the slots of ``driver.c``) over the records a one-case run would keep (every
``stride``-th step and the last), from ``e = x - x_ref(t)``: first, last, lowest, highest and
largest ``|e|``, the record after the last one outside the settling band (exact: the band of the
largest ``|e|`` so far), for a run with noise the sums of the line through ``e`` over the run's last
tenth (with the settling record, whether it is noise-limited: :func:`quadctl.metrics.noise_limited`; with
turbulence that is read against the run's twin, the case without its random disturbances, which runs
in the lanes as another case: its settling record is the twin's verdict),
largest ``|u|``, the trapezoid sum of ``e' Q e + du' R du``, the position error's sums and the
waypoint times. Read back, they equal :func:`quadctl.metrics.summarize` of the
same records.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadctl.layout import INPUT_NAMES, N_INPUTS, N_STATES, STATE_NAMES
from quadctl.metrics import (
    ERROR_FLOOR,
    NOISE_TAIL,
    SETTLING_BAND,
    Disturbance,
    read_settling,
    trend_of_sums,
    twins_settled,
)
from quadctl.native.compile import C_LONG

PER_STATE = ("e0", "e_last", "e_min", "e_max", "peak", "settle", "tail_e", "tail_te", "tail_ee")
"""Per-state sums, each :data:`N_STATES` slots, in ``driver.c``'s order."""
SETTLE_NONE = -2.0
"""``settle``: no record was outside the band (settled at once)."""
SETTLE_PENDING = -1.0
"""``settle``: the last record was outside the band (never settled)."""
SCALARS = ("cost", "integrand_last", "t_last", "track_sq", "track_max", "records", "tail_n", "tail_t", "tail_tt")
"""The sums after the per-state ones and the :data:`N_INPUTS` input peaks; one slot per leg follows."""


@dataclass(frozen=True)
class MetricSpec:
    """What the lanes of one group sum: the states summarized (the regulated ones, and those the
    weights and the tracking error read), the nonzeros of ``Q`` (12 x 12) and ``R`` (4 x 4),
    row-major (the same in every case of the group), and, flying a reference, the position error
    and the number of mission legs whose waypoint times they find; with ``tail``, the line through
    each error over the run's last tenth (runs with noise: :func:`quadctl.metrics.tail_trend`).

    Attributes
    ----------
    states : tuple of int
        Indices of the states summarized, increasing (the others' sums read NaN).
    q_pairs, r_pairs : tuple of (int, int)
    track : bool
    legs : int
    tail : bool
    """

    states: tuple[int, ...]
    q_pairs: tuple[tuple[int, int], ...]
    r_pairs: tuple[tuple[int, int], ...]
    track: bool = False
    legs: int = 0
    tail: bool = False

    @classmethod
    def of(cls, regulated_states, Q, R, track: bool = False, legs: int = 0, tail: bool = False) -> MetricSpec:
        """The spec of the ``regulated_states`` (names) and weights with the sparsity of ``Q`` and ``R``."""
        q_pairs = tuple(zip(*(v.tolist() for v in np.nonzero(np.asarray(Q)))))
        states = {STATE_NAMES.index(name) for name in regulated_states} | {i for pair in q_pairs for i in pair}
        states |= {0, 1, 2} if track else set()
        return cls(tuple(sorted(states)), q_pairs, tuple(zip(*(v.tolist() for v in np.nonzero(np.asarray(R))))),
                   bool(track), int(legs), bool(tail))

    def header(self) -> np.ndarray:
        """``driver.c``'s ``mq``: the states, counts and index pairs (C long)."""

        q, r = np.array(self.q_pairs, dtype=int).reshape(-1, 2), np.array(self.r_pairs, dtype=int).reshape(-1, 2)
        return np.concatenate([[len(self.states)], self.states, [len(q)], q[:, 0], q[:, 1], [len(r)], r[:, 0],
                               r[:, 1], [self.legs, int(self.track), int(self.tail)]]).astype(C_LONG)

    @property
    def n_values(self) -> int:
        """Per-case values: ``u_trim``, the weights' nonzeros, the tolerance, 4 a leg."""
        return N_INPUTS + len(self.q_pairs) + len(self.r_pairs) + 1 + 4 * self.legs

    @property
    def n_sums(self) -> int:
        """Slots a case's sums take."""
        return len(PER_STATE) * N_STATES + N_INPUTS + len(SCALARS) + self.legs


def case_values(spec: MetricSpec, u_trim, Q, R, tolerance: float = 0.0, legs=()) -> np.ndarray:
    """One case's ``mv`` column: ``u_trim`` (4,), the entries of ``Q`` and ``R`` at the spec's
    pairs, the waypoint tolerance (m) and per leg its start (s) and waypoint (N, E, D m); or, given
    stacks (``u_trim`` (N, 4), ``Q`` (N, 12, 12), ``R`` (N, 4, 4)), N cases' rows at once (the same
    ``tolerance`` and ``legs`` for all)."""
    u = np.asarray(u_trim, dtype=float)
    Q, R = np.asarray(Q, dtype=float), np.asarray(R, dtype=float)
    q = np.array(spec.q_pairs, dtype=int).reshape(-1, 2)
    r = np.array(spec.r_pairs, dtype=int).reshape(-1, 2)
    lead = u.shape[:-1]
    parts = [u, Q[..., q[:, 0], q[:, 1]], R[..., r[:, 0], r[:, 1]], np.full((*lead, 1), float(tolerance))]
    parts += [np.broadcast_to(np.array([leg.start, *leg.position], dtype=float), (*lead, 4)) for leg in legs]
    return np.concatenate(parts, axis=-1)


def _slot(name: str, i: int = 0) -> int:
    if name in PER_STATE:
        return PER_STATE.index(name) * N_STATES + i
    if name == "u_max":
        return len(PER_STATE) * N_STATES + i
    if name == "reached":
        return len(PER_STATE) * N_STATES + N_INPUTS + len(SCALARS) + i
    return len(PER_STATE) * N_STATES + N_INPUTS + SCALARS.index(name)


def summaries(sums: np.ndarray, dt, regulated_states, status, noisy=False, twin=None) -> list[dict]:
    """The :func:`quadctl.metrics.summarize_errors` dicts of ``B`` runs from their lane sums (a state
    the lanes did not summarize has NaN for its ``peak_error`` and ``final_error``).

    Parameters
    ----------
    sums : (B, n_sums) ndarray
    dt : (B,) array_like
        s: the runs' steps (a settling record's time is ``dt`` times its step).
    regulated_states : iterable of str
    status : sequence of B str
    noisy : Disturbance or bool, or a sequence of B of them
        What randomly disturbed each run (:func:`quadctl.metrics.summarize`'s ``noisy``).
    twin : sequence of B dict or None, optional
        Each run's twin's settling times (:func:`quadctl.metrics.summarize_errors`'s ``twin``: None for a
        run without turbulence).
    """
    names, settling, late, overshoot, u_max, cost = _readings(sums, dt, regulated_states, status, noisy, twin)
    per = _per_state(np.asarray(sums, dtype=float))
    peaks, finals = per[:, PER_STATE.index("peak")].tolist(), per[:, PER_STATE.index("e_last")].tolist()
    return [{"settling_time": dict(zip(names, settling[b])), "overshoot": dict(zip(names, overshoot[b])),
             "noise_limited": [n for n, flag in zip(names, late[b]) if flag],
             "peak_error": dict(zip(STATE_NAMES, peaks[b])), "final_error": dict(zip(STATE_NAMES, finals[b])),
             "peak": dict(zip(INPUT_NAMES, u_max[b])), "cost": cost[b], "status": status[b]}
            for b in range(len(cost))]


def row_values(sums: np.ndarray, dt, regulated_states, status, noisy=False,
               twin=None) -> tuple[tuple[str, ...], list[list]]:
    """The metric columns of a sweep's rows (``settling_time.<state>``, ``overshoot.<state>``,
    ``peak.<input>``, ``cost``, ``status``) and its ``noise_limited`` states (a list) of ``B`` runs
    from their lane sums, flat: the values of :func:`summaries` (arguments alike) without a dict per
    metric. Returns (the column names, per run its values in that order)."""
    names, settling, late, overshoot, u_max, cost = _readings(sums, dt, regulated_states, status, noisy, twin)
    columns = (*(f"settling_time.{n}" for n in names), *(f"overshoot.{n}" for n in names),
               *(f"peak.{n}" for n in INPUT_NAMES), "cost", "status", "noise_limited")
    return columns, [[*settling[b], *overshoot[b], *u_max[b], cost[b], status[b],
                      [n for n, flag in zip(names, late[b]) if flag]] for b in range(len(cost))]


def _per_state(sums: np.ndarray) -> np.ndarray:
    """(B, len(PER_STATE), 12): the per-state sums of (B, n_sums) ``sums``."""
    return sums[:, :len(PER_STATE) * N_STATES].reshape(len(sums), len(PER_STATE), N_STATES)


def _readings(sums, dt, regulated_states, status, noisy=False, twin=None) -> tuple:
    """The regulated states' names (in state order) and, per run, their settling times, whether
    each is noise-limited and their overshoots, its input peaks (4) and cost, as :func:`summaries`
    reads them."""
    sums = np.asarray(sums, dtype=float)
    wanted = set(regulated_states)
    index = [i for i, name in enumerate(STATE_NAMES) if name in wanted]
    per = _per_state(sums)[:, :, index]
    e0, low, high, settle, last, peak = (per[:, PER_STATE.index(k)] for k in ("e0", "e_min", "e_max", "settle",
                                                                              "e_last", "peak"))
    with np.errstate(invalid="ignore", divide="ignore"):
        past = np.where(e0 > 0, -low, np.where(e0 < 0, high, 0.0))  # as summarize_errors
        over = np.maximum(0.0, past) / np.abs(e0) * 100.0
    # settled at the record after the last one outside the band; at once; never (or not a full run)
    settled_at = np.asarray(dt, dtype=float)[:, None] * np.maximum(settle, 0.0)
    settling = np.where(settle == SETTLE_NONE, 0.0, settled_at).astype(object)
    ok = (np.asarray(status) == "ok")[:, None]
    # noise-limited (quadctl.metrics.read_settling): still crossing the band in the run's last tenth, and the
    # band's edge within the noise about the error's trend there (turbulence: the twin's settling record)
    kind = np.broadcast_to(np.asarray(noisy, dtype=int), (len(sums),))
    noisy = kind != Disturbance.QUIET
    late = dropped = np.zeros(settle.shape, dtype=bool)
    if noisy.any():
        t_end = sums[:, _slot("t_last")][:, None]
        tail = [per[:, PER_STATE.index(k)] for k in ("tail_e", "tail_te", "tail_ee")]
        n, st, stt = (sums[:, _slot(k)][:, None] for k in ("tail_n", "tail_t", "tail_tt"))
        trend_end, spread = trend_of_sums(n, st, stt, *tail, t_end - (1.0 - NOISE_TAIL) * t_end)
        band = np.maximum(SETTLING_BAND * peak, ERROR_FLOOR)
        reported, late = read_settling(np.where(settle == SETTLE_PENDING, np.nan, settled_at), t_end, trend_end,
                                       spread, band, gusts=(kind == Disturbance.GUSTS)[:, None],
                                       twin_settled=twins_settled(twin, tuple(STATE_NAMES[i] for i in index), kind))
        disturbed = (settle != SETTLE_NONE) & ok & noisy[:, None]
        late, dropped = late & disturbed, np.isnan(reported) & disturbed
    settling[(settle == SETTLE_PENDING) | ~ok | late | dropped] = None
    overshoot = over.astype(object)
    overshoot[np.abs(e0) <= ERROR_FLOOR] = None
    u_max = sums[:, _slot("u_max"):_slot("u_max") + N_INPUTS].tolist()
    cost = [c if math.isfinite(c) else None for c in (sums[:, _slot("cost")] / 2).tolist()]
    return (tuple(STATE_NAMES[i] for i in index), settling.tolist(), late.tolist(), overshoot.tolist(), u_max,
            cost)


def tracking(sums: np.ndarray, legs: int) -> dict:
    """A run's position tracking error (m: ``rms``, ``peak``) and, for a mission, the time each of
    its ``legs`` waypoints was reached (s, or None), from its lane sums (n_sums,)."""
    n = sums[_slot("records")]
    reached = [None if r < 0 else float(r) for r in sums[_slot("reached"):_slot("reached") + legs]]
    return {"rms": float(math.sqrt(sums[_slot("track_sq")] / n)), "peak": float(sums[_slot("track_max")]),
            "reached": reached}
