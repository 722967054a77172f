/* quadctl loop driver: iterates the closed-loop functions of quadctl/sim/builder.py.
 *
 * No dynamics here. quadctl/native/compile.py prepends the sizes (QC_L lanes, QC_NX loop states,
 * QC_NP plant states, QC_NU inputs, QC_NE exogenous channels, QC_NC constants, QC_HELD) and the
 * functions emitted by quadctl/native/emit.py from the builder's CasADi functions:
 *   qc_law(X, t, c, e, u, X_sampled)   the control law (and the controller states' update)
 *   qc_step(X, t, dt, c, e, X_next, u, P) one RK4 step with continuous feedback   (QC_HELD == 0)
 *   qc_plant(X, u, dt, c, e, X_next, P)   one RK4 step under a held input        (QC_HELD == 1)
 * (P: what the step computes from dt and c alone, computed once a run by qc_step_pre / qc_plant_pre
 * into qc_step_nh / qc_plant_nh values a lane); or, for one case of ETDRK4 (QC_ETD), in their place
 *   qc_rem(X, t, c, e, N, u, P) / qc_rem(X, u, c, e, N, P)  the nonlinear remainder N = rhs - L X
 * whose stages qc_etd combines here (P: what it computes from c alone, by qc_rem_pre)
 *   qc_ref(t, c, e, x_ref)             the reference state the law regulates to (QC_NS states)
 * and the metrics' constants (QC_BAND, QC_FLOOR, QC_NOISE_TAIL: quadctl.metrics; QC_SETTLE_NONE, QC_SETTLE_PENDING:
 * quadctl.sim.lane_metrics).
 * Every argument is lane-major: element j of lane l is at [j * QC_L + l].
 *
 * One call runs up to QC_L cases ("lanes"), each with its own constants, step, step count and
 * recording stride. Per lane it records the steps whose absolute index kk = k0 + k is a multiple
 * of the stride (state before the step, input applied during it), stops at the first state
 * outside [lo, hi] (NaN included), and records the final state with the input the law gives
 * there (the held input between samples; the last applied input after leaving the bounds).
 * A lane that is done restarts from its x0 and runs on, discarded, until every lane is done
 * (a runaway lane would drag the vector math into its slow paths for huge or NaN arguments);
 * its final record uses what it kept when it finished (state, last applied input).
 *
 * With keep == 0 only the final record is written (row 0): a sweep that needs no trajectory.
 * With mq != NULL the lanes also summarize every record as it is made (quadctl/sim/lane_metrics.py
 * reads the sums): the error e = x - x_ref(t) of the QC_NS rigid-body states against the reference
 * the law regulates to (qc_ref), its first, last, lowest, highest and largest |e|, the settling
 * record, the largest |u|, the LQR cost by the trapezoid rule, the position tracking error and the
 * waypoints reached, and, for a run with noise, the sums of the line through the error over its last
 * tenth (quadctl.metrics.tail_trend), as quadctl.metrics and quadctl.run_summary.tracking_of define them. */
#include <limits.h>
#include <math.h>
#include <string.h>

#define QC_NE1 (QC_NE + 1)
/* per-lane parameters: lane_d[QC_LD][QC_L], lane_i[QC_LI][QC_L] */
#define QC_DT(l) lane_d[0 * QC_L + (l)]         /* RK4 step, s */
#define QC_PERIOD(l) lane_d[1 * QC_L + (l)]     /* exogenous sample period, s */
#define QC_K0(l) lane_i[0 * QC_L + (l)]         /* absolute index of the first step */
#define QC_N(l) lane_i[1 * QC_L + (l)]          /* steps to take */
#define QC_STRIDE(l) lane_i[2 * QC_L + (l)]     /* record every stride-th absolute step */
#define QC_HOLD(l) lane_i[3 * QC_L + (l)]       /* steps per controller sample (held loops) */
#define QC_EXO_FIRST(l) lane_i[4 * QC_L + (l)]  /* absolute index of the first exogenous row given */
#define QC_EXO_N(l) lane_i[5 * QC_L + (l)]      /* exogenous rows given */

/* the absolute exogenous sample of step kk: floor(kk dt / period), as quadctl.physics.noise counts */
static long qc_exo_sample(const double* lane_d, int l, long kk) {
  return (long)floor((double)kk * QC_DT(l) / QC_PERIOD(l) + 1e-9);
}

#if QC_REF >= 0
/* whether a tabulated reference row's second expansion is in force at t: from its split on, when it
 * has one (quadctl.physics.reference_rows.in_force, the same rule) */
static int qc_after(const double* row, double t) {
  const double split = row[QC_REF + QC_REF_HALF];
  return split > row[QC_REF] && t > split - QC_SPLIT_ROUNDOFF * (1 + fabs(split));
}
#endif

/* the exogenous row of absolute step kk (its sample, clipped to the rows given) as the loop functions
 * read it at time t (quadctl.sim.loop_layout.REFERENCE_LAYOUT): a reference's expansion in force at t, then
 * the one in force over the step from t (at its midpoint t + dt / 2). *held is what lane l holds in e
 * (-1: nothing), not copied again (a row lasts many steps); returns whether the row is split (the
 * expansions it gives change within it) */
