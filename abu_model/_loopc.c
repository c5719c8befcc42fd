/* Compiled closed-loop response (abu_model.loop_response.response): theta, omega and alpha
 * of the loop's modal form at increasing times t for a piecewise-constant setpoint.
 *
 * Why compiled: the drive-model fits of `abu measure --kinematics drive-model` (and the
 * staircase search) evaluate the response thousands of times on a few thousand frames. The
 * NumPy reference makes ~20 small array passes and a complex exp per time and pole; its
 * per-call cost was most of the fits' time (benchmarks/bench_staircase_search.py). Here the
 * times are walked once: the modal sums z_i are carried from one time to the next,
 *     z_i <- z_i exp(p_i d)  (d the time since z's last update),   z_i <- z_i + dW_k at a step,
 * and exp(p_i d) is reused while d stays within REUSE_REL of the last d (equally spaced
 * frames), for at most EXACT_EVERY times in a row: then z is computed afresh from the last
 * step, z_i = Z_i exp(p_i (t - t_k)), as the reference computes it at every time (the carried
 * product's rounding would grow with the run's length, and where poles nearly coincide the
 * residues, ~1e9 for a triple pole, magnify it: 8e-4 of omega on 20000 frames carried
 * throughout). The same formulas as the reference, so the two agree to rounding
 * (tests/test_loop_kernel.py: <= 1e-9 of max |theta|, |omega|, |alpha| on a broad family).
 *
 * Arguments: t, step times tk, step sizes dW (float64 buffers), poles p and residues c
 * (complex128 buffers, at most MAX_POLES), the level before the first step L0, need_theta,
 * and the outputs theta, omega, alpha (writable float64, len(t) each; theta untouched when
 * need_theta is 0). Times or step times not increasing, or any input not finite, are refused
 * (ValueError) before anything is written: the caller then runs the reference (any order,
 * NaN propagated as NumPy does).
 *
 * A plain CPython extension (buffers through "y*" / "w*", no NumPy headers); the caller
 * passes C-contiguous arrays of the right dtypes (checked by size here).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <complex.h>
#include <math.h>

#define MAX_POLES 8
#define REUSE_REL 1e-12
#define EXACT_EVERY 16

static PyObject *response(PyObject *self, PyObject *args)
{
    Py_buffer b[8];
    double level0;
    int need_theta;
    (void)self;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*dpw*w*w*", &b[0], &b[1], &b[2], &b[3], &b[4],
                          &level0, &need_theta, &b[5], &b[6], &b[7]))
        return NULL;
    PyObject *result = NULL;
    const Py_ssize_t n = b[0].len / 8, k_steps = b[1].len / 8, n_poles = b[3].len / 16;
    if (b[0].len % 8 || b[1].len % 8 || b[2].len != b[1].len || b[3].len % 16
        || b[4].len != b[3].len || n_poles < 1 || n_poles > MAX_POLES) {
        PyErr_SetString(PyExc_ValueError, "_loopc: sizes of t, tk, dW, poles or residues");
        goto done;
    }
    for (int i = 5; i < 8; i++) {
        if (b[i].len < n * 8) {
            PyErr_SetString(PyExc_ValueError, "_loopc: an output is shorter than t");
            goto done;
        }
    }
    const double *t = b[0].buf, *tk = b[1].buf, *dw = b[2].buf;
    const double complex *p = b[3].buf, *c = b[4].buf;
    double *theta = b[5].buf, *omega = b[6].buf, *alpha = b[7].buf;
    for (Py_ssize_t i = 0; i < n; i++) {
        if (!isfinite(t[i]) || (i && t[i] < t[i - 1])) {
            PyErr_SetString(PyExc_ValueError, "_loopc: times not finite and increasing");
            goto done;
        }
    }
    for (Py_ssize_t j = 0; j < k_steps; j++) {
        if (!isfinite(tk[j]) || !isfinite(dw[j]) || (j && tk[j] < tk[j - 1])) {
            PyErr_SetString(PyExc_ValueError, "_loopc: steps not finite and increasing");
            goto done;
        }
    }
    if (!isfinite(level0)) {
        PyErr_SetString(PyExc_ValueError, "_loopc: the first level is not finite");
        goto done;
    }
    double complex z[MAX_POLES], e[MAX_POLES], cp[MAX_POLES], cq[MAX_POLES];
    double c_sum = 0.0;
    for (Py_ssize_t i = 0; i < n_poles; i++) {
        z[i] = 0.0;
        e[i] = 1.0;
        cp[i] = c[i] * p[i];       /* alpha's weights */
        cq[i] = c[i] / p[i];       /* theta's weights */
        c_sum += creal(cq[i]);
    }
    /* zk: the modal sums just after the last step (at t_last); z: at tz, carried */
    double complex zk[MAX_POLES];
    double t_last = 0.0, tz = 0.0, last_d = -1.0, sum_dw = 0.0, sum_dwt = 0.0;
    int carried = 0;
    Py_ssize_t j = 0;
    for (Py_ssize_t m = 0; m < n; m++) {
        const double tm = t[m];
        while (j < k_steps && tk[j] <= tm) {      /* right-continuous: the step is done */
            for (Py_ssize_t i = 0; i < n_poles; i++)
                zk[i] = (j ? zk[i] * cexp(p[i] * (tk[j] - t_last)) : 0.0) + dw[j];
            t_last = tz = tk[j];
            for (Py_ssize_t i = 0; i < n_poles; i++) z[i] = zk[i];
            sum_dw += dw[j];
            sum_dwt += dw[j] * tk[j];
            carried = 0;
            j++;
        }
        double w_modes = 0.0, a_modes = 0.0, th_modes = 0.0;
        if (j) {                                  /* before the first step z = 0 */
            const double d = tm - tz;
            if (d != 0.0) {
                const int same = fabs(d - last_d) <= REUSE_REL * d;
                if (same && carried < EXACT_EVERY) {
                    for (Py_ssize_t i = 0; i < n_poles; i++) z[i] *= e[i];
                    carried++;
                } else {    /* from the last step, as the reference: no rounding carried */
                    for (Py_ssize_t i = 0; i < n_poles; i++)
                        z[i] = zk[i] * cexp(p[i] * (tm - t_last));
                    carried = 0;
                    if (!same) {
                        for (Py_ssize_t i = 0; i < n_poles; i++) e[i] = cexp(p[i] * d);
                        last_d = d;
                    }
                }
                tz = tm;
            }
            for (Py_ssize_t i = 0; i < n_poles; i++) {
                w_modes += creal(c[i] * z[i]);
                a_modes += creal(cp[i] * z[i]);
                th_modes += creal(cq[i] * z[i]);
            }
        }
        omega[m] = level0 + sum_dw + w_modes;
        alpha[m] = a_modes;
        if (need_theta)
            theta[m] = level0 * tm + sum_dw * tm - sum_dwt + th_modes - sum_dw * c_sum;
    }
    result = Py_None;
    Py_INCREF(result);
done:
    for (int i = 0; i < 8; i++) PyBuffer_Release(&b[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"response", response, METH_VARARGS,
     "response(t, tk, dW, poles, residues, L0, need_theta, theta, omega, alpha): the loop's "
     "response at increasing times t written into theta, omega, alpha (module doc)."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_loopc",
                                    "Compiled closed-loop response (abu_model.loop_response).",
                                    -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__loopc(void) { return PyModule_Create(&module); }
