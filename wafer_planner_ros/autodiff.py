"""
Forward-mode derivatives for numpy code: values carrying their gradient.

The time optimisation needs exact gradients of joint and wafer quantities with respect to
the knot intervals; the B-spline basis recursion and the kinematics are written with plain
arithmetic, so running them on :class:`Dual` values yields those gradients analytically
(chain rule, no finite differences).
"""

import numpy as np


class Dual:
    """An array ``v`` with its gradient ``d`` (one more, trailing axis: the variables)."""

    __slots__ = ('v', 'd')
    __array_ufunc__ = None  # make ``ndarray op Dual`` use the Dual's reflected operator

    def __init__(self, v, d):
        """Wrap values and their gradient (``d.shape == v.shape + (m,)``)."""
        self.v = np.asarray(v, dtype=float)
        self.d = np.asarray(d, dtype=float)

    @classmethod
    def variables(cls, values) -> 'Dual':
        """Return independent variables: each value's gradient is a unit vector."""
        values = np.asarray(values, dtype=float)
        return cls(values, np.eye(len(values)))

    def __getitem__(self, index) -> 'Dual':
        """Return a gathered or sliced part."""
        return Dual(self.v[index], self.d[index])

    def expand(self) -> 'Dual':
        """Return the values with a new trailing axis of length 1 (for broadcasting)."""
        return Dual(self.v[..., None], self.d[..., None, :])

    def __add__(self, other) -> 'Dual':
        """Return self + other."""
        if isinstance(other, Dual):
            return Dual(self.v + other.v, self.d + other.d)  # numpy broadcasts both alike
        v = self.v + other
        d = self.d if v.shape == self.v.shape else np.broadcast_to(
            self.d, v.shape + self.d.shape[-1:])
        return Dual(v, d)

    __radd__ = __add__

    def __neg__(self) -> 'Dual':
        """Return -self."""
        return Dual(-self.v, -self.d)

    def __sub__(self, other) -> 'Dual':
        """Return self - other."""
        return self + (-other)

    def __rsub__(self, other) -> 'Dual':
        """Return other - self."""
        return (-self) + other

    def __mul__(self, other) -> 'Dual':
        """Return self * other."""
        if isinstance(other, Dual):
            return Dual(self.v * other.v,
                        self.d * other.v[..., None] + self.v[..., None] * other.d)
        other = np.asarray(other, dtype=float)
        return Dual(self.v * other, self.d * other[..., None])

    __rmul__ = __mul__

    def __truediv__(self, other) -> 'Dual':
        """Return self / other."""
        if isinstance(other, Dual):
            return self * other.reciprocal()
        other = np.asarray(other, dtype=float)
        return Dual(self.v / other, self.d / other[..., None])

    def __rtruediv__(self, other) -> 'Dual':
        """Return other / self."""
        return self.reciprocal() * other

    def reciprocal(self) -> 'Dual':
        """Return 1 / self."""
        inverse = 1.0 / self.v
        return Dual(inverse, -self.d * (inverse * inverse)[..., None])

    def total(self, axis) -> 'Dual':
        """Return the sum along a value axis."""
        return Dual(self.v.sum(axis=axis), self.d.sum(axis=_grad_axis(axis)))

    def cumsum(self, axis) -> 'Dual':
        """Return the cumulative sum along a value axis."""
        return Dual(np.cumsum(self.v, axis=axis), np.cumsum(self.d, axis=_grad_axis(axis)))

    @property
    def shape(self):
        """Return the shape of the values."""
        return self.v.shape


def _grad_axis(axis: int) -> int:
    return axis - 1 if axis < 0 else axis


def sin(x):
    """Return the sine of an array or Dual."""
    if isinstance(x, Dual):
        return Dual(np.sin(x.v), np.cos(x.v)[..., None] * x.d)
    return np.sin(x)


def cos(x):
    """Return the cosine of an array or Dual."""
    if isinstance(x, Dual):
        return Dual(np.cos(x.v), -np.sin(x.v)[..., None] * x.d)
    return np.cos(x)


def cumsum(x, axis: int):
    """Return the cumulative sum of an array or Dual along a value axis."""
    return x.cumsum(axis) if isinstance(x, Dual) else np.cumsum(x, axis=axis)


def total(x, axis: int):
    """Return the sum of an array or Dual along a value axis."""
    return x.total(axis) if isinstance(x, Dual) else np.sum(x, axis=axis)


def concatenate(parts: list) -> Dual:
    """Return the flattened Duals (all over the same variables) joined into one vector."""
    return Dual(np.concatenate([p.v.reshape(-1) for p in parts]),
                np.concatenate([p.d.reshape(-1, p.d.shape[-1]) for p in parts]))