static int qc_exo_row(const double* exo, long exo_rows, const double* lane_d, const long* lane_i,
                      int l, long kk, double t, double* e, long* held) {
  if (QC_NE == 0 || exo == NULL) return 0;
  long j = qc_exo_sample(lane_d, l, kk) - QC_EXO_FIRST(l);
  if (j > QC_EXO_N(l) - 1) j = QC_EXO_N(l) - 1;
  if (j < 0) j = 0;
  const double* row = exo + ((long)l * exo_rows + j) * QC_NE;
#if QC_REF >= 0
  const int split = row[QC_REF + QC_REF_HALF] > row[QC_REF];
  const int at = split && qc_after(row, t), over = split && qc_after(row, t + QC_DT(l) / 2);
  const long key = 4 * j + 2 * at + over;
#else
  const int split = 0;
  const long key = j;
#endif
  if (key == *held) return split;
  *held = key;
#if QC_REF >= 0
  for (int i = 0; i < QC_REF; ++i) e[i * QC_L + l] = row[i];
  const double* first = row + QC_REF + (at ? QC_REF_HALF : 0);
  const double* step = row + QC_REF + (over ? QC_REF_HALF : 0);
  for (int i = 0; i < QC_REF_HALF; ++i) {
    e[(QC_REF + i) * QC_L + l] = first[i];
    e[(QC_REF + QC_REF_HALF + i) * QC_L + l] = step[i];
  }
#else
  for (int i = 0; i < QC_NE; ++i) e[i * QC_L + l] = row[i];
#endif
  return split;
}

/* qc_exo_row of step kk (at t) in a run whose steps increase, and *until: the first later step whose
 * row is another (LONG_MAX: the rows given end first), so the steps before it need no row (a sample
 * lasts many steps), or the next step in a split row (its expansions change within it). Found from
 * an estimate, then by the same formula as each step's: the sample is nondecreasing in kk, so the
 * step found is exactly the first that changes it. */
static void qc_exo_next(const double* exo, long exo_rows, const double* lane_d, const long* lane_i,
                        int l, long kk, double t, double* e, long* held, long* until) {
  if (qc_exo_row(exo, exo_rows, lane_d, lane_i, l, kk, t, e, held)) {
    *until = kk + 1;
    return;
  }
  long sample = qc_exo_sample(lane_d, l, kk);
  if (QC_NE == 0 || exo == NULL || sample - QC_EXO_FIRST(l) >= QC_EXO_N(l) - 1) {
    *until = LONG_MAX;
    return;
  }
  double guess = ceil(((double)(sample + 1) - 1e-9) * QC_PERIOD(l) / QC_DT(l));
  if (!(guess < 0.5 * (double)LONG_MAX)) {  /* no later step in range (or NaN): look it up each step */
    *until = kk + 1;
    return;
  }
  long c = guess > (double)kk + 1.0 ? (long)guess : kk + 1;
  while (c - 1 > kk && qc_exo_sample(lane_d, l, c - 1) > sample) c -= 1;
  while (qc_exo_sample(lane_d, l, c) <= sample) c += 1;
  *until = c;
}

/* ---- the metrics of the records (mq != NULL); the slots of macc [QC_M(...)][QC_L] ---- */
#define QC_SLOT(k, i) (((k) * QC_NS + (i)) * QC_L)
enum { QC_E0, QC_ELAST, QC_EMIN, QC_EMAX, QC_PEAK, QC_SETTLE, QC_TAIL_E, QC_TAIL_TE, QC_TAIL_EE, QC_PER_STATE };
#define QC_UMAX (QC_PER_STATE * QC_NS)         /* QC_NU slots: largest |u| */
#define QC_COST (QC_UMAX + QC_NU)              /* trapezoid sum of (I_k + I_k-1)(t_k - t_k-1) */
#define QC_ILAST (QC_COST + 1)                 /* the last record's integrand */
#define QC_TLAST (QC_COST + 2)                 /* the last record's time, s */
#define QC_TRACK2 (QC_COST + 3)                /* sum of |p - p_ref|^2 over the records */
#define QC_TRACKMAX (QC_COST + 4)              /* largest |p - p_ref| */
#define QC_NREC (QC_COST + 5)                  /* records summarized */
#define QC_TAIL_N (QC_COST + 6)                /* records in the last tenth of a full run (t >= tail0) */
#define QC_TAIL_T (QC_COST + 7)                /* their sum of tau = t - tail0, s */
#define QC_TAIL_TT (QC_COST + 8)               /* their sum of tau^2 */
#define QC_REACHED (QC_COST + 9)               /* one slot per leg: the time it was reached, or -1 */

static double qc_nanmax(double a, double b) { return (b > a || b != b) ? b : a; }  /* numpy's max: NaN wins */
static double qc_nanmin(double a, double b) { return (b < a || b != b) ? b : a; }

/* mq: [n_s, s[n_s], n_q, q_i[n_q], q_j[n_q], n_r, r_i[n_r], r_j[n_r], n_legs, track, tail]: the states
 * summarized (every state the weights or the tracking error read among them), the weights'
 * nonzeros, the mission's legs, whether to sum the position error and the tail's line;
 * mv [rows][QC_L]: u_trim[QC_NU], q[n_q], r[n_r], tolerance, then per leg start, N, E, D. */
