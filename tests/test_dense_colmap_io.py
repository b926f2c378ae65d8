"""COLMAP dense array format: exact bytes, round trips, clear errors."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scenebot.dense.colmap_io import read_array, write_array


def test_layout_matches_colmap(tmp_path):
    # value(row, col, ch) = data[ch * W * H + row * W + col], header "W&H&C&"
    arr = np.arange(2 * 3 * 2, dtype=np.float32).reshape(2, 3, 2)  # H=2, W=3, C=2
    path = tmp_path / "a.bin"
    write_array(path, arr)
    raw = path.read_bytes()
    assert raw.startswith(b"3&2&2&")
    data = np.frombuffer(raw[len(b"3&2&2&") :], dtype="<f4")
    for r in range(2):
        for c in range(3):
            for ch in range(2):
                assert data[ch * 3 * 2 + r * 3 + c] == arr[r, c, ch]


def test_colmap_reader_convention(tmp_path):
    # the reader of colmap/scripts/python/read_write_dense.py: Fortran (W, H, C), transposed
    arr = np.random.default_rng(0).random((4, 5, 3)).astype(np.float32)
    path = tmp_path / "n.bin"
    write_array(path, arr)
    raw = path.read_bytes()
    payload = np.frombuffer(
        raw[raw.index(b"&", raw.index(b"&", raw.index(b"&") + 1) + 1) + 1 :], "<f4"
    )
    colmap = np.transpose(payload.reshape((5, 4, 3), order="F"), (1, 0, 2))
    np.testing.assert_array_equal(colmap, arr)


@settings(max_examples=25, deadline=None)
@given(
    h=st.integers(1, 12),
    w=st.integers(1, 12),
    c=st.sampled_from([1, 3]),
    seed=st.integers(0, 2**16),
)
def test_round_trip(tmp_path_factory, h, w, c, seed):
    arr = np.random.default_rng(seed).normal(size=(h, w, c)).astype(np.float32)
    path = tmp_path_factory.mktemp("rt") / "x.bin"
    write_array(path, arr if c == 3 else arr[:, :, 0])
    back = read_array(path)
    np.testing.assert_array_equal(back, arr if c == 3 else arr[:, :, 0])


def test_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        read_array(tmp_path / "missing.bin")
    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"3&2&1&" + np.zeros(5, "<f4").tobytes())
    with pytest.raises(ValueError, match="holds 5 floats"):
        read_array(bad)
    bad.write_bytes(b"garbage without header")
    with pytest.raises(ValueError, match="header"):
        read_array(bad)
    with pytest.raises(ValueError, match="expects"):
        write_array(tmp_path / "x.bin", np.zeros(3))
