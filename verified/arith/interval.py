# Whole: the Interval type and the functions its operators call are one API.
"""Interval arrays: rigorous, outward-rounded interval arithmetic on numpy arrays.

An :class:`Interval` holds lower and upper bounds as float64 arrays of one shape and
broadcasts like numpy, so one operation processes thousands of boxes at once. A *box*
is an ``Interval`` whose last axis indexes the state components: shape ``(..., n)``.

Every operation returns an enclosure of the exact image of its operands (see
:mod:`verified.arith._kernels` for the rounding model). Floats and float arrays, in the
constructor or mixed into an operation, are taken as exact point values; ints beyond
2**53, ``fractions.Fraction`` and ``decimal.Decimal`` values are enclosed, never
rounded (``Interval(Fraction(1, 3))`` and ``Interval(1.0) * Fraction(1, 3)`` contain
one third, ``Interval(2**53 + 1)`` contains 2**53 + 1). To enclose a decimal such as
``0.1`` use ``Decimal("0.1")``, ``Fraction("0.1")`` or ``Interval(0.1).widen_ulps(1)``.

Conventions:

* ``lo <= hi``; bounds may be infinite only when produced by an operation (for
  example division by an interval containing zero) or when a user opts in with
  ``allow_unbounded=True``.
* The empty set is ``[+inf, -inf]``: :meth:`Interval.is_empty`. ``sqrt`` and ``log``
  are restricted to their domains as in IEEE 1788 (``sqrt([-4, 4]) = [0, 2]``,
  ``sqrt([-4, -1])`` is empty).
* Division by an interval that contains zero returns the hull of the exact image,
  which is unbounded (``[1, 2] / [0, 1] = [1, inf]``, ``[1, 2] / [-1, 1] = [-inf, inf]``).
* A NaN, an inverted pair of bounds or (by default) an infinite bound given by a user
  raises :class:`IntervalError`; so do ``[inf, inf]`` and ``[-inf, -inf]``, which
  contain no real number (IEEE 1788), even with ``allow_unbounded=True``.
* ``==``, ``!=``, ``<`` and the truth value raise ``TypeError``: use
  :meth:`Interval.equals` (the same sets), :meth:`~Interval.issubset`,
  :meth:`~Interval.overlaps` or :meth:`~Interval.contains`.
* Integer powers use repeated squaring (``log2(n)`` roundings); exponents must be
  finite, ``|n| < 2**62``.

numpy ufuncs dispatch here, so generic model code such as ``np.sin(q) * l`` runs on
floats, float arrays and intervals alike.
"""

from __future__ import annotations

import numbers
from decimal import Decimal
from fractions import Fraction

import numpy as np

from verified.arith import _kernels as _k
from verified.arith.exact import enclose_fraction

__all__ = [
    "Interval",
    "IntervalError",
    "point",
    "entire",
    "empty",
    "stack",
    "concatenate",
    "hull",
    "stack_hulls",
    "intersect",
    "sqr",
    "ipow",
    "sqrt",
    "exp",
    "log",
    "sin",
    "cos",
    "tan",
    "atan",
    "iabs",
    "minimum",
    "maximum",
]


class IntervalError(ValueError):
    """Invalid interval input: NaN, inverted bounds, or a non-finite bound."""


def _enclose_number(v, what):
    """(lo, hi) floats around one exact number: a float is its own enclosure; an int
    beyond 2**53, a ``Fraction`` or a ``Decimal`` lies between two neighbouring floats."""
    if isinstance(v, np.integer):
        v = int(v)
    if isinstance(v, Decimal):
        if not v.is_finite():
            return float(v), float(v)  # NaN and +-inf: the caller's checks refuse them
        v = Fraction(v)
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
        raise IntervalError(f"{what} must be real numbers, got {type(v).__name__}: {v!r}")
    if not isinstance(v, numbers.Rational):  # float, np.floating: exact in float64 (longdouble aside)
        f = float(v)
        if isinstance(v, np.floating) and np.finfo(type(v)).nmant > 52 and np.isfinite(v):
            lo = f if np.longdouble(f) <= v else float(np.nextafter(f, -np.inf))
            hi = f if np.longdouble(f) >= v else float(np.nextafter(f, np.inf))
            return lo, hi
        return f, f
    try:
        return enclose_fraction(v)
    except OverflowError:
        raise IntervalError(f"{what}: the number {v!r} is beyond the float range") from None