#define QC_MQ_Q(mq) ((mq) + 1 + (mq)[0])
#define QC_MQ_R(mq) (QC_MQ_Q(mq) + 1 + 2 * QC_MQ_Q(mq)[0])
#define QC_MQ_LEGS(mq) (QC_MQ_R(mq) + 1 + 2 * QC_MQ_R(mq)[0])
static void qc_metric_init(const long* mq, double* macc) {
  const long n_legs = QC_MQ_LEGS(mq)[0];
  for (int l = 0; l < QC_L; ++l) {
    for (int i = 0; i < QC_NS; ++i) {
      macc[QC_SLOT(QC_E0, i) + l] = NAN;  /* a state not summarized reads NaN */
      macc[QC_SLOT(QC_ELAST, i) + l] = NAN;
      macc[QC_SLOT(QC_EMIN, i) + l] = INFINITY;
      macc[QC_SLOT(QC_EMAX, i) + l] = -INFINITY;
      macc[QC_SLOT(QC_PEAK, i) + l] = NAN;  /* set at the final record */
      macc[QC_SLOT(QC_SETTLE, i) + l] = QC_SETTLE_NONE;
      macc[QC_SLOT(QC_TAIL_E, i) + l] = 0.0;
      macc[QC_SLOT(QC_TAIL_TE, i) + l] = 0.0;
      macc[QC_SLOT(QC_TAIL_EE, i) + l] = 0.0;
    }
    for (int j = 0; j < QC_NU; ++j) macc[(QC_UMAX + j) * QC_L + l] = 0.0;
    for (int k = QC_COST; k < QC_REACHED; ++k) macc[k * QC_L + l] = 0.0;
    for (long m = 0; m < n_legs; ++m) macc[(QC_REACHED + m) * QC_L + l] = -1.0;
  }
}

/* s[l] += the sum over k < n of v[i[k]][l] v[j[k]][l] w[k][l], term by term in k's order, four terms a
 * pass (each pass adds them left to right: the same sums, a quarter of the trips through memory) */
static void qc_quadratic(double* s, const double* v, const long* i, const long* j, const double* w, long n) {
#define QC_TERM(k) v[i[k] * QC_L + l] * v[j[k] * QC_L + l] * w[(k) * QC_L + l]
  long k = 0;
  for (; k + 4 <= n; k += 4)
#pragma omp simd
    for (int l = 0; l < QC_L; ++l) s[l] = s[l] + QC_TERM(k) + QC_TERM(k + 1) + QC_TERM(k + 2) + QC_TERM(k + 3);
  for (; k < n; ++k)
#pragma omp simd
    for (int l = 0; l < QC_L; ++l) s[l] += QC_TERM(k);
#undef QC_TERM
}

/* one record of the lanes with on[l] == 1.0 (else 0.0; all_on: every lane's is 1.0): absolute step
 * kk[l] (a whole number) at time t[l], state X, input U, reference R (each [.][QC_L]); final: the
 * run's last record (its error is kept); tail0[l]: where
 * the last tenth of the lane's full run starts (s). Every loop runs over the lanes, a lane that does
 * not record keeps its sums (so the compiler vectorizes them). */
