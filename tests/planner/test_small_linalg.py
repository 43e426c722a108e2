"""planner.small_linalg: numpy.linalg's inverse and log-determinant, bit for bit, without its per-call overhead."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from planner import small_linalg


def spd_stack(rng: np.random.Generator, count: int, n: int, scale: float = 1.0) -> np.ndarray:
    a = rng.normal(size=(count, n, n)) * scale
    return a @ np.transpose(a, (0, 2, 1)) + 1e-3 * np.eye(n)


@pytest.mark.parametrize("n", [3, 4])
def test_inverse_and_logdet_are_numpys_bit_for_bit(n: int) -> None:
    rng = np.random.default_rng(7)
    for count in (1, 2, 11, 64):
        for scale in (1e-4, 1.0, 1e3):
            a = spd_stack(rng, count, n, scale)
            general = rng.normal(size=(count, n, n))  # not symmetric, some negative determinants
            for m in (a, general):
                assert np.array_equal(small_linalg.inv(m), np.linalg.inv(m))
                assert np.array_equal(small_linalg.logdet(m), np.linalg.slogdet(m)[1])
    single = spd_stack(rng, 1, 3)[0]
    assert np.array_equal(small_linalg.inv(single), np.linalg.inv(single))  # one matrix, no stack
    assert small_linalg.logdet(single).shape == ()


def test_a_singular_matrix_raises_as_numpy_does_and_warns_nothing() -> None:
    stack = np.stack([np.eye(3), np.zeros((3, 3))])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning from the gufunc's "invalid" flag on the way
        with pytest.raises(np.linalg.LinAlgError):
            small_linalg.inv(stack)
    assert small_linalg.logdet(stack)[1] == -np.inf  # numpy's slogdet: sign 0, log |det| = -inf
    assert np.array_equal(small_linalg.logdet(stack), np.linalg.slogdet(stack)[1])


def test_other_dtypes_go_to_numpy() -> None:
    a = spd_stack(np.random.default_rng(1), 3, 3).astype(np.float32)
    assert small_linalg.inv(a).dtype == np.float32
    assert np.array_equal(small_linalg.inv(a), np.linalg.inv(a))
    assert np.array_equal(small_linalg.logdet(a), np.linalg.slogdet(a)[1])