def _needs_enclosure(value):
    """Whether a (nested) list or tuple holds a number that float64 cannot hold exactly."""
    if isinstance(value, (list, tuple)):
        return any(_needs_enclosure(v) for v in value)
    if isinstance(value, (bool, float, np.floating)) and not isinstance(value, np.longdouble):
        return False
    if isinstance(value, int):
        return abs(value) > 2**53
    return isinstance(value, (Fraction, Decimal, np.longdouble))


def _enclose(value, what):
    """(lo, hi) float64 arrays that enclose the exact values given.

    Floats (and float arrays) are taken as exact. Integers beyond 2**53, ``Fraction``
    and ``Decimal`` values, in scalars or nested sequences, are enclosed between
    neighbouring floats, never rounded to nearest: ``Interval(Fraction(1, 3))``
    contains one third."""
    if isinstance(value, np.ndarray) and value.dtype == np.float64:
        return value, value
    if isinstance(value, float):
        arr = np.asarray(value)
        return arr, arr
    try:
        # numpy turns a list holding 2**63 + 1 into float64 (rounded): look first
        arr = np.asarray(value, dtype=object) if _needs_enclosure(value) else np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise IntervalError(f"{what} must be real numbers, got {type(value).__name__}: {exc}") from None
    kind = arr.dtype.kind
    if kind == "f" and arr.dtype.itemsize <= 8:  # float16/32 values are exact in float64
        f = arr.astype(np.float64)
        return f, f
    if kind in "iu" and (arr.size == 0 or (arr.min() >= -(2**53) and arr.max() <= 2**53)):
        f = arr.astype(np.float64)  # every integer up to 2**53 is a float
        return f, f
    if kind in "fiuO":  # big ints, longdouble, Fractions, Decimals, mixtures: one by one
        # tolist() gives Python ints (numpy ints would overflow in Fraction comparisons);
        # longdouble items stay numpy scalars, which tolist() would round to float
        items = list(arr.reshape(-1)) if kind == "f" else arr.reshape(-1).tolist()
        pairs = [_enclose_number(v, what) for v in items]
        lo = np.array([p[0] for p in pairs], dtype=np.float64).reshape(arr.shape)
        hi = np.array([p[1] for p in pairs], dtype=np.float64).reshape(arr.shape)
        return lo, hi
    raise IntervalError(f"{what} must be real numbers, got {type(value).__name__} of dtype {arr.dtype}")


def _check_user_bounds(lo, hi, allow_unbounded):
    if lo is hi:
        # one array for both bounds (a float or float array given as ``lo`` alone): only
        # NaN and infinities can be wrong, and finite values are the common case
        if np.isfinite(lo).all():
            return
    if np.isnan(lo).any() or np.isnan(hi).any():
        raise IntervalError("interval bounds contain NaN")
    bad = lo > hi
    if bad.any():
        idx = np.argwhere(np.atleast_1d(bad))[0]
        where = "" if lo.ndim == 0 else f" at index {tuple(int(i) for i in idx)}"
        l0 = float(np.atleast_1d(lo)[tuple(idx)])
        h0 = float(np.atleast_1d(hi)[tuple(idx)])
        raise IntervalError(f"inverted interval{where}: lower bound {l0!r} > upper bound {h0!r}")
    if not allow_unbounded and not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise IntervalError(
            "interval bounds must be finite (pass allow_unbounded=True to build unbounded intervals)"
        )
    if (lo == np.inf).any() or (hi == -np.inf).any():
        # IEEE 1788: [inf, inf] and [-inf, -inf] contain no real number (inf - inf would be NaN)
        raise IntervalError("an interval cannot have lower bound +inf or upper bound -inf "
                            "([inf, inf] contains no real number)")


_OPERAND_TYPES = (numbers.Real, np.ndarray, list, tuple)  # Interval added below


