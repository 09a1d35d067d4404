"""Exact response of one linear stiffness configuration of a shear building to affine forcing.

Between yield and unloading events a bilinear shear building is linear: every storey has a
fixed tangent stiffness ``kt[i]`` (``k[i]`` elastic, ``alpha k[i]`` yielded) and a constant
offset force.  With the state ``z = [u; v]`` (floor displacements and velocities relative to
the ground) and a segment time ``s`` in ``[0, L]``

    z' = A z + b0 + b1 s,   A = [[0, I], [-M^-1 Kt, -M^-1 C]],
    b0 = [0; M^-1 p - 1 ag0],   b1 = [0; -1 ag1],

where ``ag(s) = ag0 + ag1 s`` is the ground acceleration (piecewise linear between record
samples: first-order hold) and ``p`` the constant net floor force (external force minus the
storeys' offset forces).  The forcing vector of a segment is ``w = [ag0, ag1, p_1 .. p_n]``.

Method (:class:`Configuration`): ``A = V diag(lam) V^-1`` is diagonalised once per
configuration (cached by the caller); in modal coordinates ``q = V^-1 z`` every mode obeys
``q' = lam q + beta0 + beta1 s`` and its exact solution is

    q(s) = e^{lam s} q(0) + s phi1(lam s) beta0 + s^2 phi2(lam s) beta1,
    phi1(x) = (e^x - 1) / x,   phi2(x) = (e^x - 1 - x) / x^2,

valid for every ``lam`` including 0 (a mechanism with ``alpha = 0``): there is no division by
an eigenvalue.  So the solution can be evaluated at any time of a segment for the cost of a
few vector operations, which is what locating events and in-step peaks needs.  A defective
``A`` (only for an undamped mechanism) or a nearly defective one is refused (condition number
of ``V`` above ``MAX_CONDITION``): the modal form would lose digits there.

Energies of a segment: ``int v' C v ds`` and ``-int (1'M v) ag ds`` are integrated by
Gauss-Legendre quadrature (``GAUSS_POINTS`` per chunk, chunks no longer than
``CHUNK_RATE / max|lam|``) of the exact solution.  The integrands are sums of exponentials
``e^{mu s}`` (``|mu| <= 2 max|lam|``) and low-degree polynomials; for ``|mu| L_chunk <= 4``
and 10 points the quadrature error is below 1e-18 relative (Gauss-Legendre remainder
``(b - a)^(2m+1) (m!)^4 / ((2m+1) ((2m)!)^3) max|f^(2m)|``), i.e. the energies are exact to
round-off like the state.

:meth:`Configuration.segment_map` turns one segment length into real matrices (state map and
the two energy quadratic forms) so that a segment of a repeated length (a record interval, a
communication step) costs one matrix-vector product.

Bounds for event and peak searches (:func:`derivative_bound`): for ``Re lam <= 0`` (a damped or
undamped configuration; ``C`` and ``Kt`` are positive semi-definite) the modal amplitudes of
``z'`` grow by at most ``L |beta1|`` over a segment of length ``L``, which bounds every higher
derivative of a linear functional ``c' z`` over the segment.  With a cubic Hermite interpolant
through the end values and slopes (error at most ``max|g''''| L^4 / 384``) this proves, for most
segments in one vectorised test, that no event and no new peak can occur inside; the few that
remain are bisected (:func:`first_root`, :func:`max_abs`).
"""
from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from scipy.linalg import eig, get_lapack_funcs, lu_factor

try:        # what np.einsum calls without `optimize` (its Python wrapper costs as much as the sum)
    from numpy._core.multiarray import c_einsum as _c_einsum
except ImportError:         # another numpy layout: the public function, the same arithmetic
    _c_einsum = np.einsum
try:        # scipy's own workspace query for eig's geev (private: _eigen falls back to eig without it)
    from scipy.linalg.lapack import _compute_lwork
except ImportError:       # pragma: no cover - a scipy that moved it
    _compute_lwork = None

GAUSS_POINTS = 10
_GX, _GW = np.polynomial.legendre.leggauss(GAUSS_POINTS)
GAUSS_NODES = 0.5 * (_GX + 1.0)    # on [0, 1]
GAUSS_WEIGHTS = 0.5 * _GW
CHUNK_RATE = 2.0                   # chunk length <= CHUNK_RATE / max|lam|, see module docstring
MAX_CONDITION = 1e8                # refuse an eigenvector basis that would cost more than 8 digits
PEAK_RTOL = 1e-9                   # relative accuracy to which in-step peak values are established
ROUNDOFF = 1e-12                   # relative round-off of a modal evaluation (cond(V) eps, with margin)
MAX_CHUNKS = 4096                  # bound on one segment's quadrature work
_SERIES_RADIUS = 0.25              # phi functions by series inside this radius
_SERIES_TERMS = 14                 # 0.25^14 / 14! ~ 3e-20
# Lengths that differ by round-off only share their matrices: a host's t_next - t and the
# differences of a record's absolute knot times repeat a length only to the round-off of the
# times (measured in 40 s runs: 10 ms steps from 0.00999999999999801 to 0.010000000000001563 s,
# 10 ms knot intervals from 0.01 - 3e-14 to 0.01 + 3e-14 s); 12 significant digits (a grid of
# 1e-12 to 1e-11 of the length, 1e-13 s at 10 ms) merge them and nothing a host means apart.
LENGTH_DIGITS = 12


def canonical_length(length: float) -> float:
    """``length`` (s) rounded to ``LENGTH_DIGITS`` significant decimal digits: the length whose
    matrices serve every length that differs from it by round-off only.

    The decade is taken from a length larger by a relative 1e-9, so that a length just below a
    power of ten by round-off (0.00999999999999801) rounds to it (0.01) and not onto the finer
    grid of the decade below.  A decimal length (0.01, 0.005) is its own canonical length, so a
    host that repeats it exactly gets the matrices of that very length.
    """
    if not (0.0 < length < math.inf):
        return length
    return round(length, LENGTH_DIGITS - 1 - math.floor(math.log10(length) + 1e-9))


def phi_functions(x, second: bool = True):
    """``(e^x, phi1(x), phi2(x))`` of a complex array, accurate for every x.

    ``phi1 = expm1(x) / x`` (numpy's complex expm1 is accurate to a few ulp near 0; 1 at 0);
    ``phi2`` by its series inside ``|x| < 0.25`` and its closed form outside.  With
    ``second=False`` phi2 is not computed (None): a segment without a ramp of the ground
    acceleration multiplies it by zero.
    """
    # (count_nonzero instead of any(), and no np.where where no element needs it: the same
    # values at a third less per call; the peak searches evaluate the solution hundreds of times)
    x = np.asarray(x, dtype=complex)
    e = np.exp(x)
    if np.count_nonzero(x) < x.size:
        zero = x == 0.0
        phi1 = np.expm1(x) / np.where(zero, 1.0, x)
        phi1[zero] = 1.0
    else:
        phi1 = np.expm1(x) / x
    if not second:
        return e, phi1, None
    mag = np.abs(x)
    small = mag < _SERIES_RADIUS
    any_small = np.count_nonzero(small)
    safe = np.where(small, 1.0, x) if any_small else x
    phi2 = (e - 1.0 - x) / (safe * safe)
    if any_small:
        xs = x[small]
        # Horner for sum x^k/(k+2)!, as many terms as the largest |x| needs for a truncation
        # error below 1e-17 (at most _SERIES_TERMS for |x| < 0.25)
        r = float(mag[small].max())
        terms = next((k for k in range(2, _SERIES_TERMS + 1) if r ** (k + 1) / _FACTORIALS[k + 1] < 1e-17),
                     _SERIES_TERMS)
        # adding complex scalars: the values of adding the float c (as c + 0j), with less
        # conversion per term (in place, out=p2, would not do: numpy's complex product then
        # takes another loop, which rounds some products differently)
        p2 = np.full_like(xs, _INV_FACTORIALS[terms + 2])
        for k in range(terms - 1, -1, -1):
            p2 = p2 * xs + _INV_FACTORIALS_COMPLEX[k + 2]
        phi2[small] = p2
    return e, phi1, phi2


_FACTORIALS = [float(math.factorial(k)) for k in range(_SERIES_TERMS + 3)]
_INV_FACTORIALS = [1.0 / f for f in _FACTORIALS]
_INV_FACTORIALS_COMPLEX = tuple(np.complex128(c) for c in _INV_FACTORIALS)


def hermite_range(g0, g1, d0, d1):
    """Min and max over [0, 1] of the cubic Hermite ``H`` with ``H(0)=g0, H(1)=g1, H'(0)=d0, H'(1)=d1``.

    Vectorised over arrays of equal shape (``d`` are slopes per unit of the normalised time,
    i.e. ``L g'``).  The same IEEE operations as :func:`hermite_range_scalar`, element by
    element (the same branches: a cubic term below ``1e-14`` of the others takes the linear
    root, whatever the discriminant), so the same floats: the in-step peak tests of many
    intervals at once (``ExactPiecewiseLinear._interval_peaks``) decide as one by one.
    """
    a = 3.0 * (g1 - g0) - 2.0 * d0 - d1          # H = g0 + d0 t + a t^2 + b t^3
    b = 2.0 * (g0 - g1) + d0 + d1
    lo = np.minimum(g0, g1)
    hi = np.maximum(g0, g1)
    # H'(t) = d0 + 2 a t + 3 b t^2 = 0; with b ~ 0 the linear root -d0 / (2 a)
    qa, qb = 3.0 * b, 2.0 * a
    disc = qb * qb - 4.0 * qa * d0
    sq = np.sqrt(np.abs(disc))
    quad = np.abs(qa) > 1e-14 * (np.abs(qb) + np.abs(d0)) + 1e-300
    den = np.where(quad, 2.0 * qa, 1.0)
    lin = np.where(qb != 0.0, -d0 / np.where(qb != 0.0, qb, 1.0), -1.0)
    real = ~quad | (disc >= 0.0)                 # the linear root needs no discriminant
    for r in (np.where(quad, (-qb - sq) / den, lin), np.where(quad, (-qb + sq) / den, lin)):
        ok = real & (r > 0.0) & (r < 1.0)
        rr = np.where(ok, r, 0.0)
        h = g0 + rr * (d0 + rr * (a + rr * b))
        lo = np.where(ok, np.minimum(lo, h), lo)
        hi = np.where(ok, np.maximum(hi, h), hi)
    return lo, hi


