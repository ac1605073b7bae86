"""Random float64 test inputs that reach the corners of interval code: magnitudes from
subnormal to near overflow, zeros of both signs, infinities, NaN and (optionally) the
largest finite double with either sign."""
import numpy as np

from verified.arith import _kernels as _k


def special_floats(rng, shape, *, max_exponent: int = 300, largest: bool = False) -> np.ndarray:
    """Floats of ``shape``: about 8 % +0.0, 6 % -0.0, 2-3 % each +inf, -inf and NaN, with
    ``largest`` 3 % +-``_kernels.MAXF``; the rest normal deviates times ``10^e``, ``e`` in
    ``[-320, max_exponent)`` (subnormals included)."""
    v = rng.standard_normal(shape) * 10.0 ** rng.integers(-320, max_exponent, shape)
    u = rng.random(shape)
    v = np.where(u < 0.08, 0.0, v)
    v = np.where((u >= 0.08) & (u < 0.14), -0.0, v)
    v = np.where((u >= 0.14) & (u < 0.165), np.inf, v)
    v = np.where((u >= 0.165) & (u < 0.19), -np.inf, v)
    v = np.where((u >= 0.19) & (u < 0.215), np.nan, v)
    if largest:
        v = np.where((u >= 0.215) & (u < 0.245), _k.MAXF * np.sign(v + 0.5), v)
    return v
