/* The control step of hysteresis-hybrid's fixed-iteration SQP controller (control.c).
 *
 * control(x, u_prev, ref, U_guess[, h]) -> (u, U, step), with CasADi's calling convention and the
 * entry points casadi.external loads (control_work, control_checkout, ...), so a C program and
 * Python call the same code. See control.c.
 */
#ifndef HYST_CONTROL_H
#define HYST_CONTROL_H

#include "controller.h" /* the CasADi-generated pieces, casadi_real and casadi_int */

#ifdef __cplusplus
extern "C" {
#endif

int control(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem);
int control_work(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w);
int control_checkout(void);
void control_release(int mem);
void control_incref(void);
void control_decref(void);
casadi_int control_n_in(void);
casadi_int control_n_out(void);
const char *control_name_in(casadi_int i);
const char *control_name_out(casadi_int i);
const casadi_int *control_sparsity_in(casadi_int i);
const casadi_int *control_sparsity_out(casadi_int i);
/* The last call's QP: DAQP's exit flag (1 optimal; < 0 failed, the step then kept the iterate) and its
 * active-set iterations, summed over the SQP iterations. */
int control_qp_status(int mem, int *exitflag, int *iterations);

#ifdef __cplusplus
}
#endif

#endif /* HYST_CONTROL_H */
