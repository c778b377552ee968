"""Borrowed views: the same memory, no reference counting, and the caller's arrays unharmed."""

import sys

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from drivelab.sim.core.borrow import borrowed


@njit
def _scale_rows(a, b, factor):
    a, b = borrowed((a, b))
    total = 0.0
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            a[i, j] *= factor
            total += a[i, j]
        b[i] += i
    return total


@njit
def _shape_and_strides(a):
    (view,) = borrowed((a,))
    return view.shape, view.strides


def test_a_borrowed_view_reads_and_writes_the_arguments_memory():
    a, b = np.arange(12.0).reshape(3, 4), np.zeros(3, dtype=np.int64)
    assert _scale_rows(a, b, 2.0) == 2.0 * np.arange(12.0).sum()
    np.testing.assert_array_equal(a, 2.0 * np.arange(12.0).reshape(3, 4))
    np.testing.assert_array_equal(b, [0, 1, 2])


def test_a_borrowed_view_keeps_a_strided_arrays_layout():
    base = np.zeros((6, 10))
    view = base[::2, 1:8:3]  # neither C nor F contiguous
    assert _shape_and_strides(view) == (view.shape, view.strides)
    _scale_rows(view, np.zeros(view.shape[0], dtype=np.int64), 1.0)  # compiles for the 'A' layout
    view[...] = 1.0
    _scale_rows(view, np.zeros(view.shape[0], dtype=np.int64), 3.0)
    assert base.sum() == 3.0 * view.size and (base[::2, 1:8:3] == 3.0).all()


def test_borrowing_leaves_the_callers_reference_counts_as_they_were():
    a, b = np.ones((4, 4)), np.zeros(4, dtype=np.int64)
    _scale_rows(a, b, 1.0)
    before = sys.getrefcount(a), sys.getrefcount(b)
    for _ in range(1000):
        _scale_rows(a, b, 1.0)
    assert (sys.getrefcount(a), sys.getrefcount(b)) == before


@pytest.mark.parametrize("argument", [np.zeros(3), (np.zeros(3), 1.0)])
def test_only_a_tuple_of_arrays_can_be_borrowed(argument):
    @njit
    def borrow(x):
        return borrowed(x)

    with pytest.raises(TypingError):
        borrow(argument)
