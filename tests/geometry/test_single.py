"""The geometry functions' single-element path in C (``occmap.geometry._single.SingleCall``): the
values of that element in a batch, every other form of input through the Python path with the same
result or the same error, and compiled code that the next process loads instead of compiling."""

import copy
import inspect
import json
import pickle
import subprocess
import sys

import numpy as np
import pytest

import occmap.geometry as g
from occmap.errors import NonFiniteError, NotARotationError, NotUnitQuaternionError
from occmap.geometry import _arrays, euler, quaternion, se2, se3, so3
from occmap.geometry._single import SingleCall


def _batch_of(rng, n=5):
    """Named batches of valid operands, n elements each."""
    w = rng.normal(size=(n, 3))
    R = g.exp_so3(w)
    q = g.matrix_to_quat(R)
    T = g.make_transform(R, rng.normal(size=(n, 3)))
    return {"w": w, "R": R, "q": q, "q2": g.quat_normalize(q + 0.2), "T": T, "xi": rng.normal(size=(n, 6)),
            "s": rng.uniform(-3, 3, n), "p": rng.normal(size=(n, 3))}


#: (function, operand names): each call runs on one element and on the batch
CALLS = [
    (g.quat_multiply, ("q", "q2")), (g.quat_conjugate, ("q",)), (g.quat_inverse, ("q",)),
    (g.quat_normalize, ("p4",)), (g.quat_rotate, ("q", "p")), (g.quat_to_matrix, ("q",)),
    (g.matrix_to_quat, ("R",)), (g.axis_angle_to_quat, ("w", "s")), (g.quat_to_axis_angle, ("q",)),
    (g.quat_slerp, ("q", "q2", "s")), (g.euler_zyx_to_matrix, ("s", "s", "s")), (g.matrix_to_euler_zyx, ("R",)),
    (g.hat, ("w",)), (g.vee, ("W",)), (g.rot_x, ("s",)), (g.rot_y, ("s",)), (g.rot_z, ("s",)),
    (g.exp_so3, ("w",)), (g.log_so3, ("R",)), (g.matrix_to_axis_angle, ("R",)),
    (g.make_transform, ("R", "p")), (g.invert_transform, ("T",)), (g.transform_points, ("T", "p")),
    (g.compose_transforms, ("T", "T")), (g.exp_se3, ("xi",)), (g.log_se3, ("T",)),
    (g.se2_matrix, ("s", "s", "s")),
]


def _operands(rng):
    b = _batch_of(rng)
    b["p4"] = rng.normal(size=(5, 4))
    b["W"] = g.hat(b["w"])
    return b


def _single(value):
    """A batch's element as a single call passes it: a float for a scalar."""
    return float(value) if np.ndim(value) == 0 else value


@pytest.mark.parametrize("function, names", CALLS, ids=[f.__name__ for f, _ in CALLS])
def test_single_call_gives_the_batch_elements_values_through_the_c_path(function, names, rng):
    b = _operands(rng)
    batch = function(*[b[n] for n in names])
    for i in range(5):
        one = function(*[_single(b[n][i]) for n in names])
        for got, want in zip(one if isinstance(one, tuple) else (one,), batch if isinstance(batch, tuple) else (batch,)):
            np.testing.assert_allclose(got, want[i], rtol=1e-15, atol=1e-15)  # quat_rotate: 1 ulp (as before C)


def test_the_c_path_is_taken_and_other_inputs_give_the_same_result(rng):
    """A bound SingleCall answers float64 elements (read-only ones too) without its fallback;
    lists, int, big-endian and strided arrays go to the fallback and give the same values, as do
    NumPy floats, 0-d arrays and ints for scalars."""
    q, q2 = _batch_of(rng)["q"][:2]
    seen = []
    spy = SingleCall(((4,), (4,)), (4,), lambda *v: seen.append(v) or g.quat_multiply(*v))
    compiled = _arrays._single_kernel(quaternion.K.quat_multiply, ((4,), (4,)), (4,), (), quaternion.K.quat_multiply_one)
    spy.bind(compiled.address, compiled)
    want = g.quat_multiply(q[None], q2[None])[0]
    np.testing.assert_array_equal(spy(q, q2), want)
    ro = q.copy()
    ro.flags.writeable = False
    np.testing.assert_array_equal(spy(ro, q2), want)
    assert not seen
    for other in (q.tolist(), q.astype(">f8"), np.repeat(q, 2)[::2]):
        np.testing.assert_array_equal(spy(other, q2), want)
    e = np.array([1, 0, 0, 0])
    np.testing.assert_array_equal(spy(e, q2), q2)
    assert len(seen) == 4
    s = g.quat_slerp(q, q2, 0.25)
    for t in (np.float64(0.25), np.array(0.25)):
        np.testing.assert_array_equal(g.quat_slerp(q, q2, t), s)
    np.testing.assert_array_equal(g.rot_z(1), g.rot_z(1.0))


