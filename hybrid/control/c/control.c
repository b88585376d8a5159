/* The control step of hysteresis-hybrid's fixed-iteration SQP controller, with DAQP as its QP solver.
 *
 * Generated with a controller by hysteresis-hybrid (hyst export --controller); Python's
 * FixedSQPSolver compiles and calls the same file. One control step is
 *
 *   (V, p)  = control_start(x, u_prev, ref, U_guess[, h])   scaled warm start, made feasible
 *   CONTROL_ITERATIONS times:
 *     (H, f, A', lower, upper, f0) = control_qp(V, p)      the condensed QP of an SQP iteration
 *     z = argmin 1/2 z'Hz + f'z  s.t.  lower <= [z; A z] <= upper    (DAQP, dual active set)
 *     (V, step) = control_line(V, z, p, f0)                backtracking on the model's own cost
 *   (u, U)  = control_finish(V)                             back in physical units
 *
 * The control_* pieces are CasADi-generated C (controller.c); the QP is solved in place by DAQP
 * (daqp/, MIT licence, Daniel Arnstrom), whose workspace is allocated once, at checkout, so the
 * loop allocates nothing. Its working set is warm-started from the previous control step's, shifted
 * by one sample as the warm start U_guess is, and it takes at most CONTROL_QP_ITER_LIMIT active-set
 * iterations. A QP that fails (DAQP's exit flag < 0, which a strictly convex QP with a feasible
 * start should never give) is solved once more from an empty working set; if that fails too the
 * iteration keeps its iterate (z = 0) and the next step starts cold.
 */
#include <string.h>

#include "control.h"
#include "control_config.h" /* CONTROL_NX, CONTROL_N, CONTROL_NV, CONTROL_NC, CONTROL_NP, ... */
#include "api.h"            /* DAQP */
#include "utils.h"          /* daqp_update_ldp */

#define NM (CONTROL_NV + CONTROL_NC) /* DAQP's constraints: the simple bounds on z, then the rows A z */
#define CONTROL_MEMORY 8             /* memory objects (one per caller at a time) */

typedef struct {
  DAQPWorkspace work;
  DAQPSettings settings;
  DAQPProblem qp;
  casadi_real H[CONTROL_NV * CONTROL_NV], f[CONTROL_NV], A[CONTROL_NC * CONTROL_NV];
  casadi_real lower[NM], upper[NM], z[CONTROL_NV], lam[NM];
  casadi_real V[CONTROL_N], V_next[CONTROL_N], p[CONTROL_NP];
  int sense[NM];
  int allocated, in_use, exitflag, iterations;
} control_memory;

static control_memory memory[CONTROL_MEMORY];
static int references = 0;

static const casadi_int sp_x[3] = {CONTROL_NX, 1, 1}, sp_1[3] = {1, 1, 1}, sp_n[3] = {CONTROL_N, 1, 1};

casadi_int control_n_in(void) { return CONTROL_N_IN; }
casadi_int control_n_out(void) { return 3; }

const char *control_name_in(casadi_int i) {
  static const char *names[5] = {"x", "u_prev", "ref", "U_guess", "h"};
  return i >= 0 && i < CONTROL_N_IN ? names[i] : 0;
}

const char *control_name_out(casadi_int i) {
  static const char *names[3] = {"u", "U", "step"};
  return i >= 0 && i < 3 ? names[i] : 0;
}

const casadi_int *control_sparsity_in(casadi_int i) {
  switch (i) {
    case 0: return sp_x;
    case 1: return sp_1;
    case 2: case 3: return sp_n;
    case 4: return CONTROL_N_IN > 4 ? sp_n : 0;
    default: return 0;
  }
}

const casadi_int *control_sparsity_out(casadi_int i) {
  switch (i) {
    case 0: case 2: return sp_1;
    case 1: return sp_n;
    default: return 0;
  }
}

#define MAX(a, b) ((a) > (b) ? (a) : (b))

/* The pieces' work arrays; arg and res also hold control's own pointers while the pieces run. */
int control_work(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w) {
  casadi_int a[4], r[4], i[4], w[4], k;
  control_start_work(a, r, i, w);
  control_qp_work(a + 1, r + 1, i + 1, w + 1);
  control_line_work(a + 2, r + 2, i + 2, w + 2);
  control_finish_work(a + 3, r + 3, i + 3, w + 3);
  for (k = 1; k < 4; ++k) {
    a[0] = MAX(a[0], a[k]); r[0] = MAX(r[0], r[k]); i[0] = MAX(i[0], i[k]); w[0] = MAX(w[0], w[k]);
  }
  if (sz_arg) *sz_arg = MAX(a[0], CONTROL_N_IN);
  if (sz_res) *sz_res = MAX(r[0], 6);
  if (sz_iw) *sz_iw = i[0];
  if (sz_w) *sz_w = w[0];
  return 0;
}