static void qc_metric(const long* mq, const double* mv, double* macc, const double* on, long all_on,
                      const double* kk, const double* t, const double* X, const double* U, const double* R,
                      const double* tail0, int final) {
  const long ns = mq[0], *st = mq + 1;
  const long* mqq = QC_MQ_Q(mq), *mqr = QC_MQ_R(mq), *mql = QC_MQ_LEGS(mq);
  const long nq = mqq[0], *qi = mqq + 1, *qj = mqq + 1 + nq;
  const long nr = mqr[0], *ri = mqr + 1, *rj = mqr + 1 + nr;
  const long n_legs = mql[0], track = mql[1], tail = mql[2];
  const double* q = mv + QC_NU * QC_L;
  const double* r = q + nq * QC_L;
  const double* legs = r + nr * QC_L;  /* tolerance, then 4 rows a leg */
  double e[QC_NS * QC_L], du[QC_NU * QC_L], first[QC_L], iq[QC_L], ir[QC_L];
  double* n_rec = macc + QC_NREC * QC_L;
  long any_first = 0;
#pragma omp simd reduction(|:any_first)
  for (int l = 0; l < QC_L; ++l) {
    long f = on[l] != 0.0 && n_rec[l] == 0.0;
    first[l] = f ? 1.0 : 0.0;
    any_first |= f;
    iq[l] = 0.0;
    ir[l] = 0.0;
  }
  /* settling against the largest |e| so far (max(e_max, -e_min)): exact for the whole run, since the
     record that sets the final largest is outside its own band and every later record sees the final
     band */
  if (all_on && !final) {  /* a record before the last is inside the bounds: no NaN */
    for (long a = 0; a < ns; ++a) {
      const long i = st[a];
      double *e_min = macc + QC_SLOT(QC_EMIN, i), *e_max = macc + QC_SLOT(QC_EMAX, i);
      double* settle = macc + QC_SLOT(QC_SETTLE, i);
#pragma omp simd
      for (int l = 0; l < QC_L; ++l) {
        double v = X[i * QC_L + l] - R[i * QC_L + l], a = fabs(v), k = kk[l], s = settle[l];
        e[i * QC_L + l] = v;
        double lo = v < e_min[l] ? v : e_min[l], hi = v > e_max[l] ? v : e_max[l], p = hi > -lo ? hi : -lo;
        double band = QC_BAND * p > QC_FLOOR ? QC_BAND * p : QC_FLOOR;
        /* two selects, their operands loaded unconditionally: GCC emits a blend each, where one nested
           expression took a masked load, both comparisons and three blends */
        s = s == QC_SETTLE_PENDING ? k : s;
        e_min[l] = lo;
        e_max[l] = hi;
        settle[l] = a > band ? QC_SETTLE_PENDING : s;
      }
    }
  } else {
    for (long a = 0; a < ns; ++a) {
      const long i = st[a];
      double *e_min = macc + QC_SLOT(QC_EMIN, i), *e_max = macc + QC_SLOT(QC_EMAX, i);
      double* settle = macc + QC_SLOT(QC_SETTLE, i);
#pragma omp simd
      for (int l = 0; l < QC_L; ++l) {
        double v = X[i * QC_L + l] - R[i * QC_L + l], a = fabs(v), k = kk[l], s0 = settle[l];
        int o = on[l] != 0.0;
        e[i * QC_L + l] = v;
        double lo = qc_nanmin(e_min[l], v), hi = qc_nanmax(e_max[l], v), p = qc_nanmax(hi, -lo);
        double band = QC_BAND * p > QC_FLOOR ? QC_BAND * p : QC_FLOOR;
        double s = s0 == QC_SETTLE_PENDING ? k : s0;
        s = a > band ? QC_SETTLE_PENDING : s;
        e_min[l] = o ? lo : e_min[l];
        e_max[l] = o ? hi : e_max[l];
        settle[l] = o ? s : s0;
      }
    }
  }
  if (any_first)
    for (long a = 0; a < ns; ++a) {
      const long i = st[a];
      double* e0 = macc + QC_SLOT(QC_E0, i);
      for (int l = 0; l < QC_L; ++l) e0[l] = first[l] != 0.0 ? e[i * QC_L + l] : e0[l];
    }
  if (final)
    for (long a = 0; a < ns; ++a) {
      const long i = st[a];
      double *e_min = macc + QC_SLOT(QC_EMIN, i), *e_max = macc + QC_SLOT(QC_EMAX, i);
      double *e_last = macc + QC_SLOT(QC_ELAST, i), *peak = macc + QC_SLOT(QC_PEAK, i);
      for (int l = 0; l < QC_L; ++l) {
        e_last[l] = e[i * QC_L + l];
        peak[l] = qc_nanmax(e_max[l], -e_min[l]);
      }
    }
  for (int j = 0; j < QC_NU; ++j) {
    double* u_max = macc + (QC_UMAX + j) * QC_L;
#pragma omp simd
    for (int l = 0; l < QC_L; ++l) {
      du[j * QC_L + l] = U[j * QC_L + l] - mv[j * QC_L + l];
      u_max[l] = on[l] != 0.0 ? qc_nanmax(u_max[l], fabs(U[j * QC_L + l])) : u_max[l];
    }
  }
  /* e' Q e + du' R du, term by term over the nonzeros in row-major order (quadctl.metrics._quadratic) */
  qc_quadratic(iq, e, qi, qj, q, nq);
  qc_quadratic(ir, du, ri, rj, r, nr);
  double *cost = macc + QC_COST * QC_L, *i_last = macc + QC_ILAST * QC_L, *t_last = macc + QC_TLAST * QC_L;
#pragma omp simd
  for (int l = 0; l < QC_L; ++l) {
    double integrand = iq[l] + ir[l];
    int o = on[l] != 0.0;
    cost[l] = o && first[l] == 0.0 ? cost[l] + (integrand + i_last[l]) * (t[l] - t_last[l]) : cost[l];
    i_last[l] = o ? integrand : i_last[l];
    t_last[l] = o ? t[l] : t_last[l];
    n_rec[l] += on[l];
  }
  if (tail) {  /* the line through the error over the last tenth: left to right, as metrics.tail_trend adds */
    double in[QC_L], tau[QC_L];
    int any_in = 0;
    for (int l = 0; l < QC_L; ++l) {
      in[l] = on[l] != 0.0 && t[l] >= tail0[l] ? 1.0 : 0.0;
      tau[l] = in[l] != 0.0 ? t[l] - tail0[l] : 0.0;
      any_in |= in[l] != 0.0;
    }
    if (any_in) {
      double *tn = macc + QC_TAIL_N * QC_L, *tt = macc + QC_TAIL_T * QC_L, *ttt = macc + QC_TAIL_TT * QC_L;
#pragma omp simd
      for (int l = 0; l < QC_L; ++l) {
        tn[l] = tn[l] + in[l];
        tt[l] = tt[l] + tau[l];
        ttt[l] = ttt[l] + tau[l] * tau[l];
      }
      for (long a = 0; a < ns; ++a) {
        const long i = st[a];
        double *se = macc + QC_SLOT(QC_TAIL_E, i), *ste = macc + QC_SLOT(QC_TAIL_TE, i);
        double* see = macc + QC_SLOT(QC_TAIL_EE, i);
#pragma omp simd
        for (int l = 0; l < QC_L; ++l) {
          double v = in[l] != 0.0 ? e[i * QC_L + l] : 0.0;
          se[l] = se[l] + v;
          ste[l] = ste[l] + tau[l] * v;
          see[l] = see[l] + v * v;
        }
      }
    }
  }
  if (!track) return;
  double *sq = macc + QC_TRACK2 * QC_L, *top = macc + QC_TRACKMAX * QC_L;
#pragma omp simd
  for (int l = 0; l < QC_L; ++l) {
    double d = sqrt(e[0 * QC_L + l] * e[0 * QC_L + l] + e[1 * QC_L + l] * e[1 * QC_L + l]
                    + e[2 * QC_L + l] * e[2 * QC_L + l]);
    int o = on[l] != 0.0;
    sq[l] = o ? sq[l] + d * d : sq[l];
    top[l] = o ? qc_nanmax(top[l], d) : top[l];
  }
  /* quadctl.physics.trajectory.waypoint_times: a leg counts from its start and from the last leg reached
     before it; a leg reached (for now) clears the later legs' earlier hits */
  const double* tol = legs;
  for (long m = 0; m < n_legs; ++m) {
    const double* leg = legs + (1 + 4 * m) * QC_L;
    double* reached = macc + (QC_REACHED + m) * QC_L;
    double hit[QC_L];
#pragma omp simd
    for (int l = 0; l < QC_L; ++l) {
      double dx = X[0 * QC_L + l] - leg[1 * QC_L + l], dy = X[1 * QC_L + l] - leg[2 * QC_L + l],
             dz = X[2 * QC_L + l] - leg[3 * QC_L + l];
      int h = on[l] != 0.0 && reached[l] < 0.0 && t[l] >= leg[l] && sqrt(dx * dx + dy * dy + dz * dz) <= tol[l];
      hit[l] = h ? 1.0 : 0.0;
      reached[l] = h ? t[l] : reached[l];
    }
    for (long n = m + 1; n < n_legs; ++n) {
      double* later = macc + (QC_REACHED + n) * QC_L;
#pragma omp simd
      for (int l = 0; l < QC_L; ++l) later[l] = hit[l] != 0.0 && later[l] < t[l] ? -1.0 : later[l];
    }
  }
}