# below this many elements hermite_ranges goes element by element (measured: 2 us against 26 us for
# 2 elements, 18 against 29 for 32, 36 against 30 for 64)
HERMITE_VECTOR_FROM = 40


def hermite_ranges(g0: np.ndarray, g1: np.ndarray, d0: np.ndarray, d1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`hermite_range` of 1-d arrays, by :func:`hermite_range_scalar` element by element
    below ``HERMITE_VECTOR_FROM`` elements: the same floats (the same IEEE operations), without the
    fifty numpy calls' overhead on a few elements."""
    if g0.size >= HERMITE_VECTOR_FROM:
        return hermite_range(g0, g1, d0, d1)
    lo, hi = [], []
    for a, b, c, d in zip(g0.tolist(), g1.tolist(), d0.tolist(), d1.tolist()):
        low, high = hermite_range_scalar(a, b, c, d)
        lo.append(low)
        hi.append(high)
    return np.array(lo, dtype=float), np.array(hi, dtype=float)


def hermite_range_scalar(g0: float, g1: float, d0: float, d1: float) -> tuple[float, float]:
    """:func:`hermite_range` for floats (the bisection searches call it many times).

    Written out for speed (20,000 calls in a yielding run): the comparisons choose what the
    builtins ``min`` and ``max`` would (the first of equal values), the roots are taken in the
    same order, so the result is the same pair of floats as ``min``/``max`` over a tuple of roots.
    """
    a = 3.0 * (g1 - g0) - 2.0 * d0 - d1
    b = 2.0 * (g0 - g1) + d0 + d1
    if g1 < g0:
        lo, hi = g1, g0
    else:
        lo = g0
        hi = g1 if g1 > g0 else g0
    qa, qb = 3.0 * b, 2.0 * a
    if abs(qa) > 1e-14 * (abs(qb) + abs(d0)) + 1e-300:
        disc = qb * qb - 4.0 * qa * d0
        if disc >= 0.0:
            sq = math.sqrt(disc)
            r = (-qb - sq) / (2.0 * qa)
            if 0.0 < r < 1.0:
                h = g0 + r * (d0 + r * (a + r * b))
                if h < lo:
                    lo = h
                if h > hi:
                    hi = h
            r = (-qb + sq) / (2.0 * qa)
            if 0.0 < r < 1.0:
                h = g0 + r * (d0 + r * (a + r * b))
                if h < lo:
                    lo = h
                if h > hi:
                    hi = h
    elif qb != 0.0:
        r = -d0 / qb
        if 0.0 < r < 1.0:
            h = g0 + r * (d0 + r * (a + r * b))
            if h < lo:
                lo = h
            if h > hi:
                hi = h
    return lo, hi


def bracketed_newton(f, a: float, b: float, fa: float, fb: float, xtol: float,
                     guess: float | None = None, max_iter: int = 100) -> tuple[float, float]:
    """Root of ``f`` (returning ``(value, derivative)``) in ``[a, b]`` with ``fa * fb < 0``.

    Newton's method kept inside the bracket (bisection when a step leaves it or converges
    slowly).  Returns the final bracket ``(x_a_side, x_b_side)``, narrower than ``xtol``: the
    second end has the sign of ``fb``.
    """
    x = 0.5 * (a + b) if guess is None or not (a < guess < b) else guess
    for _ in range(max_iter):
        if b - a <= xtol:
            break
        fx, dfx = f(x)
        if fx == 0.0:
            return x, x
        if (fx < 0.0) == (fa < 0.0):
            a, fa = x, fx
        else:
            b, fb = x, fx
        step = fx / dfx if dfx != 0.0 else math.inf
        nxt = x - step
        if not (a < nxt < b) or abs(step) > 0.5 * (b - a):
            nxt = 0.5 * (a + b)
        elif abs(step) < 0.5 * xtol:
            # converged: probe just across, so that the bracket closes below xtol
            nxt = min(max(x - step + math.copysign(0.5 * xtol, -step if step else 1.0), a), b)
            if not (a < nxt < b):
                nxt = 0.5 * (a + b)
        x = nxt
    return a, b


@dataclass(frozen=True)
class SegmentMap:
    """Real matrices of one configuration and one segment length ``L`` (s).

    ``y = [z0; w]`` with ``w = [ag0, ag1, p]``:  ``z(L) = state @ y``, the watched functions at
    the start ``watch_rows @ z0 = start @ y``, the segment's :class:`Scan` vector ``= scan @ y``
    (it ends with ``Re, Im (W z'(0))``), ``int_0^L v' C v ds = y' damping @ y``,
    ``-int_0^L (1'M v) ag ds = y' input @ y``.  ``stacked`` is ``[state; start; scan; damping;
    input]`` so that one matrix-vector product gives everything a segment needs.
    ``change``/``ramp_change``: see :meth:`Configuration.change_bounds`.
    """

    length: float
    state: np.ndarray
    scan: np.ndarray
    damping: np.ndarray
    input: np.ndarray
    stacked: np.ndarray
    change: np.ndarray
    ramp_change: np.ndarray


def _inverse(V: np.ndarray, elastic: bool) -> np.ndarray:
    """``V^-1`` of a modal basis.

    The elastic configuration (every linear building's only one) keeps the arithmetic of
    earlier versions, scipy's LAPACK ``getrf``/``getrs`` as ``lu_factor``/``lu_solve`` call them,
    so that a linear building's in-step peaks stay bit for bit.  The others (new yield patterns,
    hundreds in a long inelastic run of a tall building) use numpy's ``solve``: scipy's
    multithreaded ``zgetrs`` measured 20-60 ms a call for 6x6 to 40x40 on a loaded 2-core
    machine (2-35 us single-threaded), numpy's 0.03-0.3 ms.
    """
    eye = np.eye(V.shape[0], dtype=complex)
    if not elastic:
        return np.linalg.solve(V, eye)
    lu, piv = lu_factor(V)
    getrs, = get_lapack_funcs(("getrs",), (lu, eye))
    W, info = getrs(lu, piv, eye, trans=0, overwrite_b=0)
    if info != 0:
        raise ValueError(f"LAPACK getrs failed (info = {info}) on the eigenvector basis")
    return W


_IMAGINARY_UNIT = np.array(1j, dtype="F")     # scipy.linalg.eig's, for its arithmetic of wr + i wi


def _eigen(A: np.ndarray, constants: "ConfigurationConstants | None" = None) -> tuple[np.ndarray, np.ndarray]:
    """``(lam, V)`` of a real matrix as :func:`scipy.linalg.eig` computes them, bit for bit: its
    LAPACK ``geev`` with the same workspace, ``lam = wr + i wi`` and the complex eigenvectors of
    each conjugate pair assembled from ``geev``'s two real columns as it assembles them, with the
    pairs at once instead of a Python loop over them (a third of the 60 us that eig spends
    outside LAPACK for 15 storeys, at every new yield pattern).  A non-finite matrix, or a
    LAPACK failure, goes through eig itself (its checks and errors).  ``constants`` (of the
    building whose state matrix ``A`` is) bring the routine and its workspace size, asked of
    LAPACK once per building instead of at every configuration (the same size: it depends on
    the matrix's order only)."""
    if constants is not None and constants.geev is not None:
        geev, lwork = constants.geev, constants.geev_workspace
    else:
        geev, geev_lwork = get_lapack_funcs(("geev", "geev_lwork"), (A,))
        if _compute_lwork is None or geev.typecode != "d":
            return eig(A)
        lwork = _compute_lwork(geev_lwork, A.shape[0], compute_vl=0, compute_vr=1)
    if not np.isfinite(A).all():
        return eig(A)
    wr, wi, _, vr, info = geev(A, lwork=lwork, compute_vl=0, compute_vr=1, overwrite_a=0)
    if info != 0:
        return eig(A)
    lam = wr + _IMAGINARY_UNIT * wi
    # the pairs' tests on Python floats (the imaginary parts are wi's, their signs and zeros
    # the same): the same decisions as eig's, without five numpy calls on a few elements
    imag = wi.tolist()
    if not any(imag):
        return lam, vr            # eig keeps real eigenvectors real
    last = len(imag) - 1
    # eig's pairs, with its workaround for a LAPACK bug (scipy ticket #709): a column is a pair's
    # first where its imaginary part is positive or the next one's negative
    first = [j for j, b in enumerate(imag) if b > 0.0 or (j < last and imag[j + 1] < 0.0)]
    if any(b - a == 1 for a, b in zip(first, first[1:])):
        return eig(A)             # overlapping pairs: only eig's loop gives its result
    first = np.array(first, dtype=np.intp)
    V = np.array(vr, dtype=complex)
    V.imag[:, first] = vr[:, first + 1]
    V[:, first + 1] = V[:, first].conj()
    return lam, V


class ConfigurationConstants:
    """What every stiffness configuration of one building shares (:class:`Configuration`): the
    masses and the damping matrix, the damping's rows of the state matrix, the forcing
    matrices, the rows of the tracked and watched functions that do not depend on the
    stiffness, and LAPACK's ``geev`` with its workspace size for the building's order.  Made
    once per building (``fmu_src.building_response.ExactPiecewiseLinear``) so that a new yield
    pattern builds only what depends on its stiffness; the arrays are read, never written."""

    __slots__ = ("n", "masses", "C", "damping_rows", "B0", "B1", "drift_rows", "peak_rows", "watch_rows",
                 "geev", "geev_workspace", "taylor_grids")

    def __init__(self, masses, damping_matrix):
        m = np.asarray(masses, dtype=float)
        n = m.size
        self.n = n
        self.masses = m
        self.C = np.asarray(damping_matrix, dtype=float)
        self.damping_rows = -self.C / m[:, None]             # A[n:, n:]
        # forcing w = [ag0, ag1, p]: b0 = B0 w, b1 = B1 w
        B0 = np.zeros((2 * n, n + 2))
        B0[n:, 0] = -1.0
        B0[n:, 2:] = np.diag(1.0 / m)
        B1 = np.zeros((2 * n, n + 2))
        B1[n:, 1] = -1.0
        self.B0, self.B1 = B0, B1
        D = np.eye(n) - np.eye(n, k=-1)
        self.drift_rows = D
        # the tracked functions' rows (x, drift; the accelerations' rows are the state matrix's)
        # and the watched ones' (those and the drift rates), without the stiffness' part
        F = np.zeros((3 * n, 2 * n))
        F[:n, :n] = np.eye(n)
        F[n:2 * n, :n] = D
        self.peak_rows = F
        watch = np.zeros((4 * n, 2 * n))
        watch[:3 * n] = F
        watch[3 * n:, n:] = D
        self.watch_rows = watch
        self.geev = self.geev_workspace = None
        # TaylorScan's evaluation grids by (degree, span): the same for every configuration
        # (written by Configuration.taylor_grid only)
        self.taylor_grids: dict[tuple, tuple] = {}
        if _compute_lwork is not None and n:
            geev, geev_lwork = get_lapack_funcs(("geev", "geev_lwork"), (np.zeros((2 * n, 2 * n)),))
            if geev.typecode == "d":
                self.geev = geev
                self.geev_workspace = _compute_lwork(geev_lwork, 2 * n, compute_vl=0, compute_vr=1)


class Configuration:
    """One linear stiffness configuration of a shear building (see module docstring).

    Parameters
    ----------
    masses : (n,) floor masses (kg)
    damping_matrix : (n, n) viscous damping matrix C (N s/m)
    tangent : (n,) storey tangent stiffnesses (N/m), >= 0
    max_maps : bound of the cache of :class:`SegmentMap` by length
    elastic : the building's elastic configuration (its modal basis inverted exactly as in
        earlier versions, see :func:`_inverse`)
    constants : the building's :class:`ConfigurationConstants` (made here if None; a building
        with many yield patterns passes its own, made once: the same arrays, bit for bit)
    """

    def __init__(self, masses, damping_matrix, tangent, max_maps: int = 64, elastic: bool = True,
                 constants: ConfigurationConstants | None = None):
        if constants is None:
            constants = ConfigurationConstants(masses, damping_matrix)
        m = constants.masses
        n = constants.n
        kt = np.asarray(tangent, dtype=float)
        self.n = n
        self.masses = m
        self.C = constants.C
        self.tangent = kt
        # the tridiagonal K written in place: the values of diag(kt + [kt[1:], 0]) - diag(kt[1:], 1)
        # - diag(kt[1:], -1) (x - 0 is x; 0 - k is -k, +0 for k = 0 as 0 - 0 - 0 gives)
        K = np.zeros((n, n))
        diagonal = kt.copy()
        diagonal[:-1] += kt[1:]
        K.flat[::n + 1] = diagonal
        off = 0.0 - kt[1:]
        K.flat[1::n + 1] = off
        K.flat[n::n + 1] = off
        self.K = K
        A = np.zeros((2 * n, 2 * n))
        A.flat[n:n * (2 * n + 1):2 * n + 1] = 1.0           # A[:n, n:] = I
        A[n:, :n] = -K / m[:, None]
        A[n:, n:] = constants.damping_rows
        self.A = A
        lam, V = _eigen(A, constants)
        W = None
        if not elastic:
            # cond_2(V) <= |V|_F |W|_F: a basis that this cheap bound accepts needs no SVD (most
            # yield patterns; the SVD was a third of a configuration's cost for 15 storeys)
            try:
                W = _inverse(V, elastic)
            except np.linalg.LinAlgError:
                W = None
            if W is not None and not (np.linalg.norm(V) * np.linalg.norm(W) <= MAX_CONDITION):
                W = None
        cond = np.linalg.cond(V) if W is None else 0.0
        if W is None and not (math.isfinite(cond) and cond <= MAX_CONDITION):
            raise ValueError(
                f"the storey stiffness configuration {kt.tolist()} N/m gives a defective or nearly "
                f"defective state matrix (eigenvector condition {cond:.3g} > {MAX_CONDITION:g}); "
                f"an undamped mechanism (zeta = 0 with alpha = 0) has this: give zeta > 0 or alpha > 0")
        self.lam = lam
        self.V = V
        self.W = _inverse(V, elastic) if W is None else W
        # the building's elastic configuration keeps the arithmetic of earlier versions (a linear
        # building's results bit for bit); the others may sum in another order
        self.legacy_arithmetic = bool(elastic)
        self.lam_abs = np.abs(lam)
        self.lam2 = self.lam_abs ** 2
        self.lam3 = self.lam_abs ** 3
        self.lam4 = self.lam_abs ** 4
        # columns |lam|^0 .. |lam|^4 (TaylorSegment._bound_parts scales them by a segment's amplitudes)
        powers = np.empty((2 * n, 5))
        powers[:, 0] = 1.0
        powers[:, 1] = self.lam_abs
        powers[:, 2] = self.lam2
        powers[:, 3] = self.lam3
        powers[:, 4] = self.lam4
        self.lam_powers = powers
        self.rate = max(self.lam_abs.tolist()) if n else 0.0
        self.growth_rate = max(0.0, max(lam.real.tolist()))   # > 0 only by round-off
        # Forcing w = [ag0, ag1, p]: b0 = B0 w, b1 = B1 w (the building's, ConfigurationConstants).
        B0, B1 = constants.B0, constants.B1
        self.B0, self.B1 = B0, B1
        # both modal forcing maps stacked (one product gives beta0 and beta1, :meth:`modal`: a
        # matrix-vector product's rows are the same dot products whatever rows are stacked), with
        # each as a view
        self.WB = np.vstack((self.W @ B0, self.W @ B1))
        self.WB0, self.WB1 = self.WB[:2 * n], self.WB[2 * n:]
        self.ramp_abs = np.abs(self.WB1[:, 1])      # |modal b1| per unit ground-acceleration slope
        # Scan's (_scan_bounds): where its vector's blocks end (6 blocks of the 3n tracked functions,
        # then Re W z'(0)), the columns |lam|^3..4 (a view) and |lam|^2..3 |W b1|
        self.scan_parts = (18 * n, 20 * n, powers[:, 3:5], powers[:, 2:4] * self.ramp_abs[:, None])
        # Functionals whose peaks are tracked: floor displacement, storey drift, absolute
        # acceleration a = M^-1 (p - C v - Kt u) (its constant part p/m added by the caller).
        F = constants.peak_rows.copy()
        F[2 * n:, :] = A[n:, :]
        self.peak_rows = F
        # Rows watched by the cheap per-segment test: the tracked functions and the drift rates.
        watch = constants.watch_rows.copy()
        watch[2 * n:3 * n] = F[2 * n:]
        self.watch_rows = watch
        self.peak_modal = F @ V
        self.peak_modal_abs = np.abs(self.peak_modal)
        self._maps: OrderedDict[float, SegmentMap] = OrderedDict()
        self._exact: dict[float, SegmentMap] = {}      # the same maps by the exact length asked
        self._watch_modal_abs = None                    # |watch_rows V| and 2 / |lam| (change_bounds)
        self._scan_start = None                         # scan_rows' length-independent rows
        self.max_maps = int(max_maps)
        self.maps_built = 0          # cost counter
        self.segments_without_map = 0   # segments evaluated ad hoc (see ExactPiecewiseLinear._worth_a_map)
        self._taylor_powers: dict[int, tuple] = {}      # taylor_powers by degree
        self._taylor_grids = constants.taylor_grids     # taylor_grid's (the building's)
        # modal rows of the event functions searched in this configuration, by (storey, kind,
        # mode) (fmu_src.building_response.ExactPiecewiseLinear._first_event), with their
        # magnitudes: (row, |row|), at most 3n
        self.event_rows: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}

    # -- evaluation -------------------------------------------------------------------------
    def forcing(self, w: np.ndarray, s: float = 0.0) -> np.ndarray:
        """``b(s) = B0 w + B1 w s`` (state-space forcing at segment time s)."""
        return self.B0 @ w + (self.B1 @ w) * s

    def rate_of(self, z: np.ndarray, w: np.ndarray, s: float = 0.0) -> np.ndarray:
        """``z'(s) = A z + b(s)``."""
        return self.A @ z + self.forcing(w, s)

    def modal(self, z0: np.ndarray, w: np.ndarray):
        """Modal coordinates of a segment start: ``q0, beta0, beta1``."""
        beta = self.WB @ w
        n2 = 2 * self.n
        return self.W @ z0, beta[:n2], beta[n2:]

    def modal_at(self, q0, beta0, beta1, s):
        """``q(s)`` (complex, shape ``(2n,) + shape(s)``) for segment time(s) s."""
        s = np.asarray(s, dtype=float)
        x = np.multiply.outer(self.lam, s)
        ramp = np.count_nonzero(beta1) > 0
        e, p1, p2 = phi_functions(x, second=ramp)
        if s.ndim == 0:
            q = e * q0 + s * p1 * beta0
            return q + s * s * p2 * beta1 if ramp else q
        q = e * q0[:, None] + s * p1 * beta0[:, None]
        return q + s * s * p2 * beta1[:, None] if ramp else q

    def state_at(self, q0, beta0, beta1, s):
        """Real state ``z(s)``."""
        return (self.V @ self.modal_at(q0, beta0, beta1, s)).real

    def chunk_nodes(self, length: float):
        """Gauss-Legendre nodes and weights on ``[0, length]`` (chunked by the fastest mode)."""
        chunks = max(1, int(math.ceil(self.rate * length / CHUNK_RATE)))
        if chunks > MAX_CHUNKS:
            raise ValueError(f"segment of {length:.6g} s spans {chunks} quadrature chunks of the fastest "
                             f"mode (|lambda| = {self.rate:.6g} 1/s); the limit is {MAX_CHUNKS}: use shorter steps")
        width = length / chunks
        if chunks == 1:
            # the general form's values (0 + x is x; a tile of one is a copy) without its four
            # array calls: most segments of a yielding building are one chunk
            return width * GAUSS_NODES, width * GAUSS_WEIGHTS
        starts = width * np.arange(chunks)
        nodes = (starts[:, None] + width * GAUSS_NODES[None, :]).ravel()
        weights = np.tile(width * GAUSS_WEIGHTS, chunks)
        return nodes, weights

    def energies(self, q0, beta0, beta1, w: np.ndarray, length: float):
        """``(int_0^L v'Cv ds, -int_0^L (1'M v) ag ds)`` of a segment from its modal start."""
        nodes, weights = self.chunk_nodes(length)
        v = (self.V[self.n:] @ self.modal_at(q0, beta0, beta1, nodes)).real      # (n, K)
        return self.quadrature(v, nodes, weights, w)

    def quadrature(self, v: np.ndarray, nodes: np.ndarray, weights: np.ndarray, w: np.ndarray):
        """:meth:`energies` from the floor velocities ``v`` (n, K) at the quadrature nodes."""
        # (np.einsum without optimize is c_einsum itself: called directly, the same sums)
        damping = float(_c_einsum("k,ik,ik->", weights, v, self.C @ v))
        ag = w[0] + w[1] * nodes
        work = -float((weights * ag) @ (self.masses @ v))
        return damping, work

    def has_map(self, length: float) -> bool:
        """Whether :meth:`segment_map` of this length is cached (it would not be built)."""
        return length in self._exact or float(f"{length:.12g}") in self._maps

    def segment_map(self, length: float) -> SegmentMap:
        """Real matrices of a segment of this length, cached (see :class:`SegmentMap`)."""
        found = self._exact.get(length)
        if found is not None:
            return found
        key = canonical_length(float(length))   # lengths equal to round-off share one map
        found = self._maps.get(key)
        if found is not None:
            if len(self._exact) >= 4 * self.max_maps:
                self._exact.clear()
            self._exact[length] = found
            return found
        asked, length = length, key        # computed at the canonical length: the same map whichever came first
        n = self.n
        size = 3 * n + 2
        # Modal map of y = [z0; w]: q(s) = E(s) [W z0] + s phi1 [WB0 w] + s^2 phi2 [WB1 w].
        Wy = np.hstack([self.W, np.zeros((2 * n, n + 2))])
        B0y = np.hstack([np.zeros((2 * n, 2 * n)), self.WB0])
        B1y = np.hstack([np.zeros((2 * n, 2 * n)), self.WB1])

        def real_map(s):
            e, p1, p2 = phi_functions(self.lam * s)
            return (self.V @ (e[:, None] * Wy + (s * p1)[:, None] * B0y + (s * s * p2)[:, None] * B1y)).real

        state = real_map(length)
        scan = self.scan_rows(state, length)
        nodes, weights = self.chunk_nodes(length)
        x = np.multiply.outer(self.lam, nodes)
        e, p1, p2 = phi_functions(x)                                          # (2n, K)
        # (2n, K, size): e W on the columns of z0, (s phi1) WB0 + (s^2 phi2) WB1 on those of w, by
        # blocks: the sum over all columns with the other terms' zero blocks added gives these
        # values (adding a zero changes no nonzero number), at less than half the cost
        modal = np.empty((2 * n, nodes.size, size), dtype=complex)
        np.multiply(e[:, :, None], self.W[:, None, :], out=modal[:, :, :2 * n])
        np.add((nodes * p1)[:, :, None] * self.WB0[:, None, :], (nodes * nodes * p2)[:, :, None] * self.WB1[:, None, :],
               out=modal[:, :, 2 * n:])
        K_nodes = nodes.size
        if self.legacy_arithmetic:
            vel = np.einsum("ij,jks->kis", self.V[n:], modal).real                 # (K, n, size)
        else:
            # the same sums by matrix products (BLAS): 0.3 ms instead of 1.2 ms for 15 storeys,
            # at every new yield pattern; the elastic configuration keeps the einsum (bit for bit)
            vel = (self.V[n:] @ modal.reshape(2 * n, K_nodes * size)).real.reshape(n, K_nodes, size)
            vel = vel.transpose(1, 0, 2)
        # sum_k w_k vel_k' C vel_k as one matrix product over the stacked nodes (a 4-operand
        # einsum without a contraction order took ~100 ms for 15 storeys, at every new yield pattern)
        weighted = (vel * weights[:, None, None]).reshape(K_nodes * n, size)
        damping = weighted.T @ np.matmul(self.C, vel).reshape(K_nodes * n, size)
        ag_row = np.zeros((nodes.size, size))
        ag_row[:, 2 * n] = 1.0
        ag_row[:, 2 * n + 1] = nodes
        if self.legacy_arithmetic:
            mv = np.einsum("i,kis->ks", self.masses, vel)                          # (K, size)
            work = -np.einsum("k,ks,kt->st", weights, mv, ag_row)
        else:
            mv = np.matmul(self.masses, vel)                                       # (K, size)
            work = -((mv * weights[:, None]).T @ ag_row)
        damping = 0.5 * (damping + damping.T)
        work = 0.5 * (work + work.T)
        start = np.hstack([self.watch_rows, np.zeros((4 * n, n + 2))])
        stacked = np.ascontiguousarray(np.vstack([state, start, scan, damping, work]))
        change, ramp_change = self.change_bounds(length)
        result = SegmentMap(length, state, scan, damping, work, stacked, change, ramp_change)
        if len(self._maps) >= self.max_maps:
            self._maps.popitem(last=False)
            self._exact.clear()
        self._maps[key] = result
        self._exact[asked] = result
        self.maps_built += 1
        return result

    def change_bounds(self, length: float):
        """``(N, R)`` with ``|g(t) - g(0)| <= N @ [|Re W z'(0)|; |Im W z'(0)|] + R |ag1|`` for
        ``t`` in ``[0, L]`` and every watched function ``g = watch_rows @ z``.

        In modal coordinates ``q(t) - q(0) = t phi1(lam t) q'(0) + t^2 phi2(lam t) beta1``; for
        ``Re lam <= 0``, ``|t phi1(lam t)| = |e^{lam t} - 1| / |lam| <= min(t, 2 / |lam|)`` and
        ``|phi2| <= 1/2`` (``phi2(x) = int_0^1 (1 - s) e^{x s} ds``), so the bound is closed-form
        and rigorous (times ``e^{max(Re lam, 0) L}`` for round-off growth).  Used only to skip
        work: a segment whose bound leaves every function inside its limits cannot have an
        event or a new peak.
        """
        parts = self._watch_modal_abs
        if parts is None:       # whatever the length: made once per configuration
            with np.errstate(divide="ignore"):
                limit = np.where(self.lam_abs > 0.0, 2.0 / self.lam_abs, np.inf)     # 2 / |lam|
            parts = self._watch_modal_abs = (np.abs(self.watch_rows @ self.V), limit)  # (4n, 2n)
        FV, limit = parts
        growth = math.exp(self.growth_rate * length)
        scale = np.minimum(length, limit) * growth
        ramp_change = FV @ (0.5 * length * length * growth * self.ramp_abs)
        # acting on [|Re q'(0)|; |Im q'(0)|] (their sum bounds |q'(0)|): no square root per step
        half = FV.shape[1]
        change = np.empty((FV.shape[0], 2 * half))
        np.multiply(FV, scale[None, :], out=change[:, :half])
        change[:, half:] = change[:, :half]
        return change, ramp_change

    def taylor_powers(self, degree: int) -> tuple:
        """:func:`_taylor_powers` of this configuration's eigenvalues, made once per degree (a
        yielding building asks for a handful of degrees, at every ad hoc segment)."""
        powers = self._taylor_powers.get(degree)
        if powers is None:
            # a prefix of the powers of the highest degree a TaylorSegment asks: the same floats
            # (a cumulative product and elementwise operations), made once per configuration
            # instead of once per degree (2.7 degrees per yield pattern on kasai_maison_inelastic)
            highest = _taylor_degree(TAYLOR_MAX_SPAN)
            if degree > highest:
                return _taylor_powers(self.lam, degree)
            full = self._taylor_powers.get(highest)
            if full is None:
                full = self._taylor_powers[highest] = _taylor_powers(self.lam, highest)
            P1, P2, k, _ = full
            powers = self._taylor_powers[degree] = (P1[:, :degree - 1], P2[:, :degree - 1], k[:degree - 1], degree)
        return powers

    def taylor_grid(self, degree: int, s: float) -> tuple[np.ndarray, np.ndarray]:
        """``(powers, P)`` of :meth:`TaylorScan.state_and_values` at ``s``: ``powers[k] = s^k``
        (k = 0 .. degree) and ``P`` (degree + 1 x 6) the value, slope and curvature of every
        power at 0 and at s as columns.  Remembered by ``(degree, s)`` for the building (a
        yielding building's ad hoc segments mostly span a whole knot interval); read, never
        written.  At most ``4 max_maps`` kept."""
        key = (degree, s)
        grid = self._taylor_grids.get(key)
        if grid is None:
            K = degree
            powers = _powers_of(s, K + 1)
            P = np.zeros((K + 1, 6))
            P[0, 0] = 1.0
            P[:, 1] = powers
            P[1, 2] = 1.0
            P[1:, 3] = _DEGREES[1:K + 1] * powers[:-1]
            P[2, 4] = 2.0
            P[2:, 5] = _DEGREES2[2:K + 1] * powers[:-2]
            if len(self._taylor_grids) >= 4 * self.max_maps:
                self._taylor_grids.clear()
            grid = self._taylor_grids[key] = (powers, P)
        return grid

    def state_and_peak_modal(self) -> np.ndarray:
        """``[V; peak_rows V]`` (5n x 2n, complex): the state and the tracked functions from modal
        coordinates in one product (:class:`TaylorScan`).  Made once per configuration."""
        rows = getattr(self, "_state_and_peak_modal", None)
        if rows is None:
            rows = self._state_and_peak_modal = np.ascontiguousarray(np.vstack((self.V, self.peak_modal)))
        return rows

    def drift_curvature_rows(self):
        """``(M, Ra, Rb)`` for second-order bounds of the storey drifts ``d = D u`` over a segment.

        With ``a = [|Re W z'(0)|; |Im W z'(0)|]`` (their sum bounds ``|q'(0)|``), ``M @ a +
        |ag1| (L Ra + Rb)``, times ``e^{max(Re lam, 0) L}``, bounds the maxima of ``|d''|`` (first
        n) and ``|d'''|`` (last n) over ``[0, L]``: ``q'' = lam q' + beta1`` and ``|q_j'(t)| <=
        (|q_j'(0)| + t |beta1_j|) e^{max(Re lam, 0) t}`` give ``|q_j''| <= |lam_j| (|q_j'(0)| + L
        |beta1_j|) + |beta1_j|`` and ``|q_j'''| <= |lam_j| |q_j''|``, with ``|beta1| = |ag1|``
        times :attr:`ramp_abs`.  Made once per configuration.
        """
        rows = getattr(self, "_drift_curvature", None)
        if rows is None:
            n = self.n
            DV = np.abs(self.watch_rows[n:2 * n] @ self.V)                      # (n, 2n)
            lam = self.lam_abs
            M2, M3 = DV * lam, DV * (lam * lam)
            M = np.ascontiguousarray(np.vstack([np.hstack([M2, M2]), np.hstack([M3, M3])]))
            Ra = np.concatenate([M2 @ self.ramp_abs, M3 @ self.ramp_abs])       # times L
            Rb = np.concatenate([DV @ self.ramp_abs, M2 @ self.ramp_abs])
            rows = self._drift_curvature = (M, Ra, Rb)
        return rows

    def drift_curvature_lists(self) -> tuple[list, list]:
        """``(Ra, Rb)`` of :meth:`drift_curvature_rows` as lists of Python floats (made once)."""
        lists = getattr(self, "_drift_curvature_lists", None)
        if lists is None:
            _, Ra, Rb = self.drift_curvature_rows()
            lists = self._drift_curvature_lists = (Ra.tolist(), Rb.tolist())
        return lists

    def scan_rows(self, state_map: np.ndarray, length: float) -> np.ndarray:
        """The matrix giving a segment's :class:`Scan` vector from ``y = [z0; w]``."""
        A, F = self.A, self.peak_rows
        start = self._scan_start
        if start is None:
            # the rows of the segment's start, whatever its length: made once per configuration
            # (the same products as below, so the same values)
            n = self.n
            size = 3 * n + 2
            Y0 = np.zeros((2 * n, size))
            Y0[:, :2 * n] = np.eye(2 * n)
            B0y = np.zeros((2 * n, size))
            B0y[:, 2 * n:] = self.B0
            B1y = np.zeros((2 * n, size))
            B1y[:, 2 * n:] = self.B1
            D0 = A @ Y0 + B0y
            WD0 = self.W @ D0
            start = self._scan_start = (B0y, B1y, F @ Y0, F @ D0, F @ (A @ D0 + B1y), WD0.real, WD0.imag)
        B0y, B1y, FY0, FD0, FD0dot, WD0_real, WD0_imag = start
        D1 = A @ state_map + B0y + B1y * length
        return np.vstack([FY0, F @ state_map, FD0, F @ D1, FD0dot, F @ (A @ D1 + B1y), WD0_real, WD0_imag])

    def scan_vector(self, z0: np.ndarray, z1: np.ndarray, w: np.ndarray, length: float) -> np.ndarray:
        """A segment's :class:`Scan` vector from its end states (the ad hoc path)."""
        b0 = self.B0 @ w
        b1 = self.B1 @ w
        A = self.A
        d0 = A @ z0 + b0
        d1 = A @ z1 + b0 + b1 * length
        Z = np.empty((2 * self.n, 6))
        Z[:, 0] = z0
        Z[:, 1] = z1
        Z[:, 2] = d0
        Z[:, 3] = d1
        Z[:, 4] = A @ d0 + b1
        Z[:, 5] = A @ d1 + b1
        wd0 = self.W @ d0
        return np.concatenate([(self.peak_rows @ Z).T.ravel(), wd0.real, wd0.imag])

    # -- bounds -------------------------------------------------------------------------------
    def derivative_bound(self, modal_rows_abs: np.ndarray, order: int, rate0: np.ndarray,
                         beta1: np.ndarray, length: float) -> np.ndarray:
        """Bound of ``|c' z^(order)(s)|`` over ``[a, a + length]``, ``order >= 2``, for every row.

        ``modal_rows_abs`` = ``|c' V|`` per row, ``rate0`` = modal ``z'(a)`` (``W z'(a)``),
        ``beta1`` the segment's modal ramp forcing.
        """
        lam = np.abs(self.lam)
        amp = (np.abs(rate0) + length * np.abs(beta1)) * math.exp(self.growth_rate * length)
        return modal_rows_abs @ (lam ** (order - 1) * amp + lam ** (order - 2) * np.abs(beta1))