/* DAQP's workspace for NV variables, NV simple bounds and NC rows, allocated once. */
static void allocate(control_memory *m) {
  memset(&m->work, 0, sizeof(m->work));
  daqp_default_settings(&m->settings);
  m->settings.eq_reduction = DAQP_EQ_REDUCTION_OFF; /* no equality rows: nothing to eliminate (or allocate) */
  m->settings.iter_limit = CONTROL_QP_ITER_LIMIT;
  m->work.settings = &m->settings;
  allocate_daqp_workspace(&m->work, CONTROL_NV, 0);
  allocate_daqp_ldp(&m->work, CONTROL_NV, NM, CONTROL_NV, 1, 1);
  m->qp.n = CONTROL_NV;
  m->qp.m = NM;
  m->qp.ms = CONTROL_NV;
  m->qp.H = m->H;
  m->qp.f = m->f;
  m->qp.A = m->A; /* row-major: control_qp returns A' column-major */
  m->qp.bupper = m->upper;
  m->qp.blower = m->lower;
  m->qp.sense = m->sense;
  m->qp.break_points = 0;
  m->qp.nh = 0;
  m->qp.problem_type = 0;
  m->allocated = 1;
}

static void release_all(void) {
  int k;
  for (k = 0; k < CONTROL_MEMORY; ++k) {
    if (!memory[k].allocated) continue;
    memory[k].work.settings = 0; /* ours, not DAQP's to free */
    free_daqp_workspace(&memory[k].work);
    free_daqp_ldp(&memory[k].work);
    memory[k].allocated = memory[k].in_use = 0;
  }
}

void control_incref(void) { ++references; }

void control_decref(void) {
  if (--references <= 0) {
    references = 0;
    release_all();
  }
}

int control_checkout(void) {
  int k;
  for (k = 0; k < CONTROL_MEMORY; ++k) {
    if (memory[k].in_use) continue;
    if (!memory[k].allocated) allocate(&memory[k]);
    memset(memory[k].sense, 0, sizeof(memory[k].sense)); /* a new caller starts cold */
    memory[k].in_use = 1;
    return k;
  }
  return -1;
}

void control_release(int mem) {
  if (mem >= 0 && mem < CONTROL_MEMORY) memory[mem].in_use = 0;
}

int control_qp_status(int mem, int *exitflag, int *iterations) {
  if (mem < 0 || mem >= CONTROL_MEMORY || !memory[mem].allocated) return 1;
  if (exitflag) *exitflag = memory[mem].exitflag;
  if (iterations) *iterations = memory[mem].iterations;
  return 0;
}

/* One DAQP solve of the QP in m, from the working set in m->sense; returns DAQP's exit flag. */
static int solve_once(control_memory *m) {
  const int mask = DAQP_UPDATE_Rinv | DAQP_UPDATE_M | DAQP_UPDATE_v | DAQP_UPDATE_d | DAQP_UPDATE_sense;
  DAQPResult result;
  int flag = daqp_update_ldp(mask, &m->work, &m->qp);
  if (flag < 0) return flag;
  result.x = m->z;
  result.lam = m->lam;
  daqp_solve(&result, &m->work);
  m->iterations += result.iter;
  return result.exitflag;
}

/* z: the QP's solution, warm-started; z = 0 (keep the iterate) where DAQP fails twice. */
static void solve(control_memory *m) {
  int i, flag = solve_once(m);
  if (flag < 0) { /* once more from an empty working set */
    memset(m->sense, 0, sizeof(m->sense));
    flag = solve_once(m);
  }
  m->exitflag = flag;
  if (flag < 0) {
    memset(m->z, 0, sizeof(m->z));
    memset(m->sense, 0, sizeof(m->sense));
    return;
  }
  for (i = 0; i < NM; ++i) m->sense[i] = m->work.sense[i] & (DAQP_ACTIVE | DAQP_LOWER); /* the next QP's start */
}

/* The working set one sample on: every block of N constraints (bounds and rows over the horizon) shifted
 * by one, its last entry kept, as the warm start U_guess is. */
static void shift(control_memory *m) {
  int b, i;
  for (b = 0; b + CONTROL_N <= NM; b += CONTROL_N)
    for (i = b; i + 1 < b + CONTROL_N; ++i) m->sense[i] = m->sense[i + 1];
}

int control(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const casadi_real *in[5];
  casadi_real *out[3], f0 = 0, step = 0;
  control_memory *m;
  int i, k;
  if (mem < 0 || mem >= CONTROL_MEMORY || !memory[mem].allocated) return 1;
  m = &memory[mem];
  for (i = 0; i < CONTROL_N_IN; ++i) in[i] = arg[i]; /* the pieces use arg and res as scratch */
  for (i = 0; i < 3; ++i) out[i] = res[i];
  for (i = 0; i < CONTROL_N_IN; ++i) arg[i] = in[i];
  res[0] = m->V;
  res[1] = m->p;
  if (control_start(arg, res, iw, w, 0)) return 1;
  m->iterations = 0;
  m->exitflag = 1;
  for (k = 0; k < CONTROL_ITERATIONS; ++k) {
    arg[0] = m->V; arg[1] = m->p;
    res[0] = m->H; res[1] = m->f; res[2] = m->A; res[3] = m->lower; res[4] = m->upper; res[5] = &f0;
    if (control_qp(arg, res, iw, w, 0)) return 1;
    solve(m);
    arg[0] = m->V; arg[1] = m->z; arg[2] = m->p; arg[3] = &f0;
    res[0] = m->V_next; res[1] = &step;
    if (control_line(arg, res, iw, w, 0)) return 1;
    memcpy(m->V, m->V_next, sizeof(m->V));
  }
  shift(m);
  arg[0] = m->V;
  res[0] = out[0];
  res[1] = out[1];
  if (control_finish(arg, res, iw, w, 0)) return 1;
  if (out[2]) *out[2] = step;
  return 0;
}
