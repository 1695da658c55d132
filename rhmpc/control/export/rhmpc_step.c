/*
 * _rhmpc_step: the hot path of rhmpc.control.export.CController.step as a CPython extension.
 *
 * A Step object calls an exported controller's rhmpc_tick_ext through its address (the
 * library itself is loaded by ctypes), so one build of this module serves every exported
 * controller. step(x, ref) does in C what the Python wrapper would: take x (nx,) and
 * ref (N, ny) as float64 arrays (C-contiguous float64 arrays are used in place, anything else
 * is converted as np.asarray(..., dtype=float) would), check their shapes, evaluate the
 * optional Python extra_inputs(x), pass u_prev if one was set, call the tick, and return the
 * torque as a new array (the controller's own copy stays in `last`).
 *
 * The GIL is held throughout: the tick is a few microseconds and the controller's OSQP
 * workspace is a set of static globals that must not be entered twice.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>

#include <math.h>
#include <string.h>
#include <time.h>

typedef int (*tick_fn)(void *ctl, const double *x, const double *ref, const double *u_prev,
                       const double *extra, double *tau);

typedef struct {
  PyObject_HEAD
  tick_fn tick;
  void *ctl;                 /* the controller's rhmpc_t, inside `keep` */
  PyObject *keep;            /* owns ctl and the library: kept alive with this object */
  PyObject *extra_inputs;    /* callable(x) -> (n_extra,), or NULL: the library's own */
  PyArrayObject *last;       /* (nu,) the last torque */
  PyArrayObject *u_in;       /* (nu,) u_prev for the next tick, used if u_pending */
  PyArrayObject *extra;      /* (n_extra,) the last extra inputs given by extra_inputs */
  npy_intp nx, N, ny, nu, n_extra;
  int u_pending;
  long long call_ns;
} Step;

static long long now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* obj as an aligned, C-contiguous float64 array: a new reference to obj itself if it is one. */
static PyArrayObject *as_doubles(PyObject *obj) {
  if (PyArray_Check(obj)) {
    PyArrayObject *a = (PyArrayObject *)obj;
    if (PyArray_TYPE(a) == NPY_DOUBLE && PyArray_ISCARRAY_RO(a) && PyArray_ISNOTSWAPPED(a)) {
      Py_INCREF(obj);
      return a;
    }
  }
  return (PyArrayObject *)PyArray_FROM_OTF(obj, NPY_DOUBLE, NPY_ARRAY_IN_ARRAY);
}

static int has_shape(PyArrayObject *a, int ndim, npy_intp d0, npy_intp d1) {
  const npy_intp *d = PyArray_DIMS(a);
  return PyArray_NDIM(a) == ndim && d[0] == d0 && (ndim == 1 || d[1] == d1);
}

static void shape_error(Step *self, PyArrayObject *x, PyArrayObject *ref) {
  PyObject *xs = PyObject_GetAttrString((PyObject *)x, "shape");
  PyObject *rs = PyObject_GetAttrString((PyObject *)ref, "shape");
  if (xs != NULL && rs != NULL)
    PyErr_Format(PyExc_ValueError, "step expects x (%zd,) and ref (%zd, %zd), got %R, %R",
                 (Py_ssize_t)self->nx, (Py_ssize_t)self->N, (Py_ssize_t)self->ny, xs, rs);
  Py_XDECREF(xs);
  Py_XDECREF(rs);
}

