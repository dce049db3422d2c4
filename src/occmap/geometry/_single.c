/* occmap.geometry._single: the single-element path of the geometry functions, in C.
 *
 * A call through a Numba-compiled function costs ~0.5-2 us of argument unboxing before the first
 * multiplication; a quaternion product is 16 of them. A SingleCall holds the address of a Numba
 * cfunc (the same kernel the batches run: no formula lives here) and the shapes one element of
 * each operand has. Called with exactly such operands -- float64 C-contiguous arrays in native
 * byte order, Python floats for scalars -- it takes an output, passes the operands' data
 * pointers to the cfunc and returns the output: ~40 ns. The output is one it returned before
 * when nothing but the SingleCall holds that array any more (allocating one, ~45 ns, was half of
 * a call; see take_spare), else a new one. Anything else (batches, lists, other
 * dtypes, an element the kernel rejects, a cfunc not bound yet) goes to its Python fallback, which
 * handles every case and names what is wrong. Only the argument handling lives in this file.
 *
 * A public geometry function is its SingleCall itself (no Python frame in front: ~40 ns of a
 * ~140 ns call), wearing the documented Python function's name, docstring and signature
 * (functools.wraps: an instance dict), bound as a method inside a class and pickled by name, as a
 * function is.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stddef.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>

#define MAX_OPERANDS 3
#define MAX_NDIM 2

/* The cfunc's C signature: one data pointer an operand (a scalar's: one double), the output's;
 * 0 when the kernel filled the output, non-zero when it rejected an element. */
typedef int (*kernel_fn)(const double **operands, double *out);

typedef struct {
    PyObject_HEAD
    vectorcallfunc vectorcall;
    kernel_fn kernel;               /* NULL until bound: every call goes to the fallback */
    int n_operands;
    int ndim[MAX_OPERANDS];         /* 0: a scalar (a Python float) */
    npy_intp dims[MAX_OPERANDS][MAX_NDIM];
    int out_ndim;
    npy_intp out_dims[MAX_NDIM];
    PyObject *fallback;
    PyObject *owner;                /* keeps the cfunc's machine code alive while it is bound */
    PyObject *spare[2];             /* outputs returned before, reused once nothing else holds them */
    PyObject *dict;                 /* __doc__, __name__, __wrapped__...: a public function's face */
} SingleCall;

static int is_element(PyObject *o, int ndim, const npy_intp *dims) {
    if (!PyArray_CheckExact(o)) return 0;
    PyArrayObject *a = (PyArrayObject *)o;
    if (PyArray_TYPE(a) != NPY_DOUBLE || !PyArray_ISCARRAY_RO(a) || !PyArray_ISNOTSWAPPED(a) || PyArray_NDIM(a) != ndim)
        return 0;
    for (int d = 0; d < ndim; d++)
        if (PyArray_DIM(a, d) != dims[d]) return 0;
    return 1;
}

/* Whether a spare output may be written again: nothing but the spare slot holds it (no name, no
 * view, no buffer, no weak reference can see it change) and it is still an output's shape, as
 * NumPy's temporary elision reuses an operand only its own expression holds. */
static int reusable(SingleCall *self, PyObject *o) {
    if (o == NULL || Py_REFCNT(o) != 1 || ((PyArrayObject_fields *)o)->weakreflist != NULL) return 0;
    PyArrayObject *a = (PyArrayObject *)o;
    if (PyArray_TYPE(a) != NPY_DOUBLE || !PyArray_ISCARRAY(a) || PyArray_NDIM(a) != self->out_ndim) return 0;
    for (int d = 0; d < self->out_ndim; d++)
        if (PyArray_DIM(a, d) != self->out_dims[d]) return 0;
    return 1;
}

/* A new reference to an output array: a spare no one holds any more, else a new array kept as a
 * spare. Two spares: a loop's ``x = f(...)`` holds the last output while the next is made. */