class Scan:
    """What the event and peak tests need of one segment ``[0, L]``, from one product.

    For every tracked function ``g = F z`` (rows of :attr:`Configuration.peak_rows`: floor
    displacements, storey drifts, absolute accelerations without their constant part) its
    values, slopes and curvatures at both ends (columns of ``G``: ``g(0), g(L), g'(0), g'(L),
    g''(0), g''(L)``), and bounds of ``|g|`` and ``|g'|`` over the segment
    (columns of ``B``, from the modal amplitudes of ``z'(0)``, see
    :meth:`Configuration.derivative_bound`).
    """

    __slots__ = ("G", "B")

    def __init__(self, cfg: "Configuration", vector: np.ndarray, ag_slope: float, length: float):
        # (the configuration's sizes and column views, made once: a Scan is made per segment)
        m6, re_end, _, _ = cfg.scan_parts
        self.G = vector[:m6].reshape(6, -1).T
        self.B = _scan_bounds(cfg, vector[m6:re_end], vector[re_end:], ag_slope, length)

    @classmethod
    def of_parts(cls, cfg: "Configuration", G: np.ndarray, rate0: np.ndarray, ag_slope: float,
                 length: float) -> "Scan":
        """The Scan of ``G`` (3n x 6, the columns above) and ``rate0 = W z'(0)`` (complex): what
        the vector ``[G' (rows in order); Re rate0; Im rate0]`` gives, without assembling it and
        taking it apart again (:class:`TaylorScan`'s segments)."""
        scan = object.__new__(cls)
        scan.G = G
        scan.B = _scan_bounds(cfg, rate0.real, rate0.imag, ag_slope, length)
        return scan