class Interval:
    """An array of closed real intervals ``[lo, hi]``.

    Parameters
    ----------
    lo, hi : array_like
        Lower and upper bounds; they broadcast against each other. ``hi=None`` makes
        point intervals ``[lo, lo]``. An ``Interval`` passed as ``lo`` is copied.
    allow_unbounded : bool
        Accept infinite bounds (default: refuse them, since a user-given infinite
        bound is usually a mistake).

    Raises
    ------
    IntervalError
        For NaN bounds, ``lo > hi``, or infinite bounds without ``allow_unbounded``.
    """

    __slots__ = ("lo", "hi")
    __array_priority__ = 1000  # make ndarray + Interval defer to Interval.__radd__

    def __init__(self, lo, hi=None, *, allow_unbounded=False):
        if isinstance(lo, Interval) and hi is None:
            self.lo = lo.lo.copy()
            self.hi = lo.hi.copy()
            return
        if hi is None:
            lo, hi = _enclose(lo, "bounds")
        else:
            lo = _enclose(lo, "lower bounds")[0]
            hi = _enclose(hi, "upper bounds")[1]
        if lo is not hi:  # (one array for both bounds, from ``lo`` alone: nothing to broadcast,
            # and _check_user_bounds then checks it once)
            try:
                lo, hi = np.broadcast_arrays(lo, hi)
            except ValueError:
                raise IntervalError(f"bounds of shapes {lo.shape} and {hi.shape} do not broadcast") from None
        _check_user_bounds(lo, hi, allow_unbounded)
        self.lo = np.array(lo, dtype=np.float64)
        self.hi = np.array(hi, dtype=np.float64)

    @classmethod
    def _from_bounds(cls, lo, hi):
        """Wrap bound arrays without validation or copy (internal fast path)."""
        obj = object.__new__(cls)
        obj.lo = lo
        obj.hi = hi
        return obj

    # ------------------------------------------------------------------ shape
    @property
    def shape(self):
        return self.lo.shape

    @property
    def ndim(self):
        return self.lo.ndim

    @property
    def size(self):
        return self.lo.size

    def __len__(self):
        return len(self.lo)

    def __getitem__(self, idx):
        return Interval._from_bounds(self.lo[idx], self.hi[idx])

    def __setitem__(self, idx, value):
        lo, hi = _bounds(value)
        self.lo[idx] = lo
        self.hi[idx] = hi

    def __iter__(self):
        for i in range(len(self)):
            yield self[i]

    def reshape(self, *shape):
        return Interval._from_bounds(self.lo.reshape(*shape), self.hi.reshape(*shape))

    @property
    def T(self):
        return Interval._from_bounds(self.lo.T, self.hi.T)

    def swapaxes(self, a, b):
        return Interval._from_bounds(self.lo.swapaxes(a, b), self.hi.swapaxes(a, b))

    def broadcast_to(self, shape):
        return Interval._from_bounds(np.broadcast_to(self.lo, shape), np.broadcast_to(self.hi, shape))

    def copy(self):
        return Interval._from_bounds(self.lo.copy(), self.hi.copy())

    def __repr__(self):
        if self.ndim == 0:
            return f"Interval({float(self.lo)!r}, {float(self.hi)!r})"
        return f"Interval(lo={self.lo!r},\n         hi={self.hi!r})"

    # ------------------------------------------------------- set properties
    def is_empty(self):
        """Boolean array: True where the interval is the empty set."""
        return self.lo > self.hi

    def is_bounded(self):
        return np.isfinite(self.lo) & np.isfinite(self.hi)

    def mid(self):
        """A float inside each interval, near its midpoint (0 for ``[-inf, inf]``;
        the finite float nearest to an infinite end for half-unbounded intervals)."""
        out = _bound_loop(_k.mid_loop, self.lo, self.hi)
        if out is None:
            return _mid_np(self.lo, self.hi)
        return out if out.ndim else out[()]

    def rad(self):
        """Upper bound ``r`` such that ``[mid - r, mid + r]`` contains the interval."""
        out = _bound_loop(_k.rad_loop, self.lo, self.hi)
        if out is None:
            return _rad_np(self.lo, self.hi)
        return out if out.ndim else out[()]

    def width(self):
        """Upper bound of ``hi - lo`` (0 for empty intervals)."""
        out = _bound_loop(_k.width_loop, self.lo, self.hi)
        return _width_np(self.lo, self.hi) if out is None else out

    def mag(self):
        """``max |x|`` over the interval (exact)."""
        return np.maximum(np.abs(self.lo), np.abs(self.hi))

    def contains(self, values):
        """Boolean array: True where the float ``values`` lie in the interval."""
        v = np.asarray(values, dtype=np.float64)
        return (self.lo <= v) & (v <= self.hi)

    def issubset(self, other):
        """Boolean array: True where ``self`` is a subset of ``other`` (empty is a subset of all)."""
        olo, ohi = _bounds(other)
        return ((olo <= self.lo) & (self.hi <= ohi)) | self.is_empty()

    def interior_subset(self, other):
        """True where ``self`` lies in the interior of ``other``."""
        olo, ohi = _bounds(other)
        return (olo < self.lo) & (self.hi < ohi)

    def overlaps(self, other):
        """True where ``self`` and ``other`` share at least one point."""
        olo, ohi = _bounds(other)
        return np.maximum(self.lo, olo) <= np.minimum(self.hi, ohi)

    def intersect(self, other):
        """Intersection; disjoint pairs give the empty interval ``[inf, -inf]``."""
        olo, ohi = _bounds(other)
        lo = np.maximum(self.lo, olo)
        hi = np.minimum(self.hi, ohi)
        bad = lo > hi
        if bad.any():
            lo = np.where(bad, np.inf, lo)
            hi = np.where(bad, -np.inf, hi)
        return Interval._from_bounds(lo, hi)

    def hull(self, other):
        """Interval hull of the union (empty operands are neutral)."""
        olo, ohi = _bounds(other)
        return Interval._from_bounds(np.minimum(self.lo, olo), np.maximum(self.hi, ohi))

    def equals(self, other):
        olo, ohi = _bounds(other)
        return (self.lo == olo) & (self.hi == ohi)

    def widen_ulps(self, n=1):
        """Move each bound ``n`` floats outward (to enclose an inexactly stored constant)."""
        lo, hi = self.lo, self.hi
        for _ in range(int(n)):
            lo = np.nextafter(lo, -np.inf)
            hi = np.nextafter(hi, np.inf)
        return Interval._from_bounds(lo, hi)

    # ------------------------------------------------------------ splitting
    def bisect(self, index=None, axis=-1):
        """Split boxes in two at the midpoint of one component.

        Parameters
        ----------
        index : int or int array, optional
            Component (position along ``axis``) to split; an array gives one
            component per box. Default: each box's widest component.
        axis : int
            The axis that indexes components (default: the last).

        Returns
        -------
        (left, right) : two Intervals of the input's shape whose union is the input.
        """
        lo = np.moveaxis(self.lo, axis, -1)
        hi = np.moveaxis(self.hi, axis, -1)
        if index is None:
            index = np.argmax(hi - lo, axis=-1)
        index = np.broadcast_to(np.asarray(index), lo.shape[:-1])[..., None]
        sel = Interval._from_bounds(
            np.take_along_axis(lo, index, -1), np.take_along_axis(hi, index, -1)
        )
        m = sel.mid()
        left_hi = hi.copy()
        right_lo = lo.copy()
        np.put_along_axis(left_hi, index, m, -1)
        np.put_along_axis(right_lo, index, m, -1)
        left = Interval._from_bounds(np.moveaxis(lo.copy(), -1, axis), np.moveaxis(left_hi, -1, axis))
        right = Interval._from_bounds(np.moveaxis(right_lo, -1, axis), np.moveaxis(hi.copy(), -1, axis))
        return left, right

    def subdivide(self, pieces, axis=-1):
        """Split each box into a uniform grid.

        Parameters
        ----------
        pieces : int or sequence of int
            Number of pieces per component (one int for all components).
        axis : int
            The component axis (default: the last).

        Returns
        -------
        Interval of shape ``(..., prod(pieces), n)`` (components moved to the last
        axis) whose union over the new axis is exactly the input box.
        """
        lo = np.moveaxis(self.lo, axis, -1)
        hi = np.moveaxis(self.hi, axis, -1)
        n = lo.shape[-1]
        pieces = np.broadcast_to(np.asarray(pieces, dtype=int), (n,))
        if (pieces < 1).any():
            raise ValueError(f"pieces must be >= 1, got {pieces.tolist()}")
        if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
            raise ValueError("cannot subdivide boxes with infinite or empty bounds")
        edges_lo, edges_hi = [], []
        for j in range(n):
            k = int(pieces[j])
            t = np.arange(k + 1) / k
            with np.errstate(invalid="ignore", over="ignore"):
                e = lo[..., j, None] * (1.0 - t) + hi[..., j, None] * t
            # Rounding may push an edge outside the box or out of order: clip and
            # sort so the pieces are subsets whose union is exactly the box.
            e = np.clip(e, lo[..., j, None], hi[..., j, None])
            e[..., 0] = lo[..., j]
            e[..., -1] = hi[..., j]
            e = np.maximum.accumulate(e, axis=-1)
            edges_lo.append(e[..., :-1])
            edges_hi.append(e[..., 1:])
        grids_lo = np.stack(np.meshgrid(*[np.arange(int(p)) for p in pieces], indexing="ij"), -1).reshape(-1, n)
        out_lo = np.stack([edges_lo[j][..., grids_lo[:, j]] for j in range(n)], -1)
        out_hi = np.stack([edges_hi[j][..., grids_lo[:, j]] for j in range(n)], -1)
        return Interval._from_bounds(out_lo, out_hi)

    # ----------------------------------------------------------- arithmetic
    def __add__(self, other):
        if not isinstance(other, _OPERAND_TYPES):
            return NotImplemented
        return _binary(_k.add_loop, self, other)

    def __radd__(self, other):
        if not isinstance(other, _OPERAND_TYPES):
            return NotImplemented
        return _binary(_k.add_loop, other, self)

    def __sub__(self, other):
        if not isinstance(other, _OPERAND_TYPES):
            return NotImplemented
        return _binary(_k.sub_loop, self, other)

    def __rsub__(self, other):
        if not isinstance(other, _OPERAND_TYPES):
            return NotImplemented
        return _binary(_k.sub_loop, other, self)

    def __mul__(self, other):
        if not isinstance(other, _OPERAND_TYPES):
            return NotImplemented
        return _binary(_k.mul_loop, self, other)

    def __rmul__(self, other):
        if not isinstance(other, _OPERAND_TYPES):
            return NotImplemented
        return _binary(_k.mul_loop, other, self)

    def __truediv__(self, other):
        if not isinstance(other, _OPERAND_TYPES):
            return NotImplemented
        return _binary(_k.div_loop, self, other)

    def __rtruediv__(self, other):
        if not isinstance(other, _OPERAND_TYPES):
            return NotImplemented
        return _binary(_k.div_loop, other, self)

    def __neg__(self):
        return Interval._from_bounds(-self.hi, -self.lo)

    def __pos__(self):
        return self

    def __abs__(self):
        return iabs(self)

    def __pow__(self, exponent):
        return _power(self, exponent)

    def __matmul__(self, other):
        return matmul(self, other)

    def __rmatmul__(self, other):
        return matmul(other, self)

    def sum(self, axis=None):
        """Outward-rounded sum along ``axis`` (pairwise, vectorized over the other axes)."""
        x = self.reshape(-1) if axis is None else self.swapaxes(axis, -1)
        while x.shape[-1] > 1:
            k = x.shape[-1] // 2
            paired = x[..., :k] + x[..., k : 2 * k]
            x = concatenate([paired, x[..., 2 * k :]], axis=-1) if x.shape[-1] % 2 else paired
        if x.shape[-1] == 0:
            return point(np.zeros(x.shape[:-1]))
        return x[..., 0]

    def dot(self, other):
        return matmul(self, other)

    # Comparisons between intervals have no single meaning: refuse them loudly.
    def _no_order(self, other):
        raise TypeError(
            "intervals are not ordered; use .lo/.hi, .contains(), .issubset() or .overlaps()"
        )

    __lt__ = __le__ = __gt__ = __ge__ = _no_order

    # ``==`` has two meanings for intervals (the same set? the same point?) and the
    # default, object identity, is a silent trap: refuse it as IntervalArithmetic.jl does.
    def __eq__(self, other):
        if isinstance(other, _OPERAND_TYPES):
            raise TypeError(
                "== and != are not defined for intervals; use x.equals(y) (the same sets), "
                "x.issubset(y), x.overlaps(y) or x.contains(values)"
            )
        return NotImplemented

    __ne__ = __eq__

    def __bool__(self):
        raise TypeError("the truth value of an Interval is ambiguous; use .is_empty() or .contains()")

    __hash__ = None

    # ------------------------------------------------------------ numpy hooks
    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        if method != "__call__" or kwargs:
            return NotImplemented
        if ufunc in (np.equal, np.not_equal):  # np.float64(1) == x lands here, not in __eq__
            Interval.__eq__(self, self)
        fn = _UFUNCS.get(ufunc)
        if fn is None:
            return NotImplemented
        return fn(*inputs)

    def __array__(self, dtype=None, copy=None):
        raise TypeError(
            "an Interval cannot be converted to a float array; use .mid(), .lo or .hi explicitly"
        )


