"""Step-response metrics of a simulation run: settling, overshoot, peaks, cost.

All are computed on the error ``e = x - x_ref(t)`` of each state against the reference
the controller regulates to.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np

from quadctl.errors import ArgumentError
from quadctl.layout import INPUT_NAMES, N_STATES, STATE_NAMES

SETTLING_BAND = 0.02
"""Settled once ``|e|`` stays within 2 % of the state's largest ``|e|`` over the run."""
ERROR_FLOOR = 1e-9
"""Errors below this (state units) count as zero: a state that never moves settles at t = 0."""


MAX_SAMPLES = 20_000
"""Default of ``simulation.max_samples``: a run keeps at most this many samples (every
``stride``-th step, and always the last). 10 s at the report's auto step (290 000 steps) is then
a sample every 0.5 ms: finer than any settling time or plot needs, and 4.5 MB of sim.npz."""
NOISE_TAIL = 0.1
"""The last tenth of a run. In a run with noise or turbulence, a state whose error still crosses its
settling band there (settled after ``(1 - NOISE_TAIL) t_end``, or outside the band at the end) is
*noise-limited* when the disturbance is what keeps it crossing. With noise, when the band's edge lies
within the noise about the error's trend, where the trend is a least-squares line through the last
tenth, taken at the end, and the noise its spread about that line (:data:`NOISE_REACH` standard
deviations): an error whose trend ends farther outside the band than the noise reaches (still coming
down, a drift) never settled, noise or not; one whose trend ends farther inside than the noise reaches
is on its way in, and keeps its settling time. With turbulence, whose gusts last longer than the last
tenth (:class:`Disturbance`), when the run's twin, the same case without its random disturbances
(:func:`quadctl.pipeline.twin_of`), settled that state: else it never settled. A noise-limited
state has no settling time (None): when its error last crossed the band measures the disturbance, not
the response. A run without noise or turbulence keeps its settling times as they are."""
NOISE_LIMITED_WORDS = (f"with noise or turbulence, the error still crosses its {100 * SETTLING_BAND:g} % band in the "
                       "last tenth of the run, and the band's edge lies within the noise about the error's trend "
                       "(with turbulence: the same run without its random disturbances settles)")
"""What noise-limited means, as every table, reason and artifact says it (:data:`NOISE_TAIL`)."""


class Disturbance(IntEnum):
    """What randomly disturbs a run, as its settling is read (:func:`noise_limited`; true when not quiet).

    ``NOISE``: noise, sampled fast next to the run's last tenth, so the spread of the error about its
    trend there measures it. ``GUSTS``: turbulence, whose gusts last longer than a run's last tenth
    (Dryden's length scales over the airspeed: seconds), so that spread does not measure it: a late
    crossing, or an error outside its band at the end, is read against the run's twin, the same case
    without its random disturbances (noise-limited when the twin settled, else never settled), the
    same whatever the seed."""

    QUIET = 0
    NOISE = 1
    GUSTS = 2


NOISE_MIN_RECORDS = 10
"""Records in the last tenth below which the noise about the trend is not measured (a line through
one or two records fits them exactly): its spread is then taken as unbounded, so a late crossing
reads noise-limited, and no settling time is claimed that the records cannot support (a small
``simulation.max_samples``)."""
NOISE_REACH = 3.0
"""Standard deviations of the error about its trend that count as the reach of the noise (a
Gaussian's samples over a run's last tenth stay within about three)."""
OVERSHOOT_FLOOR = 1e-6
"""Excursions past zero below this fraction of the initial error are round-off: overshoot 0."""


def settling_time(t, err, noisy: int = Disturbance.QUIET, twin_settled: bool | None = None) -> float | None:
    """Time after which ``|err|`` stays within ``SETTLING_BAND`` of its peak (s); None if it never
    does, or, in a ``noisy`` run (a :class:`Disturbance`; True: noise), if its late settling is
    not read as one (:func:`read_settling`; ``twin_settled`` as there)."""
    settled = _settled(t, err)
    if not noisy or not len(t):
        return settled
    return disturbed_settling(t, err, settled, noisy, twin_settled)[0]