/* extra <- extra_inputs(x) if x is finite (else the last values stay); 0 on success. */
static int update_extra(Step *self, PyArrayObject *x) {
  const double *xd = (const double *)PyArray_DATA(x);
  for (npy_intp i = 0; i < self->nx; ++i)
    if (!isfinite(xd[i])) return 0;
  PyObject *value = PyObject_CallOneArg(self->extra_inputs, (PyObject *)x);
  if (value == NULL) return -1;
  PyArrayObject *v = as_doubles(value);
  Py_DECREF(value);
  if (v == NULL) return -1;
  if (PyArray_SIZE(v) != self->n_extra) {
    PyErr_Format(PyExc_ValueError, "extra_inputs(x) gave %zd values, the library takes %zd",
                 (Py_ssize_t)PyArray_SIZE(v), (Py_ssize_t)self->n_extra);
    Py_DECREF(v);
    return -1;
  }
  memcpy(PyArray_DATA(self->extra), PyArray_DATA(v), self->n_extra * sizeof(double));
  Py_DECREF(v);
  return 0;
}

/* The tick on converted, shape-checked inputs; a new (nu,) array with the torque. */
static PyObject *tick(Step *self, PyArrayObject *x, PyArrayObject *ref) {
  const double *extra = NULL;
  if (self->extra_inputs != NULL) {
    if (update_extra(self, x) < 0) return NULL;
    extra = (const double *)PyArray_DATA(self->extra);
  }
  PyObject *out = PyArray_SimpleNew(1, &self->nu, NPY_DOUBLE);
  if (out == NULL) return NULL;
  const double *u_in = self->u_pending ? (const double *)PyArray_DATA(self->u_in) : NULL;
  double *last = (double *)PyArray_DATA(self->last);
  self->u_pending = 0;
  self->tick(self->ctl, (const double *)PyArray_DATA(x), (const double *)PyArray_DATA(ref), u_in,
             extra, last);
  memcpy(PyArray_DATA((PyArrayObject *)out), last, self->nu * sizeof(double));
  return out;
}

static PyObject *Step_step(Step *self, PyObject *const *args, Py_ssize_t nargs) {
  const long long t0 = now_ns();
  if (nargs != 2) {
    PyErr_Format(PyExc_TypeError, "step(x, ref) takes 2 arguments, got %zd", nargs);
    return NULL;
  }
  if (self->tick == NULL) {
    PyErr_SetString(PyExc_RuntimeError, "Step was not initialised");
    return NULL;
  }
  PyArrayObject *x = as_doubles(args[0]);
  PyArrayObject *ref = x != NULL ? as_doubles(args[1]) : NULL;
  PyObject *out = NULL;
  if (ref != NULL) {
    if (has_shape(x, 1, self->nx, 0) && has_shape(ref, 2, self->N, self->ny))
      out = tick(self, x, ref);
    else
      shape_error(self, x, ref);
  }
  Py_XDECREF(x);
  Py_XDECREF(ref);
  self->call_ns = now_ns() - t0;
  return out;
}

static int is_vector(PyObject *obj, npy_intp n, const char *name) {
  if (PyArray_Check(obj) && PyArray_TYPE((PyArrayObject *)obj) == NPY_DOUBLE &&
      PyArray_ISCARRAY((PyArrayObject *)obj) && PyArray_NDIM((PyArrayObject *)obj) == 1 &&
      PyArray_DIM((PyArrayObject *)obj, 0) == n)
    return 1;
  PyErr_Format(PyExc_TypeError, "%s must be a writeable C-contiguous float64 array of %zd",
               name, (Py_ssize_t)n);
  return 0;
}