_OPERAND_TYPES = _OPERAND_TYPES + (Interval,)


# --------------------------------------------------------------------- helpers
def _k_round_up(x):
    """Upper bound of the exact result of one correctly rounded operation (vectorized)."""
    return np.where(x == -np.inf, -_k.MAXF, x + (np.abs(x) * _k.EPS + _k.ETA))


# ------------------------------------------------- midpoint, radius, width (compiled)
def _bound_loop(loop, lo, hi):
    """``loop`` (``_kernels.mid_loop``, ``rad_loop``, ``width_loop``: the expressions of
    :func:`_mid_np`, :func:`_rad_np`, :func:`_width_np` element by element, bit for
    bit) over float64 bounds of one shape; None for anything else (the numpy path)."""
    if type(lo) is not np.ndarray or type(hi) is not np.ndarray or lo.shape != hi.shape \
            or lo.dtype != np.float64 or hi.dtype != np.float64:
        return None
    out = np.empty(lo.shape)
    loop(_k.kernel_array(lo).reshape(-1), _k.kernel_array(hi).reshape(-1), out.reshape(-1))
    return out


def _mid_np(lo, hi):
    """:meth:`Interval.mid` in numpy (the reference of ``_kernels.mid_loop``)."""
    with np.errstate(invalid="ignore", over="ignore"):
        m = 0.5 * lo + 0.5 * hi
    m = np.where(np.isnan(m), 0.0, m)  # [-inf, inf]
    return np.clip(m, np.maximum(lo, -_k.MAXF), np.minimum(hi, _k.MAXF))