#if QC_ETD
/* One case (QC_L == 1) of quadctl.sim.builder.etdrk4: its stages' remainders by qc_rem, their
 * matrix-vector products here, dense, each a column at a time over the rows (the order of CasADi's
 * product: the same sums, its structural zeros adding zeros), the sums in the order etdrk4 writes them. The
 * matrices are the PHI_LAYOUT blocks that end c, column-major. */
#define QC_PHI (QC_NC - 12 * QC_NX * QC_NX)
enum { QC_LIN, QC_A21, QC_A31, QC_A32, QC_A41, QC_A42, QC_A51, QC_A52, QC_A54, QC_B1, QC_B4, QC_B5 };
static void qc_mv(const double* restrict c, int k, const double* restrict v, double* restrict y) {
  const double* M = c + QC_PHI + (long)k * QC_NX * QC_NX;
  for (int i = 0; i < QC_NX; ++i) y[i] = M[i] * v[0];
  for (int j = 1; j < QC_NX; ++j)
    for (int i = 0; i < QC_NX; ++i) y[i] = y[i] + M[j * QC_NX + i] * v[j];
}
#if QC_HELD
#define QC_REM(Y, ts, N, U) qc_rem(Y, U, c, e, N, P)
#else
#define QC_REM(Y, ts, N, U) qc_rem(Y, ts, c, e, N, U, P)
#endif
/* X_next = one step h from X at t; u: the input at X (continuous feedback), or the held one */
static void qc_etd(const double* X, const double* t, const double* h, const double* c, const double* e,
                   double* XN, double* u, const double* P) {
  double n1[QC_NX], n2[QC_NX], n3[QC_NX], n4[QC_NX], n5[QC_NX], n23[QC_NX], LX[QC_NX];
  double a[QC_NX], b[QC_NX], d[QC_NX], Y[QC_NX], uu[QC_NU];
  double th[1] = {t[0] + h[0] / 2}, tf[1] = {t[0] + h[0]};
  (void)uu; (void)th; (void)tf;
  qc_mv(c, QC_LIN, X, LX);
  /* G(Y) = N(Y) + L X: the stages about the step's start X (etdrk4) */
#define QC_G(N) for (int i = 0; i < QC_NX; ++i) N[i] = N[i] + LX[i]
  QC_REM(X, t, n1, u);
  QC_G(n1);
  qc_mv(c, QC_A21, n1, a);
  for (int i = 0; i < QC_NX; ++i) Y[i] = X[i] + a[i];
#if QC_HELD
#define QC_U u
#else
#define QC_U uu
#endif
  QC_REM(Y, th, n2, QC_U);
  QC_G(n2);
  qc_mv(c, QC_A31, n1, a);
  qc_mv(c, QC_A32, n2, b);
  for (int i = 0; i < QC_NX; ++i) Y[i] = X[i] + a[i] + b[i];
  QC_REM(Y, th, n3, QC_U);
  QC_G(n3);
  for (int i = 0; i < QC_NX; ++i) n23[i] = n2[i] + n3[i];
  qc_mv(c, QC_A41, n1, a);
  qc_mv(c, QC_A42, n23, b);
  for (int i = 0; i < QC_NX; ++i) Y[i] = X[i] + a[i] + b[i];
  QC_REM(Y, tf, n4, QC_U);
  QC_G(n4);
  qc_mv(c, QC_A51, n1, a);
  qc_mv(c, QC_A52, n23, b);
  qc_mv(c, QC_A54, n4, d);
  for (int i = 0; i < QC_NX; ++i) Y[i] = X[i] + a[i] + b[i] + d[i];
  QC_REM(Y, th, n5, QC_U);
  QC_G(n5);
  qc_mv(c, QC_B1, n1, a);
  qc_mv(c, QC_B4, n4, b);
  qc_mv(c, QC_B5, n5, d);
  for (int i = 0; i < QC_NX; ++i) XN[i] = X[i] + a[i] + b[i] + d[i];
#undef QC_G
#undef QC_U
}
#endif