def _scan_bounds(cfg: "Configuration", re: np.ndarray, im: np.ndarray, ag_slope: float, length: float) -> np.ndarray:
    """:attr:`Scan.B` from the real and imaginary parts of ``W z'(0)``: ``|F V| @ powers`` with
    the columns ``|lam|^3 amp + |lam|^2 ramp`` and ``|lam|^4 amp + |lam|^3 ramp``, ``ramp =
    |ag1| |W b1|`` and ``amp = (|W z'(0)| + L ramp) e^{max(Re lam, 0) L}``
    (:meth:`Configuration.derivative_bound`).  The ramp terms as ``|ag1|`` times the
    configuration's ``|lam|^2..3 |W b1|`` (:attr:`Configuration.scan_parts`): fewer numpy calls
    per segment; ``ExactPiecewiseLinear._interval_peaks`` forms the same elements for many
    intervals at once (so both decide alike).  Bounds: they decide only."""
    _, _, lam34, ramp23 = cfg.scan_parts
    a = abs(ag_slope)
    amp = np.hypot(re, im)
    if a != 0.0:
        amp = amp + (length * a) * cfg.ramp_abs
    if cfg.growth_rate:
        amp = amp * math.exp(cfg.growth_rate * length)
    powers = lam34 * amp[:, None]
    if a != 0.0:
        powers += a * ramp23
    return cfg.peak_modal_abs @ powers