static int Step_init(Step *self, PyObject *args, PyObject *kwargs) {
  static char *names[] = {"tick", "ctl", "keep", "dims", "last", "u_in", "extra", "extra_inputs",
                          NULL};
  unsigned long long tick_addr, ctl_addr;
  Py_ssize_t N, nx, nu, ny, n_extra;
  PyObject *keep, *last, *u_in, *extra, *extra_inputs = Py_None;
  if (!PyArg_ParseTupleAndKeywords(args, kwargs, "KKO(nnnnn)OOO|O", names, &tick_addr, &ctl_addr,
                                   &keep, &N, &nx, &nu, &ny, &n_extra, &last, &u_in, &extra,
                                   &extra_inputs))
    return -1;
  if (!tick_addr || !ctl_addr) {
    PyErr_SetString(PyExc_ValueError, "tick and ctl must be non-null addresses");
    return -1;
  }
  if (!is_vector(last, nu, "last") || !is_vector(u_in, nu, "u_in") ||
      !is_vector(extra, n_extra, "extra"))
    return -1;
  if (extra_inputs != Py_None && !PyCallable_Check(extra_inputs)) {
    PyErr_SetString(PyExc_TypeError, "extra_inputs must be callable or None");
    return -1;
  }
  self->tick = (tick_fn)(uintptr_t)tick_addr;
  self->ctl = (void *)(uintptr_t)ctl_addr;
  self->N = N;
  self->nx = nx;
  self->nu = nu;
  self->ny = ny;
  self->n_extra = n_extra;
  Py_INCREF(keep);
  Py_XSETREF(self->keep, keep);
  Py_INCREF(last);
  Py_XSETREF(self->last, (PyArrayObject *)last);
  Py_INCREF(u_in);
  Py_XSETREF(self->u_in, (PyArrayObject *)u_in);
  Py_INCREF(extra);
  Py_XSETREF(self->extra, (PyArrayObject *)extra);
  Py_CLEAR(self->extra_inputs);
  if (extra_inputs != Py_None) {
    Py_INCREF(extra_inputs);
    self->extra_inputs = extra_inputs;
  }
  self->u_pending = 0;
  self->call_ns = 0;
  return 0;
}

static int Step_traverse(Step *self, visitproc visit, void *arg) {
  Py_VISIT(self->keep);
  Py_VISIT(self->extra_inputs);
  Py_VISIT(self->last);
  Py_VISIT(self->u_in);
  Py_VISIT(self->extra);
  return 0;
}

static int Step_clear(Step *self) {
  Py_CLEAR(self->keep);
  Py_CLEAR(self->extra_inputs);
  Py_CLEAR(self->last);
  Py_CLEAR(self->u_in);
  Py_CLEAR(self->extra);
  return 0;
}

static void Step_dealloc(Step *self) {
  PyObject_GC_UnTrack(self);
  Step_clear(self);
  Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyMethodDef Step_methods[] = {
    {"step", (PyCFunction)(void (*)(void))Step_step, METH_FASTCALL,
     "step(x, ref) -> tau: one tick of the compiled controller (a new (nu,) array)."},
    {NULL, NULL, 0, NULL}};

static PyMemberDef Step_members[] = {
    {"u_pending", T_INT, offsetof(Step, u_pending), 0,
     "1: the next tick passes u_in as u_prev (then 0 again)."},
    {"call_ns", T_LONGLONG, offsetof(Step, call_ns), READONLY,
     "Duration of the last step() inside this binding, the tick included [ns]."},
    {NULL, 0, 0, 0, NULL}};

static PyTypeObject StepType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "_rhmpc_step.Step",
    .tp_doc = "Step(tick, ctl, keep, dims, last, u_in, extra, extra_inputs=None): the hot path "
              "of one compiled controller; dims = (N, nx, nu, ny, n_extra).",
    .tp_basicsize = sizeof(Step),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Step_init,
    .tp_dealloc = (destructor)Step_dealloc,
    .tp_traverse = (traverseproc)Step_traverse,
    .tp_clear = (inquiry)Step_clear,
    .tp_methods = Step_methods,
    .tp_members = Step_members,
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_rhmpc_step",
    "The hot path of rhmpc.control.export.CController (see rhmpc/control/export/binding.py).",
    -1, NULL, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__rhmpc_step(void) {
  import_array();
  if (PyType_Ready(&StepType) < 0) return NULL;
  PyObject *m = PyModule_Create(&module);
  if (m == NULL) return NULL;
  Py_INCREF(&StepType);
  if (PyModule_AddObject(m, "Step", (PyObject *)&StepType) < 0) {
    Py_DECREF(&StepType);
    Py_DECREF(m);
    return NULL;
  }
  return m;
}