static long qc_mod(long a, long m) { return m > 0 ? ((a % m) + m) % m : 0; }

/* x0, lo, hi: [QC_NX][QC_L]; c: [QC_NC][QC_L]; exo: [QC_L][exo_rows][QC_NE] (or NULL).
 * Records into xs [QC_L][QC_NX][rows_max], us [QC_L][QC_NU][rows_max], ks [QC_L][rows_max];
 * n_rec[l]: rows written; done[l]: steps completed (n when every state stayed in bounds).
 * keep: store every record (else only the final one, in row 0); mq, mv, macc: the metrics (or
 * mq == NULL: none), see qc_metric; row0 (or NULL: 0): each lane's first row. */
static void qc_run_at(const double* x0, const double* c, const double* lane_d, const long* lane_i,
                      const double* lo, const double* hi, const double* exo, long exo_rows, long rows_max,
                      double* xs, double* us, long* ks, long* n_rec, long* done,
                      long keep, const long* mq, const double* mv, double* macc, const long* row0) {
  /* the state before and after a step: two buffers that swap roles after each step (no copy) */
  double XA[QC_NX * QC_L], XB[QC_NX * QC_L], XF[QC_NX * QC_L], XS[QC_NX * QC_L];
  double *X = XA, *XN = XB;
  double U[QC_NU * QC_L], UH[QC_NU * QC_L], UF[QC_NU * QC_L], T[QC_L], DT[QC_L], E[QC_NE1 * QC_L];
  double XR[QC_NS * QC_L], TAIL0[QC_L], KD[QC_L], ON[QC_L];
  long rec_in[QC_L], hold_in[QC_L], rows[QC_L], held[QC_L], until[QC_L];
  long active[QC_L];  /* as wide as rec_in, so the lanes' per-step tests vectorize together */
  int inb[QC_L], n_active = 0;
  long first_end = LONG_MAX;  /* the fewest steps a lane takes: no lane finishes on a step before it */
  if (mq) qc_metric_init(mq, macc);
#if QC_ETD
  double P[qc_rem_nh * QC_L];
#elif QC_HELD
  double P[qc_plant_nh * QC_L];
#else
  double P[qc_step_nh * QC_L];
#endif
  memcpy(X, x0, sizeof XA);
  memcpy(XF, x0, sizeof XF);
  memset(E, 0, sizeof E);
  memset(U, 0, sizeof U);
  memset(UH, 0, sizeof UH);
  memset(UF, 0, sizeof UF);
  (void)XS; (void)hold_in;
  for (int l = 0; l < QC_L; ++l) {
    active[l] = QC_N(l) > 0; inb[l] = 1; rows[l] = row0 ? row0[l] : 0; done[l] = 0; held[l] = -1; until[l] = LONG_MIN;
    rec_in[l] = qc_mod(-QC_K0(l), QC_STRIDE(l));   /* steps until the next recorded one */
    hold_in[l] = qc_mod(-QC_K0(l), QC_HOLD(l));    /* steps until the next controller sample */
    DT[l] = QC_DT(l);
    KD[l] = (double)QC_K0(l);  /* the absolute step K0 + k, counted in a double (exact below 2^53) */
    TAIL0[l] = (1.0 - QC_NOISE_TAIL) * (QC_DT(l) * (double)(QC_K0(l) + QC_N(l)));  /* metrics.tail_trend's t0 */
    n_active += active[l];
    if (QC_N(l) < first_end) first_end = QC_N(l);
  }
#if QC_ETD && QC_HELD
  qc_rem_pre(X, U, c, E, P);
#elif QC_ETD
  qc_rem_pre(X, T, c, E, P);
#elif QC_HELD
  qc_plant_pre(X, U, DT, c, E, P);
#else
  qc_step_pre(X, T, DT, c, E, P);
#endif
  for (long k = 0; n_active > 0; ++k) {
    long rec = 0;
#pragma omp simd reduction(|:rec)
    for (int l = 0; l < QC_L; ++l) {
      T[l] = DT[l] * KD[l];  /* QC_DT(l) * (double)(QC_K0(l) + k), the same product */
      rec |= active[l] & (rec_in[l] == 0);
    }
    if (QC_NE > 0 && exo != NULL)  /* (without exogenous rows qc_exo_next does nothing) */
      for (int l = 0; l < QC_L; ++l)
        if (QC_K0(l) + k >= until[l])
          qc_exo_next(exo, exo_rows, lane_d, lane_i, l, QC_K0(l) + k, T[l], E, held + l, until + l);
#if QC_HELD
    int sample = 0;
    for (int l = 0; l < QC_L; ++l) sample |= hold_in[l] == 0;
    if (sample) {
      qc_law(X, T, c, E, U, XS);
      for (int l = 0; l < QC_L; ++l) {
        if (hold_in[l] != 0) continue;
        for (int i = 0; i < QC_NU; ++i) UH[i * QC_L + l] = U[i * QC_L + l];
      }
    }
    const double* UA = UH;
#elif QC_ETD
    qc_etd(X, T, DT, c, E, XN, U, P);
    const double* UA = U;
#else
    qc_step(X, T, DT, c, E, XN, U, P);
    const double* UA = U;
#endif
    if (rec && mq) {
      long all_on = 1;
#pragma omp simd reduction(&:all_on)
      for (int l = 0; l < QC_L; ++l) {
        long o = active[l] & (rec_in[l] == 0);
        ON[l] = o ? 1.0 : 0.0;
        all_on &= o;
      }
      qc_ref(T, c, E, XR);
      qc_metric(mq, mv, macc, ON, all_on, KD, T, X, UA, XR, TAIL0, 0);
    }
    if (rec && keep) {
      for (int l = 0; l < QC_L; ++l) {
        if (!active[l] || rec_in[l] != 0) continue;
        double* xr = xs + (long)l * QC_NX * rows_max + rows[l];
        double* ur = us + (long)l * QC_NU * rows_max + rows[l];
        for (int i = 0; i < QC_NX; ++i) xr[i * rows_max] = X[i * QC_L + l];
        for (int i = 0; i < QC_NU; ++i) ur[i * rows_max] = UA[i * QC_L + l];
        ks[(long)l * rows_max + rows[l]] = QC_K0(l) + k;
        rows[l]++;
      }
    }
#if QC_HELD
    if (sample) {  /* the sampled controller states, then the plant under the held input */
      for (int l = 0; l < QC_L; ++l) {
        if (hold_in[l] != 0) continue;
        for (int i = QC_NP; i < QC_NX; ++i) X[i * QC_L + l] = XS[i * QC_L + l];
      }
    }
#if QC_ETD
    qc_etd(X, T, DT, c, E, XN, UH, P);
#else
    qc_plant(X, UH, DT, c, E, XN, P);
#endif
#endif
    /* bounds: each lane's own flag, OR-ed over the states (NaN compares false, so it counts as
       out); integer ORs, so the lanes vectorize without a lane's verdict mixing with another's; as
       wide as a double, so a lane's flag is its comparison's mask as it is (no packing each step) */
    long long out[QC_L], any_out = 0;
#pragma omp simd reduction(|:any_out)
    for (int l = 0; l < QC_L; ++l) {  /* the states inside: a lane's flag stays in a register */
      long long o = 0;
#pragma GCC unroll 64
      for (int i = 0; i < QC_NX; ++i) {
        double v = XN[i * QC_L + l];
        o |= !(v >= lo[i * QC_L + l]) | !(v <= hi[i * QC_L + l]);
      }
      out[l] = o;
      any_out |= o;
    }
    double* X_next = X;  /* the step's result becomes the state; the old state's buffer takes the next */
    X = XN;
    XN = X_next;
#pragma omp simd
    for (int l = 0; l < QC_L; ++l) {
      rec_in[l] = rec_in[l] == 0 ? QC_STRIDE(l) - 1 : rec_in[l] - 1;
      hold_in[l] = hold_in[l] == 0 ? QC_HOLD(l) - 1 : hold_in[l] - 1;
      KD[l] = KD[l] + 1.0;
    }
    /* the common step: every lane runs, stays in bounds and has steps left (nothing below to do) */
    if (n_active == QC_L && !any_out && k + 1 < first_end) continue;
    for (int l = 0; l < QC_L; ++l) {
      if (!active[l]) {  /* a lane done (or with no steps) restarts each step from x0: a lane that is
                            not run never drifts to inf or NaN beside the lanes that are */
        for (int i = 0; i < QC_NX; ++i) X[i * QC_L + l] = x0[i * QC_L + l];
        continue;
      }
      if (out[l] != 0 || k + 1 == QC_N(l)) {
        active[l] = 0; n_active--;
        done[l] = k + 1;
        inb[l] = out[l] == 0;
        /* the input applied during its last step: the restarted lane overwrites UH */
        for (int i = 0; i < QC_NU; ++i) UF[i * QC_L + l] = UA[i * QC_L + l];
        for (int i = 0; i < QC_NX; ++i) {
          XF[i * QC_L + l] = X[i * QC_L + l];
          X[i * QC_L + l] = x0[i * QC_L + l];
        }
      }
    }
  }
  /* the final state, with the input the law gives there (held between samples; past the
     bounds, the last applied one) */
  for (int l = 0; l < QC_L; ++l) {
    long last = QC_K0(l) + done[l];
    T[l] = QC_DT(l) * (double)last;
    qc_exo_row(exo, exo_rows, lane_d, lane_i, l, last > 0 ? last - 1 : 0, T[l], E, held + l);
  }
  qc_law(XF, T, c, E, U, XS);
  for (int l = 0; l < QC_L; ++l) {
    long last = QC_K0(l) + done[l];
    const double* uf = U;
    if (!inb[l]) uf = UF;
#if QC_HELD
    else if (qc_mod(last, QC_HOLD(l)) != 0) uf = UF;
#endif
    if (uf == UF)
      for (int i = 0; i < QC_NU; ++i) U[i * QC_L + l] = UF[i * QC_L + l];  /* the final input, every lane */
    double* xr = xs + (long)l * QC_NX * rows_max + rows[l];
    double* ur = us + (long)l * QC_NU * rows_max + rows[l];
    for (int i = 0; i < QC_NX; ++i) xr[i * rows_max] = XF[i * QC_L + l];
    for (int i = 0; i < QC_NU; ++i) ur[i * rows_max] = uf[i * QC_L + l];
    ks[(long)l * rows_max + rows[l]] = last;
    n_rec[l] = rows[l] + 1;
  }
  if (mq) {  /* the final record: the reference at its own step's row (as the one-case run's x_ref) */
    for (int l = 0; l < QC_L; ++l) {
      KD[l] = (double)(QC_K0(l) + done[l]);
      ON[l] = 1.0;
      qc_exo_row(exo, exo_rows, lane_d, lane_i, l, QC_K0(l) + done[l], T[l], E, held + l);
    }
    qc_ref(T, c, E, XR);
    qc_metric(mq, mv, macc, ON, 1, KD, T, XF, U, XR, TAIL0, 1);
  }
}