static PyObject *take_spare(SingleCall *self) {
    for (int k = 0; k < 2; k++)
        if (reusable(self, self->spare[k])) return Py_NewRef(self->spare[k]);
    PyObject *out = PyArray_SimpleNew(self->out_ndim, self->out_dims, NPY_DOUBLE);
    if (out == NULL) return NULL;
    Py_XSETREF(self->spare[1], self->spare[0]);
    self->spare[0] = Py_NewRef(out);
    return out;
}

static PyObject *single_call(PyObject *self_, PyObject *const *args, size_t nargsf, PyObject *kwnames) {
    SingleCall *self = (SingleCall *)self_;
    Py_ssize_t n = PyVectorcall_NARGS(nargsf);
    if (self->kernel == NULL || kwnames != NULL || n != self->n_operands) goto fallback;
    const double *data[MAX_OPERANDS];
    double scalars[MAX_OPERANDS];
    for (int i = 0; i < self->n_operands; i++) {
        PyObject *o = args[i];
        if (self->ndim[i] == 0) {
            if (!PyFloat_Check(o)) goto fallback;
            scalars[i] = PyFloat_AS_DOUBLE(o);
            data[i] = &scalars[i];
        } else {
            if (!is_element(o, self->ndim[i], self->dims[i])) goto fallback;
            data[i] = (const double *)PyArray_DATA((PyArrayObject *)o);
        }
    }
    PyObject *out = take_spare(self);
    if (out == NULL) return NULL;
    if (self->kernel(data, (double *)PyArray_DATA((PyArrayObject *)out)) == 0) return out;
    Py_DECREF(out);
fallback:
    return PyObject_Vectorcall(self->fallback, args, nargsf, kwnames);
}

static int read_shape(PyObject *shape, int *ndim, npy_intp *dims) {
    if (!PyTuple_Check(shape) || PyTuple_GET_SIZE(shape) > MAX_NDIM) {
        PyErr_SetString(PyExc_ValueError, "a shape is a tuple of at most two sizes");
        return -1;
    }
    *ndim = (int)PyTuple_GET_SIZE(shape);
    for (int d = 0; d < *ndim; d++) {
        dims[d] = PyLong_AsSsize_t(PyTuple_GET_ITEM(shape, d));
        if (dims[d] < 0) {
            if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "sizes are not negative");
            return -1;
        }
    }
    return 0;
}

static int single_init(PyObject *self_, PyObject *args, PyObject *kwargs) {
    SingleCall *self = (SingleCall *)self_;
    static char *keywords[] = {"operands", "out", "fallback", NULL};
    PyObject *operands, *out, *fallback;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O!O!O:SingleCall", keywords, &PyTuple_Type, &operands,
                                     &PyTuple_Type, &out, &fallback))
        return -1;
    if (!PyCallable_Check(fallback) || PyTuple_GET_SIZE(operands) < 1 || PyTuple_GET_SIZE(operands) > MAX_OPERANDS) {
        PyErr_SetString(PyExc_ValueError, "one to three operand shapes and a callable fallback");
        return -1;
    }
    self->n_operands = (int)PyTuple_GET_SIZE(operands);
    for (int i = 0; i < self->n_operands; i++)
        if (read_shape(PyTuple_GET_ITEM(operands, i), &self->ndim[i], self->dims[i]) < 0) return -1;
    if (read_shape(out, &self->out_ndim, self->out_dims) < 0) return -1;
    self->kernel = NULL;
    Py_INCREF(fallback);
    Py_XSETREF(self->fallback, fallback);
    Py_CLEAR(self->owner);
    self->vectorcall = single_call;
    return 0;
}

static PyObject *single_bind(PyObject *self_, PyObject *args) {
    SingleCall *self = (SingleCall *)self_;
    unsigned long long address;
    PyObject *owner;
    if (!PyArg_ParseTuple(args, "KO:bind", &address, &owner)) return NULL;
    Py_INCREF(owner);
    Py_XSETREF(self->owner, owner);
    self->kernel = (kernel_fn)(uintptr_t)address;
    Py_RETURN_NONE;
}