def limited_by_noise(t, err, settled: float | None, noisy: int = Disturbance.NOISE,
                     twin_settled: bool | None = None) -> bool:
    """Whether one error's settling is noise-limited (:func:`disturbed_settling`, arguments alike)."""
    return disturbed_settling(t, err, settled, noisy, twin_settled)[1]


def disturbed_settling(t, err, settled: float | None, noisy: int = Disturbance.NOISE,
                       twin_settled: bool | None = None) -> tuple[float | None, bool]:
    """:func:`read_settling` of one error ``err`` (r,) at times ``t`` (r,, s) that settled at ``settled``
    (s, None: never) in a run ``noisy`` disturbed (:class:`Disturbance`): its band from its largest
    ``|err|``, its trend over the last tenth (:func:`tail_trend`); with turbulence, ``twin_settled``
    (whether the run's twin settled this error). Returns (the settling time, s or None; whether it is
    noise-limited)."""
    t, err = np.asarray(t, dtype=float), np.asarray(err, dtype=float)
    band = max(SETTLING_BAND * float(np.abs(err).max()), ERROR_FLOOR)
    return read_settling(settled, float(t[-1]), *tail_trend(t, err), band, gusts=noisy == Disturbance.GUSTS,
                         twin_settled=twin_settled)


def noise_limited(settled: float | None, t_end: float, trend_end: float, spread: float, band: float,
                  gusts: bool = False, twin_settled: bool | None = None) -> bool:
    """Whether a settling time is noise-limited: :func:`read_settling`'s second value (arguments alike)."""
    return read_settling(settled, t_end, trend_end, spread, band, gusts, twin_settled)[1]


def read_settling(settled: float | None, t_end: float, trend_end: float, spread: float, band: float,
                  gusts: bool = False, twin_settled: bool | None = None) -> tuple:
    """The settling time a run with noise or turbulence reports, and whether it is noise-limited
    (:data:`NOISE_TAIL`), from the one it measured, ``settled`` (s, None: never), in a run that ended
    at ``t_end`` (s, from 0).

    A *late* crossing (``settled`` after ``(1 - NOISE_TAIL) t_end``, or never) is noise-limited when,
    with noise, the ``band``'s edge lies within :data:`NOISE_REACH` times the error's ``spread`` of
    where its trend over the last tenth ends (``trend_end``, :func:`tail_trend`); with ``gusts``
    (turbulence, :attr:`Disturbance.GUSTS`), whose spread the last tenth does not measure, when the
    run's twin settled (``twin_settled``: the same case without its random disturbances,
    :func:`quadctl.pipeline.twin_of`, has a settling time for this state). A noise-limited state has
    no settling time; with gusts, neither has a late one whose twin did not settle (it never
    settled); with noise, a late one that is not noise-limited keeps its time (a trend on its way
    in). Elementwise over arrays too (``settled`` then NaN for never).

    Returns
    -------
    (settling, limited)
        The settling time (s; None, or NaN in arrays: none) and whether it is noise-limited.

    Raises
    ------
    ArgumentError
        ``gusts`` without ``twin_settled``: a turbulent run is read against its twin (a ``ValueError``).
    """
    scalar = settled is None or np.ndim(settled) == 0
    settled = np.nan if settled is None else settled
    with np.errstate(invalid="ignore"):
        late = np.isnan(settled) | (settled > (1.0 - NOISE_TAIL) * np.asarray(t_end))
        within = np.abs(np.abs(trend_end) - band) <= NOISE_REACH * np.asarray(spread)
    dropped = np.zeros_like(late)
    if np.any(gusts):
        if twin_settled is None:
            raise ArgumentError("read_settling: a run with turbulence (gusts) is read against its twin, the same "
                             "case without its random disturbances: pass twin_settled (quadctl.pipeline.twin_of)")
        within = np.where(gusts, twin_settled, within)
        dropped = late & gusts
    limited = late & within
    out = np.where(limited | dropped, np.nan, settled)
    if scalar and np.ndim(limited) == 0:
        return (None if np.isnan(out) else float(out)), bool(limited)
    return out, limited