def test_an_output_is_reused_only_once_nothing_can_see_it():
    """The C path writes an earlier output again only when nothing but itself holds it: outputs
    kept in names, a view, a buffer or a weak reference keep their values, an output whose shape
    or type was changed in place is not handed out again, and one dropped is (no allocation)."""
    import weakref

    q, q2 = np.array([0.5, 0.5, 0.5, 0.5]), np.array([0.6, 0.0, 0.8, 0.0])
    product = g.quat_multiply(q, q2).copy()
    kept = [g.quat_multiply(q, q2) for _ in range(3)]  # three names at once: more than the two spares
    view, buffer = g.quat_multiply(q, q2)[1:], memoryview(g.quat_multiply(q, q2))
    watched = g.quat_multiply(q, q2)
    ref = weakref.ref(watched)
    del watched
    for _ in range(10):
        g.quat_multiply(q2, q)  # another value, into whatever spare is free
    for out in kept + ([] if ref() is None else [ref()]):  # a weakly held output lives on unchanged, or not at all
        np.testing.assert_array_equal(out, product)
    np.testing.assert_array_equal(view, product[1:])
    np.testing.assert_array_equal(np.asarray(buffer), product)
    assert len({id(out) for out in kept}) == 3
    reshaped = g.quat_multiply(q, q2)
    reshaped.shape = (2, 2)
    retyped = g.quat_multiply(q, q2)
    retyped.dtype = np.int64
    del reshaped, retyped, kept, view, buffer
    for _ in range(3):
        out = g.quat_multiply(q, q2)
        assert out.shape == (4,) and out.dtype == np.float64 and out.flags.c_contiguous and out.flags.writeable
        np.testing.assert_array_equal(out, product)
    del out
    a, b = g.quat_multiply(q, q2), g.quat_multiply(q, q2)
    buffers = {a.ctypes.data, b.ctypes.data}
    del a, b
    taken = [np.empty(4) for _ in range(8)]  # would take the blocks freed had the outputs been freed
    assert g.quat_multiply(q, q2).ctypes.data in buffers and not buffers & {t.ctypes.data for t in taken}


def test_an_unbound_call_and_a_wrong_call_go_to_the_fallback():
    calls = []
    fresh = SingleCall(((4,),), (4,), lambda *v, **k: calls.append((v, k)) or "fallback")
    assert not fresh.bound
    q = np.array([1.0, 0, 0, 0])
    assert fresh(q) == "fallback" and fresh(q, q) == "fallback" and fresh(q=q) == "fallback"
    assert [len(v) for v, _ in calls] == [1, 2, 0] and calls[2][1] == {"q": q}


def test_a_public_function_that_is_its_single_call_behaves_as_the_python_function_it_wraps(rng):
    """Most public functions are their SingleCall itself (``_arrays.public``): the wrapped
    function's name, docstring and signature; keyword arguments and a wrong number of arguments
    handled by that function (the same values, the same TypeError); bound as a method in a class;
    pickled and copied by reference."""
    published = [f for f, _ in CALLS if isinstance(f, SingleCall)]
    assert len(published) >= 20
    for f in published:
        assert f.__doc__ and pickle.loads(pickle.dumps(f)) is f and copy.deepcopy(f) is f
        assert f.__wrapped__.__name__ == f.__name__ and repr(f) == f"<function {f.__name__}>"
    q, q2 = _batch_of(rng)["q"][:2]
    f = g.quat_multiply
    assert list(inspect.signature(f).parameters) == ["q1", "q2"] and "Hamilton" in f.__doc__
    np.testing.assert_array_equal(f(q2=q2, q1=q), f(q, q2))
    np.testing.assert_array_equal(g.quat_slerp(q, q2, t=0.25), g.quat_slerp(q, q2, 0.25))
    for wrong in ((q,), (q, q2, q)):
        with pytest.raises(TypeError, match="quat_multiply"):
            f(*wrong)

    class Holder:
        multiply = g.quat_multiply

    h = Holder()
    assert h.multiply.__self__ is h and h.multiply.__func__ is f and Holder.multiply is f


def test_rejected_elements_raise_the_python_paths_named_error():
    with pytest.raises(NonFiniteError, match=r"q1 = \[nan"):
        g.quat_multiply(np.array([np.nan, 0, 0, 1.0]), np.array([1.0, 0, 0, 0]))
    with pytest.raises(NotUnitQuaternionError, match=r"q0 = \[1"):
        g.quat_slerp(np.array([1.0, 0, 0, 0.1]), np.array([1.0, 0, 0, 0]), 0.5)
    with pytest.raises(NotARotationError, match="R"):
        g.matrix_to_quat(2.0 * np.eye(3))
    with pytest.raises(NonFiniteError, match="yaw"):
        g.euler_zyx_to_matrix(float("inf"), 0.0, 0.0)


def test_a_new_process_loads_the_single_path_instead_of_compiling():
    """Numba keys a cached closure by its pickled cells, which hold ids drawn anew each process;
    the single-element cfuncs are keyed by name (``_arrays._NamedCache``), so the second process
    to call a function compiles nothing."""
    script = (
        "import json, numpy as np\n"
        "from numba.core.event import install_listener, Listener\n"
        "import occmap.geometry as g\n"
        "class Count(Listener):\n"
        "    n = 0\n"
        "    def on_start(self, event): Count.n += 1\n"
        "    def on_end(self, event): pass\n"
        "q = np.array([1.0, 0, 0, 0])\n"
        "with install_listener('numba:compile', Count()):\n"
        "    g.quat_multiply(q, q); g.quat_slerp(q, q, 0.5); g.euler_zyx_to_matrix(0.1, 0.2, 0.3); g.exp_so3(q[1:])\n"
        "print(json.dumps(Count.n))\n"
    )
    counts = [json.loads(subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True,
                                        timeout=600).stdout) for _ in range(2)]
    assert counts[1] == 0, counts
