/* quadctl simulation driver: loops the CasADi-generated RK4 step functions.
 *
 * No dynamics here: qc_step (closed-loop RK4 step), qc_ctrl (one controller sample) and
 * qc_step_ol (RK4 step under a held input) are generated from quadctl/model.py by
 * quadctl/codegen.py and prepended to this file, with QC_NZ (controller integrator states).
 * This file only iterates them, records every `stride`-th state, and stops at the first
 * state outside [lo, hi] (NaN included).
 *
 * The loop state is X = [x (12 plant states); z (QC_NZ integrator states)].
 */
#include <string.h>

#define QC_NP 12
#define QC_NX (QC_NP + QC_NZ)

static const casadi_real qc_zero[16] = {0};

static int qc_in_bounds(const double* x, const double* lo, const double* hi) {
  for (int i = 0; i < QC_NX; i++) {
    if (!(x[i] >= lo[i] && x[i] <= hi[i])) return 0;
  }
  return 1;
}

/* x0[QC_NX], c[]: packed constants; dist: n x 6 (or NULL), meas: n x 12 (or NULL);
 * hold = 0: continuous feedback inside every RK4 stage (z integrated by the same RK4 step);
 * hold = k > 0: control computed every k steps (zero-order hold) from x + meas noise, and the
 * integrators advanced once per sample by qc_ctrl.
 * Records rows k = 0, stride, 2 stride, ... and the last step into xs (QC_NX per row), us (4)
 * and ks (step index). Returns steps completed (n when every state stayed in bounds);
 * *n_rec receives the number of rows written (at most n / stride + 2). */
long qc_run(const double* x0, double t0, double dt, long n, const double* c,
            const double* dist, const double* meas, long hold, long stride,
            const double* lo, const double* hi, double* xs, double* us, long* ks, long* n_rec) {
  const casadi_real* arg[QC_SZ_ARG];
  casadi_real* res[QC_SZ_RES];
  casadi_int iw[QC_SZ_IW + 1];
  casadi_real w[QC_SZ_W + 1];
  double t, xa[QC_NX + 1], xb[QC_NX + 1], xm[QC_NP], z_new[QC_NZ + 1];
  double u_now[4], u_hold[4] = {0, 0, 0, 0};
  double *x = xa, *x_next = xb, *swap;
  const size_t x_bytes = sizeof(double) * QC_NX;
  long rows = 0, k;
  int in_bounds = 1;
  memcpy(x, x0, x_bytes);
  for (k = 0; k < n; k++) {
    const double* dk = dist ? dist + 6 * k : qc_zero;
    const double* mk = meas ? meas + QC_NP * k : qc_zero;
    t = t0 + dt * (double)k;
    if (hold > 0) {
      if (k % hold == 0) {
        for (int i = 0; i < QC_NP; i++) xm[i] = x[i] + mk[i];
        arg[0] = xm; arg[1] = x + QC_NP; arg[2] = &t; arg[3] = c; res[0] = u_hold; res[1] = z_new;
        qc_ctrl(arg, res, iw, w, 0);
        memcpy(x_next + QC_NP, z_new, sizeof(double) * QC_NZ);
      } else {
        memcpy(x_next + QC_NP, x + QC_NP, sizeof(double) * QC_NZ);
      }
      memcpy(u_now, u_hold, sizeof u_now);
      arg[0] = x; arg[1] = u_hold; arg[2] = &dt; arg[3] = c; arg[4] = dk; res[0] = x_next;
      qc_step_ol(arg, res, iw, w, 0);
    } else {
      arg[0] = x; arg[1] = &t; arg[2] = &dt; arg[3] = c; arg[4] = dk; arg[5] = mk;
      res[0] = x_next; res[1] = u_now;
      qc_step(arg, res, iw, w, 0);
    }
    if (k % stride == 0) {
      memcpy(xs + QC_NX * rows, x, x_bytes);
      memcpy(us + 4 * rows, u_now, sizeof u_now);
      ks[rows++] = k;
    }
    swap = x; x = x_next; x_next = swap;
    if (!qc_in_bounds(x, lo, hi)) { in_bounds = 0; k++; break; }
  }
  /* the final state, with the input the law gives there (or the held one) */
  memcpy(xs + QC_NX * rows, x, x_bytes);
  if (!in_bounds || (hold > 0 && k % hold != 0)) {
    memcpy(us + 4 * rows, hold > 0 ? u_hold : u_now, sizeof u_now);
  } else {
    const double* mk = meas ? meas + QC_NP * (k > 0 ? k - 1 : 0) : qc_zero;
    for (int i = 0; i < QC_NP; i++) xm[i] = x[i] + mk[i];
    t = t0 + dt * (double)k;
    arg[0] = xm; arg[1] = x + QC_NP; arg[2] = &t; arg[3] = c; res[0] = us + 4 * rows; res[1] = z_new;
    qc_ctrl(arg, res, iw, w, 0);
  }
  ks[rows++] = k;
  *n_rec = rows;
  return k;
}