def twins_settled(twin, names, kind) -> np.ndarray | None:
    """Whether each of ``B`` runs' twin (:func:`quadctl.pipeline.twin_of`) settled each state of
    ``names``: ``(B, len(names))`` bool, for :func:`noise_limited`'s ``twin_settled``; None when no
    run has turbulence (``kind``, (B,) :class:`Disturbance`).

    ``twin``: per run, its twin's settling times (state name -> s, None: never; a state it does not
    name did not settle), None for a run without turbulence; one dict or None for all.

    Raises
    ------
    ArgumentError
        A run with turbulence and no twin (a ``ValueError``).
    """
    gusts = np.asarray(kind) == Disturbance.GUSTS
    if not gusts.any():
        return None
    twins = [twin] * len(gusts) if twin is None or isinstance(twin, dict) else list(twin)
    missing = [b for b, (g, times) in enumerate(zip(gusts, twins)) if g and times is None]
    if missing:
        raise ArgumentError(f"runs {missing} have turbulence and no twin: pass each one's twin's settling times "
                         "(quadctl.pipeline.twin_settling)")
    return np.array([[times is not None and times.get(name) is not None for name in names] for times in twins],
                    dtype=bool).reshape(len(gusts), len(names))


def settling_times(sim, states) -> dict:
    """Each of ``states``' settling time (s, None: never, or the run did not reach its end) in ``sim``
    (a SimResult: ``t``, ``x``, ``x_ref``, ``status``) as a run without random disturbances reads
    it: a twin's verdict (:func:`noise_limited`'s ``twin_settled``)."""
    err = sim.x - sim.x_ref
    return {name: _settled(sim.t, err[:, STATE_NAMES.index(name)]) if sim.status == "ok" else None
            for name in states}


def tail_trend(t, err) -> tuple:
    """The trend of ``err`` over the run's last tenth (:data:`NOISE_TAIL`, the samples at ``t >= (1 -
    NOISE_TAIL) t[-1]``): a least-squares line's value at the end and the RMS of ``err`` about it,
    in ``err``'s unit. ``t`` (..., r) and ``err`` (..., r) give arrays of the leading shape.

    The sums run left to right over the samples (``cumsum``), as the sweep's lanes add them as
    they step (:func:`trend_of_sums`), so the two agree to the last bit."""
    t, err = np.asarray(t, dtype=float), np.asarray(err, dtype=float)
    t_end = t[..., -1:]
    t0 = (1.0 - NOISE_TAIL) * t_end
    # only the samples from the first any run has in its tail: before it the sums add zeros, exactly
    first = int(np.argmax(t >= t0, axis=-1).min())
    t, err = t[..., first:], err[..., first:]
    tail = t >= t0
    tau = np.where(tail, t - t0, 0.0)
    e = np.where(tail, err, 0.0)

    def last(v):
        return np.cumsum(v, axis=-1)[..., -1]

    return trend_of_sums(last(tail.astype(float)), last(tau), last(tau * tau), last(e), last(tau * e),
                         last(e * e), t_end[..., 0] - t0[..., 0])


def trend_of_sums(n, st, stt, se, ste, see, tau_end) -> tuple:
    """(the line's value at ``tau_end``, the RMS about it) of the least-squares line ``e = a + b tau``
    through ``n`` samples with the sums of ``tau``, ``tau^2``, ``e``, ``tau e`` and ``e^2``
    (elementwise over arrays; one sample: the line is flat through it). Fewer than
    :data:`NOISE_MIN_RECORDS` samples: the RMS is ``inf`` (not measured)."""
    n, st, stt, se, ste, see = (np.asarray(v, dtype=float) for v in (n, st, stt, se, ste, see))
    with np.errstate(invalid="ignore", divide="ignore"):
        det = n * stt - st * st
        slope = np.where(det > 0, (n * ste - st * se) / np.where(det > 0, det, 1.0), 0.0)
        mean = se / np.maximum(n, 1.0)
        a = mean - slope * st / np.maximum(n, 1.0)
        ssr = np.maximum(see - a * se - slope * ste, 0.0)
        spread = np.where(n >= NOISE_MIN_RECORDS, np.sqrt(ssr / np.maximum(n, 1.0)), np.inf)
    trend = a + slope * np.asarray(tau_end, dtype=float)
    if np.ndim(trend) == 0:
        return float(trend), float(spread)
    return trend, spread