class ModalSegment:
    """One segment of one configuration from a known start, evaluated anywhere in ``[0, L]``.

    Used by the event and peak searches: ``derivatives(c_modal, s, count)`` returns
    ``c' z^(j)(s)`` for ``j = 0 .. count-1`` (real), from the modal solution.
    """

    __slots__ = ("cfg", "q0", "beta0", "beta1", "_memo")

    def __init__(self, cfg: Configuration, z0: np.ndarray, w: np.ndarray):
        self.cfg = cfg
        self.q0, self.beta0, self.beta1 = cfg.modal(z0, w)
        self._memo: dict[float, tuple[np.ndarray, np.ndarray]] = {}

    def modal_derivatives(self, s: float):
        """``(q(s), q'(s))`` in modal coordinates (memoised by s)."""
        hit = self._memo.get(s)
        if hit is None:
            q = self.cfg.modal_at(self.q0, self.beta0, self.beta1, s)
            dq = self.cfg.lam * q + self.beta0 + self.beta1 * s
            hit = self._memo[s] = (q, dq)
        return hit

    def derivatives(self, c_modal: np.ndarray, s: float, count: int) -> list[float]:
        """``[c'z, c'z', c'z'', ...]`` (``count`` values) at segment time s."""
        q, dq = self.modal_derivatives(s)
        lam = self.cfg.lam
        out = [float((c_modal @ q).real)]
        if count > 1:
            out.append(float((c_modal @ dq).real))
        term = dq
        for j in range(2, count):
            # q^(j) = lam^(j-1) q' + lam^(j-2) beta1
            term = lam * term + (self.beta1 if j == 2 else 0.0)
            out.append(float((c_modal @ term).real))
        return out

    def start_values(self, c_modal: np.ndarray, c_modal_abs: np.ndarray) -> tuple[list[float], list[float]]:
        """``(derivatives(c_modal, 0, 3), magnitudes(c_modal_abs, 0, 3))`` (:func:`first_root`'s
        start) with ``q''(0)`` formed once: the same operations, so the same values."""
        q, dq = self.modal_derivatives(0.0)
        term = self.cfg.lam * dq + self.beta1
        return ([float((c_modal @ q).real), float((c_modal @ dq).real), float((c_modal @ term).real)],
                [float(c_modal_abs @ np.abs(q)), float(c_modal_abs @ np.abs(dq)), float(c_modal_abs @ np.abs(term))])

    def evaluator(self, c_modal: np.ndarray, count: int):
        """``s -> derivatives(c_modal, s, count)``: what the searches call at every point."""
        return lambda s: self.derivatives(c_modal, s, count)

    def magnitudes(self, c_modal_abs: np.ndarray, s: float, count: int) -> list[float]:
        """``sum |c_j| |q_j^(k)(s)|`` for ``k = 0 .. count-1``: the scale of each derivative's
        round-off."""
        q, dq = self.modal_derivatives(s)
        lam = self.cfg.lam
        out = [float(c_modal_abs @ np.abs(q))]
        term = dq
        for j in range(1, count):
            if j >= 2:
                term = lam * term + (self.beta1 if j == 2 else 0.0)
            out.append(float(c_modal_abs @ np.abs(term)))
        return out

    def seed(self, s: float, q, dq) -> None:
        """Store ``q'(s)`` (and ``q(s)`` if given) computed elsewhere (vectorised sampling)."""
        if s not in self._memo:
            if q is None:
                q = (dq - self.beta0 - self.beta1 * s) / np.where(self.cfg.lam != 0.0, self.cfg.lam, 1.0)
                if np.any(self.cfg.lam == 0.0):
                    return      # q cannot be recovered from q' for a zero eigenvalue: evaluate later
            self._memo[s] = (q, dq)

    def bound(self, c_modal_abs: np.ndarray, order: int, s: float, length: float) -> float:
        """Bound of ``|c' z^(order)|`` over ``[s, s + length]`` (``order >= 2``)."""
        _, dq = self.modal_derivatives(s)
        return float(self.cfg.derivative_bound(c_modal_abs, order, dq, self.beta1, length))

    def bounds45(self, c_modal_abs: np.ndarray, s: float, length: float) -> tuple[float, float]:
        """Bounds of ``|c' z''''|`` and ``|c' z'''''|`` over ``[s, s + length]``."""
        _, dq = self.modal_derivatives(s)
        cfg = self.cfg
        ramp = np.abs(self.beta1)
        amp = (np.abs(dq) + length * ramp) * math.exp(cfg.growth_rate * length)
        b4 = float(c_modal_abs @ (cfg.lam3 * amp + cfg.lam2 * ramp))
        b5 = float(c_modal_abs @ (cfg.lam4 * amp + cfg.lam3 * ramp))
        return b4, b5


