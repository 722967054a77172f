"""The batched path of a chunk: its cases designed together and flown in the SIMD lanes, read back as rows.

:func:`evaluate_batched` takes every config :func:`quadctl.pipeline.simulation_of` takes: the subsystem
designs of the whole chunk in batched Riccati solves (continuous, or discrete at the controller
rate with the ``lqrd`` weights), residual-checked, a case whose solve misses the check designed
again one by one (which names the reason); the coupled verdicts stacked; the simulations in the
SIMD lanes of :mod:`quadctl.sim`, :data:`~quadctl.sim.engine.LANES` cases per call, with the
rate and hold, motors and saturation, integrators and noise of each case; a case with turbulence
reads its late settling against its twin (:func:`quadctl.pipeline.twin_of`), flown in the lanes too.
A run's metrics are summed in its lane, or, where the lanes keep records, summarized together
(:class:`MetricsBatch`).
"""

from __future__ import annotations

import time

import numpy as np

from quadctl import pipeline, run_summary
from quadctl.errors import QuadctlError
from quadctl.layout import N_STATES
from quadctl.metrics import error_into, summarize_errors
from quadctl.sim.lane_metrics import row_values, tracking
from quadctl.sim.run import verdict
from quadctl.sweep import batched, lane_jobs
from quadctl.sweep.gates import tracking_columns
from quadctl.sweep.prepare import Prepared
from quadctl.sweep.rows import case_row, failed_row, mission_reason, resample_deviation

SEED_KEYS = (("simulation", "noise", "seed"), ("simulation", "wind", "turbulence", "seed"))
"""Key paths whose value a case's twin (:func:`quadctl.pipeline.twin_of`) does not read: the cases of a
chunk whose other values are the same share one twin (a Monte Carlo over turbulence seeds runs one)."""


def evaluate_batched(preps: list[Prepared], stats: dict, trace: tuple = (), seeds: tuple = ()) -> tuple[dict, dict]:
    """Design, assess and simulate cases together; (rows, Monte Carlo traces) by case number.

    A case with turbulence reads its late settling against its twin (:func:`quadctl.pipeline.twin_of`),
    simulated as one more case in the lanes, before the cases (its settling times are read with
    theirs); the cases whose parameters differ only in the columns ``seeds`` (their names,
    :data:`SEED_KEYS`) share one."""

    rows: dict[int, dict] = {}
    t0, c0 = time.perf_counter(), time.process_time()
    # rows read the extremes of each core, and take its gains to round-off
    designs = batched.design_all(preps, stats, any_order=True, compiled=True)
    stats["design_time"] += time.perf_counter() - t0
    stats["design_cpu"] += time.process_time() - c0
    live = []
    for prep, des in zip(preps, designs):
        if isinstance(des, str):
            rows[prep.index] = failed_row(prep.head, "design_failed", des)
        else:
            live.append((prep, des))
    twin_live, twin_of_case = _twins(live, seeds)
    exponential = bool(live) and live[0][0].setup.method == "etdrk4"  # a sweep runs one method
    jobs, twin_jobs = [], []
    made = lane_jobs.loops_of(live + twin_live, "etdrk4" if exponential else "rk4")
    for (prep, des), job in zip(live, made):
        if isinstance(job, str):
            row = case_row(prep.head, des.stable, des.core, None, None, 0, job, des.path)
            row["status"] = "step_refused"
            rows[prep.index] = row
        elif isinstance(job, QuadctlError):
            rows[prep.index] = failed_row(prep.head, "failed", str(job))
        else:
            jobs.append((prep, des, job))
    # a twin whose job is refused did not run: no state of it settled
    twin_jobs = [(prep, des, job) for (prep, des), job in zip(twin_live, made[len(live):])
                 if not isinstance(job, (str, QuadctlError))]
    t0 = time.perf_counter()
    twin_rows = _simulated(twin_jobs, stats, (), exponential, {})[0]
    twins = {case: {name: twin_rows.get(k, {}).get(f"settling_time.{name}") for name in twin_live[k][0].setup.regulated}
             for case, k in twin_of_case.items()}
    simulated, traces, tracked, reasons = _simulated(jobs, stats, trace, exponential, twins)
    rows.update(simulated)
    stats["simulate_time"] += time.perf_counter() - t0
    for index, columns in tracked.items():
        rows[index].update(columns)
    for index, reason in reasons.items():
        if reason:
            rows[index]["reason"] = reason
    return rows, traces