def _settled(t, err) -> float | None:
    """:func:`settling_time` without noise."""
    mag = np.abs(err)
    peak = float(mag.max()) if mag.size else 0.0
    if peak <= ERROR_FLOOR:
        return 0.0
    band = max(SETTLING_BAND * peak, ERROR_FLOOR)
    outside = np.nonzero(mag > band)[0]
    if outside.size == 0:
        return 0.0
    last = int(outside[-1])
    if last == len(t) - 1:
        return None
    return float(t[last + 1])


def overshoot(err) -> float | None:
    """Largest excursion past zero, in % of the initial error; None when the initial error is ~0."""
    e0 = float(err[0])
    if abs(e0) <= ERROR_FLOOR:
        return None
    excursion = max(0.0, float(np.max(-np.sign(e0) * err))) / abs(e0)
    return 0.0 if excursion < OVERSHOOT_FLOOR else excursion * 100.0


def lqr_cost(t, err, du, Q, R) -> float:
    """``integral of e' Q e + du' R du dt`` by the trapezoid rule."""
    integrand = np.einsum("ki,ij,kj->k", err, Q, err) + np.einsum("ki,ij,kj->k", du, R, du)
    return float(np.sum((integrand[1:] + integrand[:-1]) * np.diff(t)) / 2) if len(t) > 1 else 0.0


def summarize(sim, u_trim, Q, R, regulated_states, noisy: int = Disturbance.QUIET, twin: dict | None = None) -> dict:
    """Metrics of a run, as plain JSON-ready data.

    Parameters
    ----------
    sim : SimResult
    u_trim : (4,) array_like
    Q : (12, 12) array_like
    R : (4, 4) array_like
    regulated_states : iterable of str
        States that get settling and overshoot figures.
    noisy : Disturbance or bool
        What randomly disturbed the run (True: noise): its settling times may be noise-limited
        (:data:`NOISE_TAIL`).
    twin : dict of str -> float or None, optional
        With turbulence (required then): the settling times of the run's twin, the same case without
        its random disturbances (:func:`quadctl.pipeline.twin_settling`, :func:`settling_times`).

    Returns
    -------
    dict
        ``settling_time`` (s; None when the run did not reach its end, never settled or is
        noise-limited), ``overshoot`` (%), ``peak_error``, ``final_error`` per state;
        ``noise_limited``, the regulated states whose settling time is noise-limited (state order);
        ``peak`` per input (max |u|, N or N m); ``cost``; ``status``.
    """
    err = sim.x - sim.x_ref
    du = sim.u - np.asarray(u_trim)
    out: dict = {"settling_time": {}, "overshoot": {}, "peak_error": {}, "final_error": {}, "noise_limited": []}
    by_twin = twins_settled(twin, STATE_NAMES, [int(noisy)])
    for i, name in enumerate(STATE_NAMES):
        out["peak_error"][name] = float(np.abs(err[:, i]).max())
        out["final_error"][name] = float(err[-1, i])
        if name in regulated_states:  # a run cut short has not shown where it settles
            settled = _settled(sim.t, err[:, i]) if sim.status == "ok" else None
            if sim.status == "ok" and noisy:
                settled, limited = disturbed_settling(sim.t, err[:, i], settled, noisy,
                                                      None if by_twin is None else bool(by_twin[0, i]))
                if limited:
                    out["noise_limited"].append(name)
            out["settling_time"][name] = settled
            out["overshoot"][name] = overshoot(err[:, i])
    out["peak"] = {name: float(np.abs(sim.u[:, j]).max()) for j, name in enumerate(INPUT_NAMES)}
    cost = lqr_cost(sim.t, err, du, np.asarray(Q), np.asarray(R))
    out["cost"] = cost if math.isfinite(cost) else None
    out["status"] = sim.status
    return out


