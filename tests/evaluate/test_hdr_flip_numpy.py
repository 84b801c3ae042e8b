"""cornell_harness.evaluate.hdr_flip_numpy, HDR-FLIP without numba: the numba path's map, bit for bit, on the
stored Cornell box's noise batch against its reference, in a process where numba cannot be imported."""

from __future__ import annotations

import ctypes
import subprocess
import sys

import numpy as np
import pytest

from tests.conftest import CORNELL, ROOT
from cornell_harness.evaluate import flip, hdr_flip, hdr_flip_numpy
from cornell_harness.store.exr import read_exr

pytest.importorskip("numba")  # the reference for the comparison is the numba path

#: Run with numba made unimportable, as in a core install: the maps of the stored noise batch and of a brighter
#: copy of the reference, against the reference, saved to argv[1].
_WITHOUT_NUMBA = """
import sys
sys.modules["numba"] = None
import numpy as np
from cornell_harness.evaluate import flip, hdr_flip
from cornell_harness.store.exr import read_exr
assert hdr_flip.njit is None
ref, noise = read_exr(sys.argv[2]), read_exr(sys.argv[3])
np.save(sys.argv[1], np.stack([flip.flip_map(noise, ref), flip.flip_map(ref * 1.5, ref)]))
"""


def test_without_numba_the_map_is_the_numba_paths_bit_for_bit(tmp_path):
    ref_path, noise_path = CORNELL.parent / "reference.exr", CORNELL.parent / "noise.exr"
    ref, noise = read_exr(ref_path), read_exr(noise_path)
    out = tmp_path / "maps.npy"
    proc = subprocess.run([sys.executable, "-c", _WITHOUT_NUMBA, str(out), str(ref_path), str(noise_path)],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert hdr_flip.njit is not None
    expected = np.stack([flip.flip_map(noise, ref), flip.flip_map(ref * 1.5, ref)])
    got = np.load(out)
    assert 0.01 < np.mean(expected[0]) < 0.5  # a real comparison, not a map of zeros
    np.testing.assert_array_equal(got, expected)
    assert [float(np.mean(m)) for m in got] == [float(np.mean(m)) for m in expected]


def test_each_plane_kernel_matches_its_numba_namesake():
    ref = flip.flip_input(read_exr(CORNELL.parent / "reference.exr"))
    noise = flip.flip_input(read_exr(CORNELL.parent / "noise.exr"))
    p = flip.flip_parameters(ref)
    spatial, _ = hdr_flip.filters(p["ppd"])
    tc, scale = np.asarray(flip.ACES_COEFFICIENTS, np.float32), flip.exposure_scales(p)[-1]
    planes = [np.empty((4, *ref.shape[:2]), np.float32) for _ in range(2)]
    hdr_flip._exposed_ycxcz(noise, scale, tc, planes[0])
    hdr_flip_numpy.exposed_ycxcz(noise, scale, tc, planes[1])
    np.testing.assert_array_equal(*planes)
    rows = [np.empty_like(planes[0]) for _ in range(2)]
    hdr_flip._filter_rows(planes[0], hdr_flip._COLOUR_ROWS, spatial, rows[0])
    hdr_flip_numpy.filter_rows(planes[0], hdr_flip._COLOUR_ROWS, spatial, rows[1])
    np.testing.assert_array_equal(*rows)
    columns = [np.empty_like(planes[0]) for _ in range(2)]
    hdr_flip._filter_columns(rows[0], hdr_flip._COLOUR_COLUMNS, spatial, columns[0])
    hdr_flip_numpy.filter_columns(rows[0], hdr_flip._COLOUR_COLUMNS, spatial, columns[1])
    np.testing.assert_array_equal(*columns)
    ref_side, test_side = (hdr_flip.image_side(x, scale, tc, p["ppd"]) for x in (ref, noise))
    errors = [np.zeros(ref.shape[:2], np.float32) for _ in range(2)]
    hdr_flip._keep_largest_error(ref_side, test_side, errors[0])
    hdr_flip_numpy.keep_largest_error(ref_side, test_side, errors[1], hdr_flip._max_distance())
    assert np.count_nonzero(errors[0]) > errors[0].size // 2
    np.testing.assert_array_equal(*errors)


def test_powf_is_the_c_librarys_where_a_float64_power_rounds_the_other_way():
    libc = ctypes.CDLL(None)
    libc.powf.restype, libc.powf.argtypes = ctypes.c_float, [ctypes.c_float, ctypes.c_float]
    rng = np.random.default_rng(3)
    bases = rng.random(200_000).astype(np.float32)
    exponent = np.float32(1.0) / np.float32(3.0)
    expected = np.array([libc.powf(b, exponent) for b in bases.tolist()], np.float32)
    rounded = np.power(bases.astype(np.float64), np.float64(exponent)).astype(np.float32)
    assert np.count_nonzero(rounded != expected) > 10  # the cases powf settles: they exist
    np.testing.assert_array_equal(hdr_flip_numpy.powf(bases, exponent), expected)
    assert hdr_flip_numpy.powf(bases[7], exponent) == expected[7]  # a scalar too
