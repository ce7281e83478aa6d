"""lpvest's random generator (lpvest.core._rng): numpy's PCG64 raw words, uniforms,
normals by AS 241 with the module's own logarithm, multivariate draws. The same
bits in the C runtime are checked in tests/test_native_core.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ndtri

from lpvest.core._errors import ArgumentError, ArgumentTypeError
from lpvest.core._rng import Stream, as_stream, log, lower_times, normal_quantile, psd_cholesky
from tests.tolerances import EPS, roundoff


@pytest.mark.parametrize("seed", [0, 1, 2026, 2**31 - 1, 2**40 + 3])
def test_raw_words_are_numpys_pcg64_seeded_by_seedsequence(seed):
    assert np.array_equal(Stream(seed).raw(500), np.random.default_rng(seed).bit_generator.random_raw(500))


def test_uniforms_are_the_top_53_bits_as_numpys_random():
    assert np.array_equal(Stream(5).uniform(1000), np.random.default_rng(5).random(1000))


def test_a_generator_or_bit_generator_is_used_as_given():
    gen = np.random.default_rng(3)
    a = as_stream(gen).normal(4)
    b = Stream(3).normal(8)[4:]
    assert np.array_equal(as_stream(gen).normal(4), b)  # the generator advanced by 4 words
    assert a.shape == (4,)
    s = Stream(9)
    assert as_stream(s) is s


def test_bad_seeds_are_refused():
    with pytest.raises(ArgumentError, match="non-negative integer; found -1"):
        Stream(-1)
    with pytest.raises(ArgumentTypeError, match="not str"):
        as_stream("7")  # type: ignore[arg-type]


def test_the_logarithm_is_within_one_unit_in_the_last_place():
    # fdlibm's e_log.c is accurate to < 1 ulp; the C library's log is too (glibc: correctly
    # rounded in almost every case), so the two differ by at most one spacing of the result
    x = np.concatenate([np.exp(np.linspace(-745.0, 709.0, 20001)),
                        np.random.default_rng(1).random(20000) * 2.0 + 1e-300, [1.0, 2.0, 0.5, 2.0**-1074]])
    ours = log(x)
    ref = np.log(x)
    assert np.all(np.abs(ours - ref) <= np.spacing(np.abs(ref)))
    assert float(log(1.0)) == 0.0


def test_normal_quantile_matches_scipys_to_its_rounding():
    # AS 241 approximates the quantile to ~1e-16 relative (Wichura 1988); its two
    # rational functions of degree 7 are evaluated by Horner's rule, whose error is
    # bounded by gamma_16 (sum |c_i| |r|^i) / |value| (Higham (5.3)), here <= 16 eps
    # times a condition number <= 3 (r >= 0 in the central branch, |r - 1.6| and
    # |r - 5| small in the tails); the tails add the logarithm's 1 ulp, halved by
    # the square root (z ~ sqrt(-2 log p)); scipy's ndtri has its own ~2 eps. Total:
    # 2 (16 * 3 + 1 + 2) eps = 102 eps, relative to max(1, |z|).
    p = np.concatenate([((np.random.default_rng(2).bit_generator.random_raw(200000) >> np.uint64(12))
                         .astype(np.float64) + 0.5) * 2.0**-52, [2.0**-53, 1 - 2.0**-53, 0.5, 0.075, 0.925]])
    z = normal_quantile(p)
    ref = ndtri(p)
    assert np.all(np.abs(z - ref) <= 102 * EPS * np.maximum(1.0, np.abs(ref)))
    assert np.array_equal(normal_quantile(1.0 - p[:1000]), -normal_quantile(p[:1000]))  # odd: p and 1 - p exact


def test_normals_are_standard_normal():
    z = Stream(11).normal(400_000)
    # sample mean and variance of 4e5 standard normals: standard errors 1/632 and sqrt(2)/632
    assert abs(z.mean()) < 5 / math.sqrt(z.size)
    assert abs(z.var() - 1.0) < 5 * math.sqrt(2.0 / z.size)


def test_psd_cholesky_factors_a_semidefinite_covariance():
    L = psd_cholesky(np.array([[4.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 9.0]]))
    assert np.array_equal(L, [[2.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 3.0]])
    P = np.array([[2.0, 0.3], [0.3, 1.0]])
    L = psd_cholesky(P)
    assert L[0, 1] == 0.0
    # a Cholesky factor reproduces P to rounding: sums of 2 products of size <= 2 (Higham (10.5))
    np.testing.assert_allclose(L @ L.T, P, rtol=0, atol=roundoff(2.0, 2, n=2))


def test_gaussian_vector_is_mean_plus_factor_times_normals():
    P = np.array([[2.0, 0.3], [0.3, 1.0]])
    x = Stream(4).gaussian_vector(np.array([1.0, -1.0]), P)
    z = Stream(4).normal(2)
    L = psd_cholesky(P)
    assert x.tolist() == [1.0 + L[0, 0] * z[0], -1.0 + (L[1, 0] * z[0] + L[1, 1] * z[1])]


def test_lower_times_sums_in_column_order():
    L = np.array([[1.0, 0.0], [1e16, 1.0]])
    z = np.array([[1.0, 1.0]])
    assert lower_times(L, z).tolist() == [[1.0, 1e16]]  # (1e16 * 1) + 1 rounds to 1e16