def summarize_run(t, x, u, x_ref, u_trim, Q, R, regulated_states, status, noisy: int = Disturbance.QUIET,
                  twin: dict | None = None) -> dict:
    """:func:`summarize` of one run, vectorized over the states (:func:`summarize_errors` of it).

    Same definitions and the same numbers (the cost integral to round-off: its quadratic forms
    are summed term by term over the nonzeros of ``Q`` and ``R`` instead of by ``einsum``),
    several times faster on 10 000 samples. Works on the state-major transposes, where every
    reduction runs along contiguous memory, and calls no BLAS (whose threads would fight the
    sweep's worker processes for the cores).

    Parameters
    ----------
    t : (r,) ndarray
        s.
    x : (r, 12) ndarray
        Any memory layout; ``x.T`` contiguous is fastest.
    x_ref : (r, 12) ndarray, or a pair ``(x_trim (12,), x_rate (12,))``
        The reference, or what makes it: ``x_trim + x_rate t`` (cheaper than building it).
    u : (r, 4) ndarray
    u_trim : (4,) ndarray
    Q : (12, 12) ndarray
    R : (4, 4) ndarray
    regulated_states : iterable of str
    status : str
    noisy : Disturbance or bool
    twin : dict, optional
        As :func:`summarize`'s.

    Returns
    -------
    dict
        The keys of :func:`quadctl.metrics.summarize`.
    """
    t = np.asarray(t, dtype=float)
    if isinstance(x_ref, tuple):
        err = np.empty((1, N_STATES, len(t)))
        error_into(err[0], t, np.asarray(x).T, *x_ref)
    else:
        err = (np.asarray(x).T - np.asarray(x_ref).T)[None]
    return summarize_errors(t[None], err, np.asarray(u).T[None], np.asarray(u_trim, dtype=float)[None],
                            np.asarray(Q, dtype=float)[None], np.asarray(R, dtype=float)[None], regulated_states,
                            [status], [noisy], [twin])[0]


def error_into(out: np.ndarray, t: np.ndarray, xT: np.ndarray, x_trim, x_rate) -> np.ndarray:
    """``x - x_ref(t)`` state-major into ``out`` (12, r), with ``x_ref(t) = x_trim + x_rate t``.

    ``xT`` (12, r) holds the states (any strides); ``t`` (r,) s.
    """
    np.subtract(xT, np.asarray(x_trim, dtype=float)[:, None], out=out)
    x_rate = np.asarray(x_rate, dtype=float)
    for i in np.nonzero(x_rate)[0]:
        out[i] -= x_rate[i] * t
    return out