def _rad_np(lo, hi):
    """:meth:`Interval.rad` in numpy (the reference of ``_kernels.rad_loop``)."""
    m = _mid_np(lo, hi)
    with np.errstate(invalid="ignore", over="ignore"):
        r = np.maximum(_k_round_up(m - lo), _k_round_up(hi - m))
    return r


def _width_np(lo, hi):
    """:meth:`Interval.width` in numpy (the reference of ``_kernels.width_loop``)."""
    with np.errstate(invalid="ignore", over="ignore"):
        w = _k_round_up(hi - lo)
    return np.where(lo > hi, 0.0, w)


def _bounds(x):
    """(lo, hi) float arrays of an Interval, or enclosing exact values (floats are
    exact; big ints, Fractions and Decimals are enclosed, see :func:`_enclose`)."""
    if isinstance(x, Interval):
        return x.lo, x.hi
    lo, hi = _enclose(x, "operand")
    if not (np.isfinite(lo).all() and (hi is lo or np.isfinite(hi).all())):
        raise IntervalError(f"non-finite value (NaN or inf) used in interval arithmetic: {x!r}")
    return lo, hi


def _flat(arr, shape):
    if arr.shape != shape:
        # (a fresh array filled by broadcasting: cheaper than np.broadcast_to's read-only
        # view and the copy the kernel then needs, on every operation with a scalar operand)
        out = np.empty(shape)
        out[...] = arr
        return out.reshape(-1)
    return _k.kernel_array(arr).reshape(-1)


