"""No copy of the input beyond one conversion, measured with tracemalloc (which sees numpy's
allocations) on 10 M points: a C-contiguous float64 array goes through `crease.extract`
without any (the extension views it in place), and every other input is converted once, into
the (N, 3) float64 array the extension then views."""

import tracemalloc

import crease
import laspy
import numpy as np
import pytest

N = 10_000_000


@pytest.fixture(scope="module")
def cube_points() -> np.ndarray:
    """N points on the faces of the unit cube."""
    rng = np.random.default_rng(1)
    p = rng.random((N, 3))
    face = rng.integers(0, 6, N)
    p[np.arange(N), face % 3] = face // 3
    return p


def traced_peak(f):
    """The result of f() and the peak of memory numpy and Python allocated meanwhile."""
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        out = f()
        return out, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_a_float64_array_goes_through_extract_without_a_copy(cube_points):
    assert crease._as_points(cube_points) is cube_points
    curves, peak = traced_peak(lambda: crease.extract(cube_points))
    assert len(curves) == 12
    # (The curves themselves and a few objects: under 1 % of the 240 MB array.)
    assert peak < 0.01 * cube_points.nbytes, f"{peak / 1e6:.1f} MB allocated for a {cube_points.nbytes / 1e6:.0f} MB array"


def as_laspy(points: np.ndarray) -> laspy.LasData:
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales = np.array([1e-6, 1e-6, 1e-6])
    header.offsets = np.zeros(3)
    las = laspy.LasData(header, points=laspy.ScaleAwarePointRecord.zeros(len(points), header=header))
    for k, name in enumerate("XYZ"):
        setattr(las, name, np.round(points[:, k] / 1e-6).astype(np.int32))
    return las


@pytest.mark.parametrize("kind", ["float32", "fortran", "structured", "laspy"])
def test_any_other_input_is_converted_once(cube_points, kind):
    if kind == "float32":
        given = cube_points.astype(np.float32)
    elif kind == "fortran":
        given = np.asfortranarray(cube_points)
    elif kind == "structured":
        given = np.zeros(N, dtype=[("X", "f8"), ("Y", "f8"), ("Z", "f8"), ("Intensity", "u2")])
        given["X"], given["Y"], given["Z"] = cube_points.T
    else:
        given = as_laspy(cube_points)
    converted, peak = traced_peak(lambda: crease._as_points(given))
    assert converted.shape == (N, 3) and converted.dtype == np.float64 and converted.flags.c_contiguous
    one = converted.nbytes
    assert one <= peak < 1.01 * one, f"{kind}: {peak / 1e6:.1f} MB allocated for a conversion of {one / 1e6:.0f} MB"
    if kind == "laspy":
        assert np.array_equal(converted[:, 0], np.asarray(given.x))
    elif kind != "float32":
        assert np.array_equal(converted, cube_points)