void qc_run(const double* x0, const double* c, const double* lane_d, const long* lane_i,
            const double* lo, const double* hi, const double* exo, long exo_rows, long rows_max,
            double* xs, double* us, long* ks, long* n_rec, long* done,
            long keep, const long* mq, const double* mv, double* macc) {
  qc_run_at(x0, c, lane_d, lane_i, lo, hi, exo, exo_rows, rows_max, xs, us, ks, n_rec, done, keep, mq, mv, macc,
            NULL);
}

/* n_seg segments run one after another in one call (ETDRK4's graded schedule), each lane from where
 * its last segment ended: segment s's c [QC_NC][QC_L], lane_d [2][QC_L] and lane_i [6][QC_L] at
 * c + s QC_NC QC_L, lane_d + 2 s QC_L, lane_i + 6 s QC_L (QC_N(l) == 0: lane l has no segment s).
 * A segment's final record is overwritten by the next segment's first (the same state and time); a
 * lane stops at its last segment or where a segment stops early (it left its bounds). Records as
 * qc_run's, all segments' in one row range (rows_max counts one more, a spare row the lanes done
 * write into); first[s][l]: the row segment s of lane l starts at (-1: none); done[l]: the steps of
 * all its segments. */
void qc_run_segments(long n_seg, const double* x0, const double* c, const double* lane_d, const long* lane_i,
                     const double* lo, const double* hi, const double* exo, long exo_rows, long rows_max,
                     double* xs, double* us, long* ks, long* n_rec, long* done, long* first) {
  double X[QC_NX * QC_L];
  long li[6 * QC_L], row0[QC_L], rows[QC_L], seg_done[QC_L], last[QC_L];
  int live[QC_L];
  memcpy(X, x0, sizeof X);
  for (int l = 0; l < QC_L; ++l) {
    last[l] = -1;
    for (long s = 0; s < n_seg; ++s)
      if (lane_i[(6 * s + 1) * QC_L + l] > 0) last[l] = s;
    live[l] = last[l] >= 0;
    row0[l] = live[l] ? 0 : rows_max - 1;
    done[l] = 0;
    n_rec[l] = 1;
  }
  for (long s = 0; s < n_seg; ++s) {
    int any = 0;
    memcpy(li, lane_i + 6 * s * QC_L, sizeof li);
    for (int l = 0; l < QC_L; ++l) {
      first[s * QC_L + l] = live[l] ? row0[l] : -1;
      if (!live[l]) li[1 * QC_L + l] = 0;  /* QC_N: a lane done takes no steps, records into the spare row */
      any |= live[l];
    }
    if (!any) continue;
    qc_run_at(X, c + s * QC_NC * QC_L, lane_d + 2 * s * QC_L, li, lo, hi, exo, exo_rows, rows_max, xs, us, ks,
              rows, seg_done, 1, NULL, NULL, NULL, row0);
    for (int l = 0; l < QC_L; ++l) {
      if (!live[l]) continue;
      long end = rows[l] - 1;  /* the segment's final record */
      done[l] += seg_done[l];
      for (int i = 0; i < QC_NX; ++i) X[i * QC_L + l] = xs[((long)l * QC_NX + i) * rows_max + end];
      if (s == last[l] || seg_done[l] < li[1 * QC_L + l]) {
        live[l] = 0;
        n_rec[l] = rows[l];
        row0[l] = rows_max - 1;
      } else {
        row0[l] = end;
      }
    }
  }
}