def _binary(loop, x, y):
    xl, xh = (x.lo, x.hi) if type(x) is Interval else _bounds(x)
    yl, yh = (y.lo, y.hi) if type(y) is Interval else _bounds(y)
    xs, ys = xl.shape, yl.shape
    try:
        # (a scalar operand: the other's shape, as broadcasting gives it)
        shape = xs if (xs == ys or not ys) else (ys if not xs else np.broadcast_shapes(xs, ys))
    except ValueError:
        raise ValueError(f"interval operands of shapes {xl.shape} and {yl.shape} do not broadcast") from None
    lo = np.empty(shape)
    hi = np.empty(shape)
    loop(_flat(xl, shape), _flat(xh, shape), _flat(yl, shape), _flat(yh, shape), lo.reshape(-1), hi.reshape(-1))
    return Interval._from_bounds(lo, hi)


def _unary(loop, x):
    xl, xh = _bounds(x)
    shape = xl.shape
    lo = np.empty(shape)
    hi = np.empty(shape)
    loop(_flat(xl, shape), _flat(xh, shape), lo.reshape(-1), hi.reshape(-1))
    return Interval._from_bounds(lo, hi)


_MAX_EXPONENT = 2**62  # integer exponents are evaluated in int64 by repeated squaring


def _integer_exponent(n):
    """``n`` as a Python int, or a one-line error for a non-integer, infinite or absurd one."""
    if isinstance(n, (bool, np.bool_)):
        raise TypeError(f"integer exponent expected, got {n!r}")
    if not isinstance(n, numbers.Integral):
        try:
            f = float(n)
        except (TypeError, ValueError):
            raise TypeError(f"integer exponent expected, got {type(n).__name__}: {n!r}") from None
        if not np.isfinite(f):
            raise IntervalError(f"exponent {n!r} is not finite")
        if not f.is_integer():
            raise TypeError(f"integer exponent expected, got {n!r}")
        n = int(f)
    n = int(n)
    if abs(n) >= _MAX_EXPONENT:
        raise IntervalError(f"integer exponent {n} is too large (|n| < 2**62 supported)")
    return n