def _twins(live: list, seeds: tuple) -> tuple[list, dict]:
    """The twins (:func:`quadctl.pipeline.twin_of`) the cases with turbulence among ``live`` (``(prep,
    design)`` each) read their settling against: ``(prep, design)`` per twin (its ``index`` its place
    in the list) and the twin's place per case number; cases whose parameters but ``seeds`` are the
    same share one."""

    twins: list = []
    place: dict = {}  # the case's parameters but its seeds -> its twin's place
    of_case: dict[int, int] = {}
    for prep, des in live:
        twin = pipeline.twin_of(prep.setup)
        if twin is None:
            continue
        key = repr([(name, value) for name, value in prep.head.items() if name != "case" and name not in seeds])
        if key not in place:
            place[key] = len(twins)
            twins.append((Prepared(len(twins), {}, twin, prep.plant), des))
        of_case[prep.index] = place[key]
    return twins, of_case


def _simulated(jobs: list, stats: dict, trace: tuple, exponential: bool, twins: dict) -> tuple:
    """Run ``jobs`` (``(prep, design, job)`` each) in the lanes and read their rows: (rows, Monte Carlo
    traces, tracking columns, a mission's reason), each by ``prep.index``. ``twins``: per case with
    turbulence, its twin's settling times (:func:`quadctl.metrics.summarize`'s ``twin``)."""

    rows: dict[int, dict] = {}
    traces: dict[int, np.ndarray] = {}
    tracked: dict[int, dict] = {}  # case -> its tracking columns (cases that fly a reference)
    reasons: dict[int, str] = {}  # case -> why its mission failed (cases that fly waypoints and finish)
    batch = MetricsBatch()
    summed: list = []  # (prep, design, job, done, status, message, sums) of the runs summed in the lanes

    def recorded(prep, des, job, done, t, xs, us, backend):
        setup, linear = prep.setup, prep.plant.linear
        plan = job.plan
        x = xs[:, :len(linear.x_trim)]
        status, message = verdict(x, t, done, plan.n_steps, job.lo, job.hi)
        stats["steps"] += done
        stats["backend"].add(backend)
        x_ref = None
        if setup.reference is not None:  # the reference the lanes flew: their exogenous rows

            flown = setup.flown_reference
            rows_at = np.floor(t / job.exo_period + 1e-9).astype(np.int64)
            x_ref = flown.flown(flown.rows(rows_at, job.exo_period), t)[0]
            tracking = run_summary.tracking_of(setup.reference, t, x, x_ref)
            tracked[prep.index] = tracking_columns(tracking)
            if "waypoints" in tracking:
                reasons[prep.index] = mission_reason(setup, [w["reached"] for w in tracking["waypoints"]], status)
        for (p, d, j, steps, msg), summary in batch.add(t, x, us, setup, linear, status,
                                                         (prep, des, job, done, message), x_ref,
                                                         twins.get(prep.index)):
            rows[p.index] = case_row(p.head, d.stable, d.core, j.plan, summary, steps,
                                     "" if summary["status"] == "ok" else msg, d.path)
        if trace and status == "ok":
            x_ref = linear.x_trim + np.outer(t, linear.x_rate) if x_ref is None else x_ref
            traces[prep.index] = resample_deviation(t, x, x_ref, trace, setup.duration)

    if trace or exponential:  # a Monte Carlo keeps each trajectory; ETDRK4's lanes keep records
        for (prep, des, job), (done, t, xs, us), backend in batched.simulate_all(jobs):
            recorded(prep, des, job, done, t, xs, us, backend)
    else:
        for (prep, des, job), result, backend in batched.summarize_all(jobs):
            done = result[0]
            if result[-1] is None:  # a runner that keeps records (CasADi's VM)
                recorded(prep, des, job, *result[:4], backend)
                continue
            _, t_end, x_end, _, sums = result
            status, message = verdict(x_end[None, :N_STATES], np.array([t_end]), done, job.plan.n_steps, job.lo,
                                      job.hi)
            stats["steps"] += done
            stats["backend"].add(backend)
            summed.append((prep, des, job, done, status, message, sums.copy()))
    for (p, d, j, steps, msg), summary in batch.flush():
        rows[p.index] = case_row(p.head, d.stable, d.core, j.plan, summary, steps,
                                 "" if summary["status"] == "ok" else msg, d.path)
    _summed_rows(summed, rows, tracked, reasons, twins)
    return rows, traces, tracked, reasons