static PyObject *single_bound(PyObject *self_, void *closure) {
    return PyBool_FromLong(((SingleCall *)self_)->kernel != NULL);
}

/* As a function's: an attribute of a class, it is a method of the instances. */
static PyObject *single_get(PyObject *self, PyObject *obj, PyObject *type) {
    if (obj == NULL || obj == Py_None) return Py_NewRef(self);
    return PyMethod_New(self, obj);
}

/* Pickled by reference, as a function is: its module and qualified name (set by functools.wraps). */
static PyObject *single_reduce(PyObject *self, PyObject *unused) {
    return PyObject_GetAttrString(self, "__qualname__");
}

static PyObject *single_repr(PyObject *self) {
    PyObject *name = PyObject_GetAttrString(self, "__qualname__");
    if (name == NULL) {
        PyErr_Clear();
        return PyUnicode_FromFormat("<SingleCall object at %p>", self);
    }
    PyObject *r = PyUnicode_FromFormat("<function %U>", name);
    Py_DECREF(name);
    return r;
}

static int single_traverse(PyObject *self_, visitproc visit, void *arg) {
    SingleCall *self = (SingleCall *)self_;
    Py_VISIT(self->fallback);
    Py_VISIT(self->owner);
    Py_VISIT(self->dict);
    Py_VISIT(self->spare[0]);
    Py_VISIT(self->spare[1]);
    return 0;
}

static int single_clear(PyObject *self_) {
    SingleCall *self = (SingleCall *)self_;
    self->kernel = NULL;
    Py_CLEAR(self->fallback);
    Py_CLEAR(self->owner);
    Py_CLEAR(self->dict);
    Py_CLEAR(self->spare[0]);
    Py_CLEAR(self->spare[1]);
    return 0;
}

static void single_dealloc(PyObject *self) {
    PyObject_GC_UnTrack(self);
    single_clear(self);
    Py_TYPE(self)->tp_free(self);
}

static PyMethodDef single_methods[] = {
    {"bind", single_bind, METH_VARARGS,
     "bind(address, owner): call the cfunc at ``address`` (kept alive by holding ``owner``) from now on."},
    {"__reduce__", single_reduce, METH_NOARGS, "The qualified name: pickled by reference, as functions are."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef single_getset[] = {
    {"bound", single_bound, NULL, "Whether a cfunc is bound (until then every call goes to the fallback).", NULL},
    {"__dict__", PyObject_GenericGetDict, PyObject_GenericSetDict, NULL, NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject SingleCallType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "occmap.geometry._single.SingleCall",
    .tp_doc = "SingleCall(operands, out, fallback): a geometry function's single-element path (see the module's source).",
    .tp_basicsize = sizeof(SingleCall),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_VECTORCALL | Py_TPFLAGS_HAVE_GC,
    .tp_vectorcall_offset = offsetof(SingleCall, vectorcall),
    .tp_call = PyVectorcall_Call,
    .tp_new = PyType_GenericNew,
    .tp_init = single_init,
    .tp_traverse = single_traverse,
    .tp_clear = single_clear,
    .tp_dealloc = single_dealloc,
    .tp_methods = single_methods,
    .tp_getset = single_getset,
    .tp_descr_get = single_get,
    .tp_repr = single_repr,
    .tp_dictoffset = offsetof(SingleCall, dict),
};

static struct PyModuleDef single_module = {
    PyModuleDef_HEAD_INIT, "occmap.geometry._single",
    "The geometry functions' single-element path in C: argument handling only, the arithmetic is Numba's.", -1, NULL,
};

PyMODINIT_FUNC PyInit__single(void) {
    import_array();
    if (PyType_Ready(&SingleCallType) < 0) return NULL;
    PyObject *m = PyModule_Create(&single_module);
    if (m == NULL) return NULL;
    Py_INCREF(&SingleCallType);
    if (PyModule_AddObject(m, "SingleCall", (PyObject *)&SingleCallType) < 0) {
        Py_DECREF(&SingleCallType);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