def _power(x, exponent):
    if isinstance(exponent, Interval):
        raise TypeError("interval exponents are not supported; use exp(y * log(x))")
    if not isinstance(exponent, numbers.Integral) and isinstance(exponent, numbers.Real) \
            and float(exponent) == 0.5:
        return sqrt(x)
    try:
        n = _integer_exponent(exponent)
    except TypeError:
        raise TypeError(f"only integer exponents (and 0.5) are supported, got {exponent!r}") from None
    return ipow(x, n)


# ----------------------------------------------------------- public functions
def point(values):
    """Point intervals ``[v, v]`` for exact float values (finite)."""
    lo, hi = _bounds(values)
    return Interval._from_bounds(np.array(lo), np.array(hi))


def entire(shape=()):
    """Intervals ``[-inf, inf]`` of the given shape."""
    return Interval._from_bounds(np.full(shape, -np.inf), np.full(shape, np.inf))


def empty(shape=()):
    """Empty intervals ``[inf, -inf]`` of the given shape."""
    return Interval._from_bounds(np.full(shape, np.inf), np.full(shape, -np.inf))


def _as_interval(x):
    if isinstance(x, Interval):
        return x
    lo, hi = _bounds(x)
    return Interval._from_bounds(lo, hi)


def stack(intervals, axis=0):
    """Stack Intervals (or exact floats) along a new axis, like ``np.stack``."""
    items = [_as_interval(x) for x in intervals]
    shape = np.broadcast_shapes(*[i.shape for i in items])  # once: per item it was O(N^2)
    return Interval._from_bounds(
        np.stack([np.broadcast_to(x.lo, shape) for x in items], axis),
        np.stack([np.broadcast_to(x.hi, shape) for x in items], axis),
    )


def concatenate(intervals, axis=0):
    """Join Intervals along an existing axis, like ``np.concatenate``."""
    items = [_as_interval(x) for x in intervals]
    return Interval._from_bounds(
        np.concatenate([x.lo for x in items], axis), np.concatenate([x.hi for x in items], axis)
    )


def hull(x, y=None, axis=None):
    """Hull of two intervals, or of all intervals of ``x`` along ``axis``."""
    if y is not None:
        return _as_interval(x).hull(y)
    x = _as_interval(x)
    return Interval._from_bounds(np.min(x.lo, axis=axis), np.max(x.hi, axis=axis))


def stack_hulls(list_of_boxes) -> Interval:
    """(k, n): the hull of each batch of boxes (B_j, n) in a list of k, stacked (the
    ``hull`` and ``tube_hull`` of a solution)."""
    return stack([hull(b, axis=0) for b in list_of_boxes], axis=0)


def intersect(x, y):
    return _as_interval(x).intersect(y)


def sqr(x):
    """Square: ``sqr([-1, 2]) = [0, 4]`` (tighter than ``x * x = [-2, 4]``)."""
    return _unary(_k.sqr_loop, x)


def ipow(x, n):
    """Integer power ``x ** n`` (even powers are non-negative; ``n < 0`` divides)."""
    n = _integer_exponent(n)
    xl, xh = _bounds(x)
    shape = xl.shape
    lo = np.empty(shape)
    hi = np.empty(shape)
    _k.ipow_loop(_flat(xl, shape), _flat(xh, shape), n, lo.reshape(-1), hi.reshape(-1))
    return Interval._from_bounds(lo, hi)


def sqrt(x):
    """Square root on the domain ``[0, inf]`` (IEEE 1788: negative parts are dropped)."""
    return _unary(_k.sqrt_loop, x)


def exp(x):
    return _unary(_k.exp_loop, x)


def log(x):
    """Natural log on the domain ``(0, inf]``; ``log([0, 1]) = [-inf, 0]``."""
    return _unary(_k.log_loop, x)


def sin(x):
    return _unary(_k.sin_loop, x)


def cos(x):
    return _unary(_k.cos_loop, x)


def tan(x):
    """Tangent; ``[-inf, inf]`` where the interval may contain a pole."""
    return _unary(_k.tan_loop, x)


def atan(x):
    return _unary(_k.atan_loop, x)


def iabs(x):
    return _unary(_k.iabs_loop, x)


def minimum(x, y):
    return _binary(_k.imin_loop, x, y)