class TaylorScan:
    """A short segment's state and :class:`Scan` vector at any ``s`` in ``[0, L]``, and its energy
    integrals, from the real Taylor coefficients of the state and of the tracked functions: its
    :class:`TaylorSegment`'s modal columns mapped once by ``[V; F V]``
    (:meth:`Configuration.state_and_peak_modal`), then a few small products per evaluation
    (what :meth:`TaylorSegment.state`, :meth:`Configuration.scan_vector` and
    :meth:`TaylorSegment.energies` compute, the same sums in another order: round-off apart).
    What an ad hoc segment of a yielding building needs (``ExactPiecewiseLinear._interval``)."""

    __slots__ = ("cfg", "Z", "F", "rate0", "degree")

    def __init__(self, segment: "TaylorSegment"):
        cfg = segment.cfg
        n = cfg.n
        columns = segment.taylor()                 # (2n, degree + 1) complex: q^(k)(0) / k!
        coefficients = (cfg.state_and_peak_modal() @ columns).real
        self.cfg, self.degree = cfg, columns.shape[1] - 1
        self.Z = coefficients[:2 * n]               # z(s) = Z @ [s^k]
        self.F = coefficients[2 * n:]               # the tracked functions' coefficients (3n rows)
        self.rate0 = columns[:, 1]                   # W z'(0)

    @staticmethod
    def fits(cfg: "Configuration", length: float) -> bool:
        """Whether a segment of ``length`` s is short enough (:class:`TaylorSegment`'s polynomials)."""
        return cfg.rate * length <= TAYLOR_MAX_SPAN

    @property
    def wd(self) -> np.ndarray:
        """``[Re W z'(0); Im W z'(0)]``: the scan vector's last block."""
        return np.concatenate((self.rate0.real, self.rate0.imag))

    def state_and_scan(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """``(z(s), the scan vector of [0, s])``: what :meth:`Configuration.scan_vector` gives."""
        z, G = self.state_and_values(s)
        return z, np.concatenate((G.T.ravel(), self.wd))

    def state_and_values(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """``(z(s), G)``: the state and the tracked functions' values, slopes and curvatures at
        both ends of ``[0, s]`` (3n x 6, :attr:`Scan.G`'s columns): :meth:`state_and_scan`'s
        numbers, for :meth:`Scan.of_parts`."""
        powers, P = self.cfg.taylor_grid(self.degree, s)
        return self.Z @ powers, self.F @ P          # (3n, 6)

    def energies(self, w: np.ndarray, length: float):
        """:meth:`Configuration.energies` over ``[0, length]`` from the velocity coefficients."""
        cfg = self.cfg
        nodes, weights = cfg.chunk_nodes(length)
        powers = np.ones((self.degree + 1, nodes.size))
        powers[1:] = nodes
        powers.cumprod(axis=0, out=powers)
        return cfg.quadrature(self.Z[cfg.n:] @ powers, nodes, weights, w)


class TaylorSegment(ModalSegment):
    """A :class:`ModalSegment` of known length ``L`` whose searches run on Python floats.

    For a short segment (``rho = max|lam| L <= TAYLOR_MAX_SPAN``) every searched function
    ``g = c' z`` is evaluated by its Taylor polynomial at the start,

        g(s) = sum_k a_k s^k,   a_k = Re(c' q^(k)(0)) / k!,
        q^(1)(0) = q'(0),   q^(2)(0) = lam q'(0) + beta1,   q^(k)(0) = lam q^(k-1)(0)  (k >= 3),

    truncated where the remainder of the highest derivative asked, ``rho^(K+1) / (K+1)!``
    relative to the modal amplitude of that derivative, is below ``TAYLOR_TRUNCATION``: exact
    to round-off like the modal form, whose terms it sums in another order (the terms'
    magnitudes sum to at most ``e^rho`` times that amplitude, so for ``rho <= 2`` the round-off
    stays within a few ulp of the modal evaluation's, far inside the searches' ``ROUNDOFF``).
    One small matrix product per function and segment replaces an exponential of every mode
    at every point of a search.  The bounds of higher derivatives over ``[s, s + w]`` come from
    the start (:meth:`bound`): ``q'' = lam q' + beta1`` gives ``|q_j'(t)| <= (|q_j'(0)| + t
    |beta1_j|) e^{max(Re lam, 0) t}``, with no evaluation at ``s``.  A longer segment is
    evaluated in modal form.  Used by every deferred in-step peak search
    (``ExactPiecewiseLinear.resolve_peaks``) and by a yielding building's event searches.
    """

    __slots__ = ("length", "_taylor", "_amp0", "_ramp", "_dq0", "_bounds", "_coefficients", "_abs3")

    def __init__(self, cfg: Configuration, z0: np.ndarray, w: np.ndarray, length: float):
        super().__init__(cfg, z0, w)
        self.length = float(length)
        dq0 = self._dq0 = cfg.lam * self.q0 + self.beta0
        # the start needs no evaluation: what modal_at(0) gives, bit for bit
        self._memo[0.0] = (self.q0, dq0)
        self._amp0 = self._ramp = None      # |q'(0)|, |beta1|: made at the first bound (_bound_parts)
        self._taylor = None                 # the columns, made at their first use
        self._bounds = {}                   # see _bound_parts
        self._coefficients = None           # (c_modal, its Taylor coefficients) last asked
        self._abs3 = None                   # |q(0)|, |q'(0)|, |q''(0)| / 2 as columns (start_values)

    def taylor(self) -> np.ndarray | None:
        """``(2n, K + 1)``: column k is ``q^(k)(0) / k!``; None for a long segment."""
        if self._taylor is None:
            rho = self.cfg.rate * self.length
            if rho > TAYLOR_MAX_SPAN:
                return None
            self._taylor = _taylor_columns(self.cfg.taylor_powers(_taylor_degree(rho)), self.q0, self._dq0,
                                          self.beta1)
        return self._taylor

    def _taylor_coefficients(self, c_modal: np.ndarray) -> list[float]:
        """``Re(c' q^(k)(0)) / k!``, k = 0 .. K: the Taylor coefficients of ``g = c' z`` at 0
        (the columns must exist), remembered for the array last asked (start_values, then
        evaluator, for one search)."""
        hit = self._coefficients
        if hit is None or hit[0] is not c_modal:
            hit = self._coefficients = (c_modal, (c_modal @ self._taylor).real.tolist())
        return hit[1]

    def start_values(self, c_modal: np.ndarray, c_modal_abs: np.ndarray) -> tuple[list[float], list[float]]:
        """:meth:`ModalSegment.start_values` with the slope and curvature from the Taylor
        coefficients (``g'(0) = a_1``, ``g''(0) = 2 a_2``) and the magnitudes from the first three
        columns (``|q''(0)| = 2 |q''(0) / 2|``) in one product: the value at 0 (which a search
        at its limit shifts its offset by) as the modal form computes it; the others decide
        only (round-off tolerances, exclusion bounds), to round-off."""
        columns = self.taylor()
        if columns is None:
            return super().start_values(c_modal, c_modal_abs)
        a = self._taylor_coefficients(c_modal)
        if self._abs3 is None:
            self._abs3 = np.abs(columns[:, :3])
        m0, m1, m2 = (c_modal_abs @ self._abs3).tolist()
        return [float((c_modal @ self.q0).real), a[1], 2.0 * a[2]], [m0, m1, 2.0 * m2]

    def evaluator(self, c_modal: np.ndarray, count: int):
        columns = self.taylor() if count <= _TAYLOR_DERIVATIVES + 1 else None
        if columns is None:
            return super().evaluator(c_modal, count)
        a = self._taylor_coefficients(c_modal)          # Taylor coefficients of g at 0
        if count == 3:
            # what the searches ask: g, g', g'' in one Horner pass (value, slope, half curvature)
            highest_first = a[::-1]

            def three(s):
                v = d1 = d2 = 0.0
                for ck in highest_first:
                    d2 = d2 * s + d1
                    d1 = d1 * s + v
                    v = v * s + ck
                return [v, d1, 2.0 * d2]

            def value_and_slope(s):
                # three's g and g' (the same operations, without g''): what Newton asks, 5 times a root
                v = d1 = 0.0
                for ck in highest_first:
                    d1 = d1 * s + v
                    v = v * s + ck
                return v, d1
            three.value_and_slope = value_and_slope
            return three
        polys = [a[::-1]]                               # highest degree first, for Horner
        for _ in range(1, count):
            a = [k * a[k] for k in range(1, len(a))]
            polys.append(a[::-1])

        def values(s):
            out = []
            for coefficients in polys:
                v = 0.0
                for ck in coefficients:
                    v = v * s + ck
                out.append(v)
            return out
        return values

    def state(self, s: float) -> np.ndarray:
        """Real state ``z(s)`` (``0 <= s <= length``)."""
        columns = self.taylor()
        if columns is None:
            return self.cfg.state_at(self.q0, self.beta0, self.beta1, s)
        return (self.cfg.V @ (columns @ _powers_of(s, columns.shape[1]))).real

    def energies(self, w: np.ndarray, length: float):
        """:meth:`Configuration.energies` over ``[0, length]`` (``length <= self.length``)."""
        cfg = self.cfg
        columns = self.taylor()
        if columns is None:
            return cfg.energies(self.q0, self.beta0, self.beta1, w, length)
        nodes, weights = cfg.chunk_nodes(length)
        powers = np.ones((columns.shape[1], nodes.size))
        powers[1:] = nodes
        powers.cumprod(axis=0, out=powers)
        v = (cfg.V[cfg.n:] @ (columns @ powers)).real
        return cfg.quadrature(v, nodes, weights, w)

    def bound(self, c_modal_abs: np.ndarray, order: int, s: float, length: float) -> float:
        end = s + length
        parts = self._bound_parts(c_modal_abs)
        return math.exp(self.cfg.growth_rate * end) * (parts[order][0] + end * parts[order][1]) + parts[order][2]

    def bounds45(self, c_modal_abs: np.ndarray, s: float, length: float) -> tuple[float, float]:
        end = s + length
        parts = self._bound_parts(c_modal_abs)
        growth = math.exp(self.cfg.growth_rate * end)
        (a4, r4, c4), (a5, r5, c5) = parts[4], parts[5]
        return growth * (a4 + end * r4) + c4, growth * (a5 + end * r5) + c5

    def _bound_parts(self, c_modal_abs: np.ndarray) -> dict:
        """The bounds of ``|c' z^(k)|`` over ``[0, end]`` (k = 2..5) as ``e^{max(Re lam, 0) end}
        (a_k + end r_k) + c_k``: per mode ``|q_j^(k)| <= |lam_j|^(k-1) (|q_j'(0)| + end
        |beta1_j|) e^{...} + |lam_j|^(k-2) |beta1_j|``, summed with the weights ``|c_j|`` once
        per function (a search asks for them on every sub-interval; the weights' array is
        kept, so that its id is not reused while cached)."""
        key = id(c_modal_abs)
        hit = self._bounds.get(key)
        if hit is None or hit[0] is not c_modal_abs:
            if self._amp0 is None:
                self._amp0 = np.abs(self._dq0)
                self._ramp = np.abs(self.beta1)
            powers = self.cfg.lam_powers
            weights = c_modal_abs
            amp0 = (weights @ (powers * self._amp0[:, None])).tolist()
            ramp = (weights @ (powers * self._ramp[:, None])).tolist()
            parts = {k: (amp0[k - 1], ramp[k - 1], ramp[k - 2]) for k in range(2, 6)}
            hit = self._bounds[key] = (c_modal_abs, parts)
        return hit[1]


TAYLOR_MAX_SPAN = 2.0        # max|lam| L up to which TaylorSegment evaluates by polynomial
TAYLOR_TRUNCATION = 1e-17    # its truncation, relative to the modal amplitude of the derivative
_TAYLOR_DERIVATIVES = 2      # the highest derivative the searches ask of a polynomial (g'')
def _powers_of(s: float, count: int) -> np.ndarray:
    """``[1, s, s^2, .., s^(count-1)]`` as the running product of ``s`` (the Taylor polynomials'
    power row; the method, not ``np.cumprod``, whose wrapper costs as much as the product)."""
    powers = np.full(count, s).cumprod()
    powers[1:] = powers[:-1]
    powers[0] = 1.0
    return powers


_DEGREES = np.arange(64, dtype=float)          # k, and k (k - 1): the powers' slopes and curvatures (TaylorScan)
_DEGREES2 = _DEGREES * (_DEGREES - 1.0)


def _taylor_degree(rho: float) -> int:
    """Degree of :class:`TaylorSegment`'s polynomials: ``K0 + 3`` with ``K0`` the smallest k with
    ``rho^(k+1) / (k+1)! < TAYLOR_TRUNCATION`` (the second derivative's polynomial has degree
    ``K - 2``; one more term makes the tail, a series whose ratio is below 1/2, count too)."""
    k, term = 0, rho
    while term >= TAYLOR_TRUNCATION:
        k += 1
        term *= rho / (k + 1)
    return k + _TAYLOR_DERIVATIVES + 1


def _taylor_powers(lam, degree: int) -> tuple:
    """``(P1, P2, k, degree)`` of :func:`_taylor_columns` for eigenvalues ``lam``: with the powers
    ``P[:, j] = lam^j / j!`` (one cumulative product), ``P1 = P[:, 1:]``, ``P2 = P[:, :-1] / (k - 1)``
    and ``k = 2 .. degree``: what depends on the configuration and the degree only (kept by
    :meth:`Configuration.taylor_powers`)."""
    k = np.arange(2, degree + 1, dtype=float)
    P = np.ones((lam.size, degree), dtype=complex)
    P[:, 1:] = lam[:, None] / np.arange(1, degree, dtype=float)
    P.cumprod(axis=1, out=P)
    return P[:, 1:], P[:, :-1] / (k - 1.0), k, degree


def _taylor_columns(powers: tuple, q0, dq0, beta1) -> np.ndarray:
    """``(2n, degree + 1)``: column k is ``q^(k)(0) / k!`` (see :class:`TaylorSegment`):
    ``(lam^(k-1) q'(0) + lam^(k-2) beta1) / k!`` for ``k >= 2``, from the configuration's
    :func:`_taylor_powers` of that degree."""
    P1, P2, k, degree = powers
    cols = np.empty((q0.size, degree + 1), dtype=complex)
    cols[:, 0] = q0
    cols[:, 1] = dq0
    cols[:, 2:] = (dq0[:, None] * P1 + beta1[:, None] * P2) / k
    return cols


def _cubic_lower_bound_positive(g0: float, g1: float, g2: float, bound3: float, length: float) -> bool:
    """True if ``g0 + g1 s + g2 s^2/2 - bound3 s^3/6 > 0`` for every s in (0, length]."""
    if g0 < 0.0 or (g0 == 0.0 and (g1 < 0.0 or (g1 == 0.0 and g2 <= 0.0))):
        return False
    # P'(s) = g1 + g2 s - bound3 s^2 / 2: check P at the end and at interior critical points.
    candidates = [length]
    if bound3 > 0.0:
        disc = g2 * g2 + 2.0 * bound3 * g1
        if disc >= 0.0:
            r = math.sqrt(disc)
            candidates += [(g2 - r) / bound3, (g2 + r) / bound3]
    elif g2 != 0.0:
        candidates.append(-g1 / g2)
    for s in candidates:
        if 0.0 < s <= length and g0 + s * (g1 + s * (0.5 * g2 - s * bound3 / 6.0)) <= 0.0:
            return False
    return True


def first_root(segment: "ModalSegment", c_modal: np.ndarray, order: int, offset: float,
               length: float, xtol: float, min_width: float, budget: int = 200,
               c_modal_abs: np.ndarray | None = None) -> float | None:
    """First s in [0, length] where ``g = c' z^(order) + offset`` reaches 0 from above, or None.

    ``g`` should be >= 0 at s = 0; it may start at 0 (a storey that has just switched sits at
    its limit): values and slopes at the start within round-off of zero (``ROUNDOFF`` times
    the modal magnitude of the term) count as zero, and the sign of the first derivative that
    is not zero says whether ``g`` leaves at once (root 0) or moves inward.  A start clearly
    below zero is a root at 0.  Sub-intervals are excluded by a cubic Hermite bound and by a
    Taylor bound from their left end; the rest are bisected (``budget`` evaluations at most); a
    sign change is refined by bracketed Newton to ``xtol``.  The time returned is on or past
    the crossing (``g <= 0`` there): the state handed to the next law lies on the new side, or
    the switch would be undone at once.  A touch without crossing narrower than ``min_width``
    is not a root (a graze).  ``c_modal_abs``: ``|c_modal|`` if the caller keeps it.
    """
    c_abs = np.abs(c_modal) if c_modal_abs is None else c_modal_abs
    if order == 0:
        start, scale = segment.start_values(c_modal, c_abs)
    else:
        start = segment.derivatives(c_modal, 0.0, order + 3)[order:]
        scale = segment.magnitudes(c_abs, 0.0, order + 3)[order:]
    tol = [ROUNDOFF * m for m in scale]
    tol[0] += ROUNDOFF * abs(offset)
    g0 = start[0] + offset
    if g0 < -tol[0]:
        return 0.0
    if abs(g0) <= tol[0]:
        offset -= g0                          # exactly at the limit
        g1 = start[1] if abs(start[1]) > tol[1] else 0.0
        g2 = start[2] if abs(start[2]) > tol[2] else 0.0
        if g1 < 0.0 or (g1 == 0.0 and g2 < 0.0):
            return 0.0                        # leaves at once
        first = [0.0, g1, g2]
    else:
        first = [g0, start[1], start[2]]

    evaluate = segment.evaluator(c_modal, order + 3)

    def at(s):
        d = evaluate(s)[order:]
        d[0] += offset
        return d

    two = getattr(evaluate, "value_and_slope", None) if order == 0 else None
    if two is None:
        def newton(s):
            return tuple(at(s)[:2])
    else:
        def newton(s):
            v, d1 = two(s)
            return v + offset, d1

    stack = [(0.0, length)]
    values = {0.0: first}
    evaluations = 1
    while stack:
        a, b = stack.pop()
        va = values[a]
        vb = values.get(b)
        if vb is None:
            vb = values[b] = at(b)
            evaluations += 1
        width = b - a
        if vb[0] < 0.0 and va[0] > 0.0:
            lo, hi = bracketed_newton(newton, a, b, va[0], vb[0], xtol)
            return hi
        if vb[0] >= 0.0:
            b4 = segment.bound(c_abs, order + 4, a, width)
            lo, _ = hermite_range_scalar(va[0], vb[0], width * va[1], width * vb[1])
            if va[0] > 0.0 and lo - b4 * width ** 4 / 384.0 > 0.0:
                continue
            b3 = segment.bound(c_abs, order + 3, a, width)
            if _cubic_lower_bound_positive(va[0], va[1], va[2], b3, width):
                continue
            if width < min_width or evaluations >= budget:
                continue           # a graze narrower than the resolution, or out of budget
        elif width < min_width:
            return b               # from exactly 0 (moving inward) to below 0 within xtol
        mid = 0.5 * (a + b)
        values[mid] = at(mid)
        evaluations += 1
        stack.append((mid, b))
        stack.append((a, mid))  # left half first (LIFO)
    return None


def max_abs(segment: "ModalSegment", c_modal: np.ndarray, offset: float, length: float,
            known: float, xtol: float, min_width: float, budget: int = 200,
            rtol: float = PEAK_RTOL, atol: float = 0.0) -> tuple[float, float]:
    """``(max |g|, where)`` over [0, length] of ``g = c' z + offset`` if it exceeds ``known``.

    Branch and bound: a sub-interval whose Hermite bound on ``|g|`` stays at or below the best
    value found (plus ``rtol`` of it and ``atol``: the peak is then known to that accuracy), or
    on which ``g'`` provably keeps its sign (the extremes are then at its ends, already
    counted), is dropped; a sign change of ``g'`` is refined by bracketed Newton from the
    Hermite estimate, and the neighbourhood of that extremum in which the Taylor bound
    ``|g(t*)| - |g''(t*)| r^2 / 2 + B3 r^3 / 6`` (B3 bounds the third derivative) stays below
    ``|g(t*)|`` is dropped too.  Returns ``(known, -1.0)`` when nothing exceeds ``known``.
    ``xtol`` (s) is the tolerance of the extremum's time: the value's error is of the order of
    ``|g''| xtol^2``.
    """
    c_abs = np.abs(c_modal)

    evaluate = segment.evaluator(c_modal, 3)

    def at(s):
        d = evaluate(s)
        d[0] += offset
        return d

    values = {0.0: at(0.0), length: at(length)}
    best, where = known, -1.0
    for s in (0.0, length):
        if abs(values[s][0]) > best:
            best, where = abs(values[s][0]), s
    stack = [(0.0, length)]
    evaluations = 2
    while stack and evaluations < budget:
        a, b = stack.pop()
        va, vb = values[a], values[b]
        width = b - a
        w4 = width ** 4 / 384.0
        lo, hi = hermite_range_scalar(va[0], vb[0], width * va[1], width * vb[1])
        b45 = segment.bounds45(c_abs, a, width)
        if max(-lo, hi) + b45[0] * w4 <= best * (1.0 + rtol) + atol:
            continue
        dlo, dhi = hermite_range_scalar(va[1], vb[1], width * va[2], width * vb[2])
        err = b45[1] * w4
        if dlo - err > 0.0 or dhi + err < 0.0:
            continue                 # monotonic: its extremes are the ends
        if width < min_width:
            continue
        if va[1] * vb[1] < 0.0:
            lo_, hi_ = bracketed_newton(lambda s: tuple(at(s)[1:3]), a, b, va[1], vb[1], xtol,
                                        guess=a + width * va[1] / (va[1] - vb[1]))
            t = 0.5 * (lo_ + hi_)
        else:
            t = 0.5 * (a + b)
        if not (a < t < b):
            t = 0.5 * (a + b)
        vt = values[t] = at(t)
        evaluations += 1
        if abs(vt[0]) > best:
            best, where = abs(vt[0]), t
        radius = 0.0
        if vt[0] * vt[2] < 0.0:
            # a local maximum of |g| near t: |g(t + r)| <= |g(t)| + |g'(t)| r - |g''(t)| r^2 / 2
            # + B3 r^3 / 6 stays <= |g(t)| while |g'| + B3 r^2 / 6 <= |g''| r / 2
            b3 = segment.bound(c_abs, 3, a, width)
            g1_, g2_ = abs(vt[1]), abs(vt[2])
            disc = 0.25 * g2_ * g2_ - 4.0 * (b3 / 6.0) * g1_
            if b3 > 0.0 and disc >= 0.0:
                radius = (0.5 * g2_ + math.sqrt(disc)) / (2.0 * b3 / 6.0)
            radius = min(radius, width)
        for lo_end, hi_end in ((t + radius, b), (a, t - radius)):   # left part popped first
            if hi_end - lo_end <= 0.0:
                continue
            for end in (lo_end, hi_end):
                if end not in values:
                    values[end] = at(end)
                    evaluations += 1
            stack.append((lo_end, hi_end))
    return best, where
