"""lpvest's random numbers: one documented generator, the same bits in Python and in C.

Every random number an lpvest component draws (a plant's noise and its
initial state, the ``gaussian`` and ``random`` signals of the Scheduler and
Source) comes from :class:`Stream`, defined bit for bit so that the native
FMUs (C, ``lpvest/fmi/native/runtime/lpv_rng.c``) give the same numbers as
the library for the same seed, on every platform:

1. **Raw words.** The 64-bit outputs of numpy's ``PCG64`` bit generator seeded
   through ``numpy.random.SeedSequence(seed)`` (what
   ``numpy.random.default_rng(seed)`` uses; numpy keeps bit-generator streams
   stable across versions). The C runtime implements PCG64 (XSL-RR, 128-bit
   state) and SeedSequence's hashing.
2. **Uniforms** in ``[0, 1)``: the top 53 bits, ``(w >> 11) * 2**-53`` (numpy's
   ``random()``); ``uniform(-1, 1)`` is ``-1 + 2 u``, as numpy computes it.
3. **Normals**: one raw word per normal, ``u = ((w >> 12) + 1/2) * 2**-52``
   (strictly inside ``(0, 1)``, every value exact), then the inverse of the
   normal distribution function, Wichura's AS 241 (PPND16, relative accuracy
   about 1e-16), with its logarithm :func:`log` written here with ``+ - * /``,
   ``sqrt`` and the exact ``frexp`` only (fdlibm's ``e_log.c`` polynomial). Those
   operations are correctly rounded in IEEE arithmetic, in numpy's array loops,
   Python floats and C compiled without contraction (``-ffp-contract=off``), so
   the normals are the same bits everywhere. No rejection: draw ``k`` is raw
   word ``k``.
4. **Vectors**: ``x = mean + L z`` with ``L`` a Cholesky factor, each entry
   summed in column order, ``L[i, 0] z[0] + L[i, 1] z[1] + ...``
   (:func:`lower_times`); a covariance that is only semidefinite gets a factor
   with zero columns where a pivot vanishes (:func:`psd_cholesky`).

Examples
--------
>>> s = Stream(0)
>>> s.normal(3)
array([ 0.35034923, -0.61345818, -1.73949889])
>>> Stream(0).raw(1)[0] == np.random.default_rng(0).bit_generator.random_raw()
np.True_
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ._errors import ArgumentError, ArgumentTypeError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["Stream", "as_stream", "normal_quantile", "log", "normals_from_raw", "uniforms_from_raw",
           "psd_cholesky", "lower_times"]

_TWO_M52 = 2.0**-52
_TWO_M53 = 2.0**-53

# fdlibm e_log.c (Sun Microsystems, 1993): ln 2 split in two, and the minimax
# coefficients of log((1 + s) / (1 - s)) = 2 s + s R(s^2)
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_LG = (6.666666666666735130e-01, 3.999999999940941908e-01, 2.857142874366239149e-01, 2.222219843214978396e-01,
       1.818357216161805012e-01, 1.531383769920937332e-01, 1.479819860511658591e-01)
_SQRT2 = 1.4142135623730951

# AS 241 (Wichura 1988), PPND16: numerators and denominators, highest power first
_A = (2.5090809287301226727e+3, 3.3430575583588128105e+4, 6.7265770927008700853e+4, 4.5921953931549871457e+4,
      1.3731693765509461125e+4, 1.9715909503065514427e+3, 1.3314166789178437745e+2, 3.3871328727963666080e+0)
_B = (5.2264952788528545610e+3, 2.8729085735721942674e+4, 3.9307895800092710610e+4, 2.1213794301586595867e+4,
      5.3941960214247511077e+3, 6.8718700749205790830e+2, 4.2313330701600911252e+1, 1.0)
_C = (7.74545014278341407640e-4, 2.27238449892691845833e-2, 2.41780725177450611770e-1, 1.27045825245236838258e+0,
      3.64784832476320460504e+0, 5.76949722146069140550e+0, 4.63033784615654529590e+0, 1.42343711074968357734e+0)
_D = (1.05075007164441684324e-9, 5.47593808499534494600e-4, 1.51986665636164571966e-2, 1.48103976427480074590e-1,
      6.89767334985100004550e-1, 1.67638483018380384940e+0, 2.05319162663775882187e+0, 1.0)
_E = (2.01033439929228813265e-7, 2.71155556874348757815e-5, 1.24266094738807843860e-3, 2.65321895265761230930e-2,
      2.96560571828504891230e-1, 1.78482653991729133580e+0, 5.46378491116411436990e+0, 6.65790464350110377720e+0)
_F = (2.04426310338993978564e-15, 1.42151175831644588870e-7, 1.84631831751005468180e-5, 7.86869131145613259100e-4,
      1.48753612908506148525e-2, 1.36929880922735805310e-1, 5.99832206555887937690e-1, 1.0)


def _horner(coef: tuple[float, ...], r: np.ndarray) -> np.ndarray:
    acc = coef[0] * r + coef[1]
    for c in coef[2:]:
        acc = acc * r + c
    return acc


def log(x: ArrayLike) -> np.ndarray:
    """The natural logarithm of ``x > 0`` (finite), from ``+ - * /`` and ``frexp`` only.

    fdlibm's algorithm (``e_log.c``): ``x = 2^k (1 + f)`` with
    ``sqrt(2)/2 <= 1 + f < sqrt(2)``, ``s = f / (2 + f)``,
    ``log(1 + f) = f - (f^2/2 - s (f^2/2 + R(s^2)))`` with fdlibm's minimax
    ``R``, plus ``k ln 2`` in two parts. Accurate to about one unit in the
    last place; the same bits in numpy and in the C runtime (module notes).

    Parameters
    ----------
    x : array_like
        Positive finite numbers (not checked).

    Returns
    -------
    ndarray
        ``log(x)``, of the shape of ``x``.

    Examples
    --------
    >>> float(log(1.0)), bool(abs(float(log(10.0)) - math.log(10.0)) <= 2e-15)
    (0.0, True)
    """
    x = np.asarray(x, dtype=np.float64)
    m, e = np.frexp(x)  # x = m 2^e, m in [1/2, 1): exact
    m2 = m * 2.0  # [1, 2): exact
    big = m2 > _SQRT2
    m2 = np.where(big, m, m2)
    k = (e - 1 + big).astype(np.float64)
    f = m2 - 1.0  # exact (Sterbenz)
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * (_LG[1] + w * (_LG[3] + w * _LG[5]))
    t2 = z * (_LG[0] + w * (_LG[2] + w * (_LG[4] + w * _LG[6])))
    r = t2 + t1
    hfsq = 0.5 * f * f
    return k * _LN2_HI - ((hfsq - (s * (hfsq + r) + k * _LN2_LO)) - f)


def normal_quantile(p: ArrayLike) -> np.ndarray:
    """The standard normal quantile (inverse distribution function) of ``p``
    in ``(0, 1)``: Wichura's AS 241 (PPND16) with :func:`log`.

    Parameters
    ----------
    p : array_like
        Probabilities strictly between 0 and 1 (not checked).

    Returns
    -------
    ndarray
        ``z`` with ``Phi(z) = p``, of the shape of ``p``.

    Examples
    --------
    >>> float(normal_quantile(0.5)), round(float(normal_quantile(0.975)), 12)
    (0.0, 1.95996398454)
    """
    p = np.asarray(p, dtype=np.float64)
    q = p - 0.5
    central = np.abs(q) <= 0.425
    r = 0.180625 - q * q
    x_central = (_horner(_A, r) * q) / _horner(_B, r)
    tail = np.where(q <= 0.0, p, 1.0 - p)
    tail = np.where(central, 0.5, tail)  # any value in (0, 1): the central branch is taken there
    rt = np.sqrt(-log(tail))
    near = rt <= 5.0
    r1 = rt - 1.6
    r2 = rt - 5.0
    x_near = _horner(_C, r1) / _horner(_D, r1)
    x_far = _horner(_E, r2) / _horner(_F, r2)
    x_tail = np.where(near, x_near, x_far)
    x_tail = np.where(q < 0.0, -x_tail, x_tail)
    return np.where(central, x_central, x_tail)


def uniforms_from_raw(raw: np.ndarray) -> np.ndarray:
    """Uniform doubles in ``[0, 1)`` from raw 64-bit words: ``(w >> 11) * 2**-53``.

    Parameters
    ----------
    raw : array_like of uint64, any shape
        Raw words (e.g. from :meth:`Stream.raw`).

    Returns
    -------
    ndarray of float64, shape of ``raw``
        One uniform per word.
    """
    return (np.asarray(raw, dtype=np.uint64) >> np.uint64(11)).astype(np.float64) * _TWO_M53


def normals_from_raw(raw: np.ndarray) -> np.ndarray:
    """Standard normals from raw 64-bit words, one word each (module notes, 3.).

    Parameters
    ----------
    raw : array_like of uint64, any shape
        Raw words (e.g. from :meth:`Stream.raw`).

    Returns
    -------
    ndarray of float64, shape of ``raw``
        One normal per word.
    """
    u = ((np.asarray(raw, dtype=np.uint64) >> np.uint64(12)).astype(np.float64) + 0.5) * _TWO_M52
    return normal_quantile(u)


class Stream:
    """The random numbers of one seeded lpvest component (see the module notes).

    Parameters
    ----------
    seed : int or numpy.random.BitGenerator or numpy.random.Generator or None
        A non-negative integer seed (``PCG64(SeedSequence(seed))``), a bit
        generator (its raw words are used, and it advances), a Generator (its
        bit generator), or ``None`` (fresh entropy).

    Examples
    --------
    >>> s = Stream(3)
    >>> a = s.normal(2); state = s.state; b = s.normal(2)
    >>> s.state = state; bool((s.normal(2) == b).all())
    True
    """

    __slots__ = ("_bits",)

    def __init__(self, seed: int | np.random.BitGenerator | np.random.Generator | None = 0) -> None:
        if isinstance(seed, np.random.Generator):
            self._bits: np.random.BitGenerator = seed.bit_generator
        elif isinstance(seed, np.random.BitGenerator):
            self._bits = seed
        elif seed is None or (isinstance(seed, int | np.integer) and not isinstance(seed, bool)):
            if seed is not None and seed < 0:
                raise ArgumentError(f"a seed must be a non-negative integer; found {seed}")
            self._bits = np.random.PCG64(np.random.SeedSequence(None if seed is None else int(seed)))
        else:
            raise ArgumentTypeError(f"a random stream needs an integer seed, a numpy Generator or None, "
                                    f"not {type(seed).__name__}")

    @property
    def bit_generator(self) -> np.random.BitGenerator:
        """The bit generator the raw words come from."""
        return self._bits

    @property
    def state(self) -> dict[str, object]:
        """The bit generator's state (``bit_generator.state``); assign to restore it."""
        return dict(self._bits.state)

    @state.setter
    def state(self, value: dict[str, object]) -> None:
        self._bits.state = value

    def raw(self, size: int) -> np.ndarray:
        """The next ``size`` raw 64-bit words (uint64).

        Parameters
        ----------
        size : int
            Number of words; the bit generator advances by as many.

        Returns
        -------
        ndarray of uint64, shape (size,)
            The words.
        """
        return np.asarray(self._bits.random_raw(int(size)), dtype=np.uint64).reshape(-1)

    def uniform(self, size: int | tuple[int, ...]) -> np.ndarray:
        """Uniforms in ``[0, 1)``, one raw word each, in C (row-major) order.

        Parameters
        ----------
        size : int or tuple of int
            Shape of the draw.

        Returns
        -------
        ndarray of float64, shape (size,) or size
            The uniforms.
        """
        shape = (size,) if isinstance(size, int | np.integer) else tuple(size)
        return uniforms_from_raw(self.raw(int(np.prod(shape, dtype=np.int64)))).reshape(shape)

    def normal(self, size: int | tuple[int, ...]) -> np.ndarray:
        """Standard normals, one raw word each, in C (row-major) order.

        Parameters
        ----------
        size : int or tuple of int
            Shape of the draw.

        Returns
        -------
        ndarray of float64, shape (size,) or size
            The normals.
        """
        shape = (size,) if isinstance(size, int | np.integer) else tuple(size)
        return normals_from_raw(self.raw(int(np.prod(shape, dtype=np.int64)))).reshape(shape)

    def gaussian_vector(self, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
        """One draw of ``N(mean, cov)`` (``cov`` positive semidefinite, checked
        by the caller): ``mean + L z`` with ``L = psd_cholesky(cov)``, ``z``
        standard normal (``n`` words, also where a column of ``L`` is zero).

        Parameters
        ----------
        mean : array_like, shape (n,)
            The mean (flattened).
        cov : array_like, shape (n, n)
            The covariance, symmetric positive semidefinite; only its lower
            triangle is read.

        Returns
        -------
        ndarray, shape (n,)
            The draw.
        """
        m = np.asarray(mean, dtype=np.float64).reshape(-1)
        return m + self.correlated(psd_cholesky(cov), 1)[0]

    def correlated(self, factor: np.ndarray, size: int) -> np.ndarray:
        """``size`` draws of ``L z`` (``z`` standard normal, ``L = factor``
        lower triangular (n, n)), shape ``(size, n)`` (:func:`lower_times`).

        Parameters
        ----------
        factor : array_like, shape (n, n)
            ``L``; the entries above the diagonal are not read.
        size : int
            Number of draws; ``size * n`` words are used, in row-major order.

        Returns
        -------
        ndarray, shape (size, n)
            Row ``k`` is ``L z_k``.
        """
        L = np.asarray(factor, dtype=np.float64)
        return lower_times(L, self.normal((int(size), L.shape[0])))


def as_stream(rng: int | np.random.Generator | np.random.BitGenerator | Stream | None) -> Stream:
    """A :class:`Stream` from a seed, a numpy Generator or bit generator (its
    raw words), a Stream (itself) or ``None`` (fresh entropy).

    Parameters
    ----------
    rng : int, numpy.random.Generator, numpy.random.BitGenerator, Stream or None
        The source, as above.

    Returns
    -------
    Stream
        The stream (a given Stream is returned as it is).

    Raises
    ------
    ArgumentError
        A negative seed.
    ArgumentTypeError
        Anything else.
    """
    if isinstance(rng, Stream):
        return rng
    if rng is not None and not isinstance(rng, int | np.integer | np.random.Generator | np.random.BitGenerator):
        raise ArgumentTypeError(f"rng must be a numpy Generator, an integer seed or None, not {type(rng).__name__}")
    return Stream(rng)


def lower_times(L: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``z @ L.T`` for a lower triangular ``L`` (n, n) and rows ``z`` (T, n),
    each entry summed in column order ``L[i, 0] z[:, 0] + L[i, 1] z[:, 1] + ...``
    (``j <= i``): the order the C runtime sums in, so both give the same bits.

    Parameters
    ----------
    L : ndarray, shape (n, n)
        Lower triangular (the entries above the diagonal are not read).
    z : ndarray, shape (T, n)
        The vectors, one per row.

    Returns
    -------
    ndarray, shape (T, n)
        Row ``t`` is ``L z[t]``.
    """
    n = L.shape[0]
    z = np.asarray(z, dtype=np.float64)
    out = np.empty(z.shape)
    for i in range(n):
        acc = L[i, 0] * z[:, 0]
        for j in range(1, i + 1):
            acc = acc + L[i, j] * z[:, j]
        out[:, i] = acc
    return out


def psd_cholesky(P: np.ndarray) -> np.ndarray:
    """A lower triangular ``L`` with ``L L^T = P`` for a symmetric positive
    semidefinite ``P``: the textbook (Cholesky-Banachiewicz) recurrence, with
    a column of zeros where a pivot is at most ``n eps max(diag P)`` (a
    direction of zero variance). The C runtime computes the same bits.

    Parameters
    ----------
    P : ndarray, shape (n, n)
        Symmetric positive semidefinite (checked by the caller); only its
        lower triangle is read.

    Returns
    -------
    L : ndarray, shape (n, n)
        Lower triangular.

    Examples
    --------
    >>> psd_cholesky(np.array([[4.0, 2.0], [2.0, 1.0]]))
    array([[2., 0.],
           [1., 0.]])
    """
    a = np.asarray(P, dtype=np.float64).tolist()
    n = len(a)
    scale = max((a[i][i] for i in range(n)), default=0.0)
    tol = n * 2.220446049250313e-16 * scale
    L = [[0.0] * n for _ in range(n)]
    for j in range(n):
        d = a[j][j]
        for k in range(j):
            d -= L[j][k] * L[j][k]
        if d <= tol:
            continue  # a zero pivot: column j stays zero
        ljj = math.sqrt(d)
        L[j][j] = ljj
        for i in range(j + 1, n):
            s = a[i][j]
            for k in range(j):
                s -= L[i][k] * L[j][k]
            L[i][j] = s / ljj
    return np.array(L, dtype=np.float64).reshape(n, n)