def summarize_errors(t, err, u, u_trim, Q, R, regulated_states, status, noisy=False, twin=None) -> list[dict]:
    """:func:`summarize` of ``B`` runs of as many samples at once (a sweep's batches of cases).

    Each run's numbers are those :func:`summarize_run` gives it alone (every operation is
    elementwise or a reduction along one run's samples), so they do not depend on the batch.

    Parameters
    ----------
    t : (B, r) ndarray
        s.
    err : (B, 12, r) ndarray
        ``x - x_ref`` (state units), state-major (:func:`error_into`).
    u : (B, 4, r) ndarray
        Applied inputs, input-major.
    u_trim : (B, 4) ndarray
    Q : (B, 12, 12) ndarray
    R : (B, 4, 4) ndarray
        Same sparsity in every run (the cost sums the nonzeros of the first run's ``Q`` and ``R``).
    regulated_states : iterable of str
        States that get settling and overshoot figures (the same in every run).
    status : sequence of B str
    noisy : Disturbance or bool, or a sequence of B of them
        What randomly disturbed each run (:func:`summarize`'s ``noisy``).
    twin : sequence of B dict or None, optional
        Each run's twin's settling times (:func:`summarize`'s ``twin``; None: a run without turbulence).

    Returns
    -------
    list of B dict
        The keys of :func:`quadctl.metrics.summarize`.
    """
    B, _, n = err.shape
    du = u - u_trim[:, :, None]
    low, high = err.min(axis=2), err.max(axis=2)
    with np.errstate(invalid="ignore"):
        peak = np.abs(np.where(np.isnan(low) | np.isnan(high), np.nan, np.maximum(high, -low)))  # max |e|
    band = np.maximum(SETTLING_BAND * peak, ERROR_FLOOR)
    mag = np.abs(err)
    # outside the band, newest sample first (contiguous, so the search for the last one is fast)
    outside = mag[:, :, ::-1] > band[:, :, None]
    newest = np.argmax(outside, axis=2)
    last = n - 1 - newest  # the last sample outside (n - 1 when none is)
    run, state = np.indices(last.shape)
    # settled at once when the error is ~0 or never leaves the band; never when the last sample is out
    at_once = (peak <= ERROR_FLOOR) | ~outside[run, state, newest]
    never = outside[:, :, 0]
    settled_at = np.take_along_axis(t, np.minimum(last + 1, n - 1), axis=1)
    # noise-limited (noise_limited): a full run with noise whose error still crossed its band in the last
    # tenth, the band's edge within the noise about the error's trend there (turbulence: its twin settled)
    kind = np.broadcast_to(np.asarray(noisy, dtype=int), (B,))
    noisy = kind != Disturbance.QUIET
    late = dropped = np.zeros((B, err.shape[1]), dtype=bool)
    if noisy.any():
        trend_end, spread = tail_trend(t[:, None, :], err)
        reported, late = read_settling(np.where(never, np.nan, settled_at), t[:, -1:], trend_end, spread, band,
                                       gusts=(kind == Disturbance.GUSTS)[:, None],
                                       twin_settled=twins_settled(twin, STATE_NAMES, kind))
        disturbed = ~at_once & noisy[:, None] & (np.asarray(status) == "ok")[:, None]
        late, dropped = late & disturbed, np.isnan(reported) & disturbed
    at_once, never, settled_at = at_once.tolist(), (never | dropped).tolist(), settled_at.tolist()
    late = late.tolist()
    e0 = err[:, :, 0]
    # max(-sign(e0) e) without the product: -min(e) where e0 > 0, max(e) where e0 < 0 (exact)
    past = np.where(e0 > 0, -low, np.where(e0 < 0, high, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        over = (np.maximum(0.0, past) / np.abs(e0) * 100.0).tolist()
    no_initial = (np.abs(e0) <= ERROR_FLOOR).tolist()
    peaks, finals = peak.tolist(), err[:, :, -1].tolist()
    peak_u = np.abs(u).max(axis=2).tolist()
    with np.errstate(all="ignore"):
        integrand = _quadratic(err, Q, np.multiply(mag, mag, out=mag)) + _quadratic(du, R)
        cost = ((integrand[:, 1:] + integrand[:, :-1]) * np.diff(t, axis=1)).sum(axis=1) / 2 if n > 1 \
            else np.zeros(B)
    regulated = [(i, name) for i, name in enumerate(STATE_NAMES) if name in set(regulated_states)]
    out = []
    for b, c in enumerate(cost.tolist()):
        out.append({
            "settling_time": {name: None if never[b][i] or status[b] != "ok" or late[b][i] else 0.0 if at_once[b][i]
                              else settled_at[b][i] for i, name in regulated},
            "noise_limited": [name for i, name in regulated if late[b][i]],
            "overshoot": {name: None if no_initial[b][i] else over[b][i] for i, name in regulated},
            "peak_error": dict(zip(STATE_NAMES, peaks[b])), "final_error": dict(zip(STATE_NAMES, finals[b])),
            "peak": dict(zip(INPUT_NAMES, peak_u[b])), "cost": c if math.isfinite(c) else None,
            "status": status[b]})
    return out


def _quadratic(vT: np.ndarray, M: np.ndarray, squares: np.ndarray | None = None) -> np.ndarray:
    """``v_k^T M v_k`` for each sample ``k`` of each run: ``vT`` (B, n, r), ``M`` (B, n, n) -> (B, r),
    summed term by term over the nonzeros of the first run's ``M`` (row-major order). ``squares``,
    ``vT * vT`` if the caller has it, saves a product per diagonal term (the same numbers)."""
    acc = np.zeros((vT.shape[0], vT.shape[2]))
    term = np.empty_like(acc)
    for i, j in zip(*np.nonzero(M[0])):
        if i == j and squares is not None:
            np.multiply(squares[:, i], M[:, i, j][:, None], out=term)
        else:
            np.multiply(vT[:, i], vT[:, j], out=term)
            term *= M[:, i, j][:, None]
        acc += term
    return acc