def _summed_rows(summed: list, rows: dict, tracked: dict, reasons: dict, twins: dict) -> None:
    """Rows (and tracking columns, and a mission's reason) of the runs summed in the lanes: ``(prep,
    design, job, done, status, message, sums)`` each, read back together per set of regulated states;
    ``twins`` as :func:`_simulated`'s."""

    groups: dict[tuple, list] = {}
    for item in summed:
        groups.setdefault(item[0].setup.regulated, []).append(item)
    for regulated, items in groups.items():
        names, out = row_values(np.stack([it[6] for it in items]), [it[2].plan.dt for it in items], regulated,
                                [it[4] for it in items], [pipeline.noisy(it[0].setup) for it in items],
                                [twins.get(it[0].index) for it in items])
        for (prep, des, job, done, status, message, sums), values in zip(items, out):
            rows[prep.index] = case_row(prep.head, des.stable, des, job.plan, None, done,
                                        "" if status == "ok" else message, des.path, flat=(names, values))
            ref = prep.setup.reference
            if ref is not None:
                got = tracking(sums, len(ref.legs))
                columns = {"position_error": {"rms": got["rms"], "peak": got["peak"]}}
                if ref.legs:
                    columns["waypoints"] = [{"reached": r} for r in got["reached"]]
                    reasons[prep.index] = mission_reason(prep.setup, got["reached"], status)
                tracked[prep.index] = tracking_columns(columns)


class MetricsBatch:
    """Runs gathered for :func:`quadctl.metrics.summarize_errors`: their errors are computed as the
    runner yields them (its arrays are overwritten by the next lanes) into one (B, 12, r) array,
    and summarized together when the batch is full (:meth:`size`) or the next run differs in
    samples, regulated states or weight sparsity (each run's numbers are those it gets alone)."""

    SIZE = 8
    """Runs a batch holds at most."""
    SAMPLES = 16_384
    """Samples a batch holds at most (runs times samples): past that the per-call cost saved is
    small and the batch's arrays outgrow the caches (measured: 2 000-sample runs gain 8 at a time,
    10 000-sample runs lose ~5 % even 2 at a time)."""

    def size(self, r: int) -> int:
        """Runs of ``r`` samples a batch holds."""
        return max(1, min(self.SIZE, self.SAMPLES // max(r, 1)))

    def __init__(self):
        self.key = None
        self.items: list = []

    def add(self, t, x, u, setup, linear, status, item, x_ref=None, twin: dict | None = None) -> list:
        """Gather one run (``x`` (r, 12), ``u`` (r, 4); ``x_ref`` (r, 12) the reference it flew, None:
        the trim moving at its velocity; ``twin``: with turbulence, its twin's settling times,
        :func:`quadctl.metrics.summarize`'s); returns the ``(item, summary)`` pairs of the
        batch this completes or closes (else none)."""
        key = (len(t), setup.regulated, (setup.Q_block != 0).tobytes(), (setup.R_block != 0).tobytes())
        done = self.flush() if key != self.key else []
        if not self.items:
            self.key = key
            r = len(t)
            self.capacity = self.size(r)
            self.t, self.err, self.u = np.empty((self.capacity, r)), np.empty((self.capacity, N_STATES, r)), \
                np.empty((self.capacity, u.shape[1], r))
            self.u_trim, self.Q, self.R, self.status, self.noisy, self.twin = [], [], [], [], [], []

        b = len(self.items)
        self.t[b] = t
        if x_ref is None:
            error_into(self.err[b], t, x.T, linear.x_trim, linear.x_rate)
        else:
            np.subtract(x.T, x_ref.T, out=self.err[b])
        self.u[b] = u.T
        self.u_trim.append(linear.u_trim)
        self.Q.append(setup.Q_block)
        self.R.append(setup.R_block)
        self.status.append(status)
        self.noisy.append(pipeline.noisy(setup))
        self.twin.append(twin)
        self.items.append(item)
        return done + (self.flush() if len(self.items) == self.capacity else [])

    def flush(self) -> list:
        """Summarize what is gathered: ``(item, summary)`` pairs."""

        if not self.items:
            return []
        B = len(self.items)
        summaries = summarize_errors(self.t[:B], self.err[:B], self.u[:B], np.array(self.u_trim), np.array(self.Q),
                                     np.array(self.R), self.key[1], self.status, self.noisy, self.twin)
        out = list(zip(self.items, summaries))
        self.items = []
        return out