def maximum(x, y):
    return _binary(_k.imax_loop, x, y)


def _add(x, y):
    return _binary(_k.add_loop, x, y)


def _sub(x, y):
    return _binary(_k.sub_loop, x, y)


def _mul(x, y):
    return _binary(_k.mul_loop, x, y)


def _div(x, y):
    return _binary(_k.div_loop, x, y)


def _neg(x):
    return -_as_interval(x)


_UFUNCS = {
    np.add: _add,
    np.subtract: _sub,
    np.multiply: _mul,
    np.true_divide: _div,
    np.negative: _neg,
    np.positive: _as_interval,
    np.square: sqr,
    np.power: _power,
    np.sqrt: sqrt,
    np.exp: exp,
    np.log: log,
    np.sin: sin,
    np.cos: cos,
    np.tan: tan,
    np.arctan: atan,
    np.absolute: iabs,
    np.minimum: minimum,
    np.maximum: maximum,
    np.fmin: minimum,
    np.fmax: maximum,
}


# --------------------------------------------------------------------------- matrix products
# (here, not in verified.arith.linalg: the @ operator needs them, and linalg builds on Interval)
def _flatten(x, batch_shape, core_shape):
    full = batch_shape + core_shape
    # (broadcast only where the shape differs: a broadcast view is read-only, and copied)
    lo = _k.kernel_array(x.lo if x.lo.shape == full else np.broadcast_to(x.lo, full)).reshape((-1,) + core_shape)
    hi = _k.kernel_array(x.hi if x.hi.shape == full else np.broadcast_to(x.hi, full)).reshape((-1,) + core_shape)
    return lo, hi


def matmul(a, b):
    """Interval matrix product ``a @ b`` with numpy's ``matmul`` shape rules.

    Parameters
    ----------
    a : Interval or float array, shape ``(..., n, k)``
    b : Interval or float array, shape ``(..., k, m)``, or ``(k,)`` for one vector
        (use :func:`matvec` for a batch of vectors ``(..., k)``).

    Returns
    -------
    Interval of shape ``(..., n, m)`` (``(..., n)`` for a 1-d ``b``): encloses every
    product of point matrices taken from ``a`` and ``b``. Floats are exact points.
    """
    a = _as_interval(a)
    b = _as_interval(b)
    if b.ndim == 1:
        return matvec(a, b)
    if a.ndim < 2:
        raise ValueError(f"matmul needs a matrix on the left, got shape {a.shape}")
    if a.shape[-1] != b.shape[-2]:
        raise ValueError(
            f"matmul shapes {a.shape} and {b.shape} do not align (inner sizes {a.shape[-1]} vs {b.shape[-2]})"
        )
    try:
        batch = np.broadcast_shapes(a.shape[:-2], b.shape[:-2])
    except ValueError:
        raise ValueError(f"matmul batch shapes {a.shape[:-2]} and {b.shape[:-2]} do not broadcast") from None
    alo, ahi = _flatten(a, batch, a.shape[-2:])
    blo, bhi = _flatten(b, batch, b.shape[-2:])
    clo, chi = _k.matmul_bounds(alo, ahi, blo, bhi)
    shape = batch + (a.shape[-2], b.shape[-1])
    return Interval._from_bounds(clo.reshape(shape), chi.reshape(shape))


def matvec(a, x):
    """Batched interval matrix-vector product: ``(..., n, k) x (..., k) -> (..., n)``."""
    a = _as_interval(a)
    x = _as_interval(x)
    if x.ndim < 1:
        raise ValueError("matvec needs a vector on the right")
    if a.ndim >= 2 and a.shape[:-2] == x.shape[:-1] and a.shape[-1] == x.shape[-1] and a.size:
        # (the same batch, no broadcasting: one compiled call, the same bounds as
        # matmul's with one column, without its shape handling; the set code makes ~20
        # such products a step)
        n, k = a.shape[-2:]
        alo = _k.kernel_array(a.lo).reshape((-1, n, k))
        ahi = _k.kernel_array(a.hi).reshape((-1, n, k))
        xlo = _k.kernel_array(x.lo).reshape((-1, k))
        xhi = _k.kernel_array(x.hi).reshape((-1, k))
        clo, chi = _k.matvec_bounds(alo, ahi, xlo, xhi)
        shape = a.shape[:-1]
        return Interval._from_bounds(clo.reshape(shape), chi.reshape(shape))
    return matmul(a, x.reshape(x.shape + (1,)))[..., 0]
