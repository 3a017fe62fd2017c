"""Aggregation kernels beta(u, v) of Smoluchowski's equation.

As functions of two particle volumes u, v in units of a reference volume v_ref = x_ref^3
(dimensionless).

With the state in mass fractions M_i and the number per class N_i = M_i / v_i (v_i the
pivot volume of class i in units of v_ref), beta [1/s] is the collision-and-stick rate of a
pair per unit N: a charge made only of reference-size particles (N = 1) loses number at
dN/dt = -beta0/2 at t = 0 under the constant kernel.

- constant:        beta = beta0                              (Smoluchowski 1917)
- sum (Golovin):   beta = beta0 (u + v)                      (Golovin 1963)
- product:         beta = beta0 u v                          (gels in finite time)
- shear:           beta = beta0 (u^(1/3) + v^(1/3))^3        (orthokinetic, Smoluchowski)
- user:            beta = f(u, v), vectorised over arrays, checked non-negative, finite
                   and symmetric on the pivots where it is evaluated.

References
----------
M. von Smoluchowski, Versuch einer mathematischen Theorie der Koagulationskinetik
kolloider Lösungen, Z. phys. Chem. 92 (1917) 129-168; A. M. Golovin, The solution of
the coagulation equation for cloud droplets in a rising air current, Izv. Akad. Nauk
SSSR, Ser. Geofiz. (1963).

Examples
--------
>>> import numpy as np
>>> k = sum_kernel(2.0)
>>> k.matrix(np.array([2.0, 1.0]))  # beta0 (u + v) on the pivots [1/s]
array([[8., 6.],
       [6., 4.]])
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from millflow.errors import InputError

__all__ = ["KernelError", "Kernel", "constant_kernel", "sum_kernel", "product_kernel", "shear_kernel",
           "user_kernel", "KERNELS"]


class KernelError(InputError):
    """An aggregation kernel is negative, non-finite or not symmetric."""


@dataclass(frozen=True)
class Kernel:
    """An aggregation kernel: name, rate constant and shape.

    An aggregation kernel: ``name``, rate constant ``beta0`` [1/s], and ``func(u, v)``
    (dimensionless shape, multiplied by beta0). Call :meth:`matrix` on pivot volumes.
    """

    name: str
    beta0: float
    func: Callable

    def __post_init__(self):
        if not (isinstance(self.beta0, (int, float)) and math.isfinite(self.beta0) and self.beta0 >= 0):
            raise KernelError(f"aggregation kernel {self.name!r}: beta0 = {self.beta0!r}; expected a finite "
                              "rate >= 0 [1/s]")

    def matrix(self, v) -> np.ndarray:
        """beta(v_j, v_k) on the pivot volumes v (dimensionless); (N, N), checked."""
        v = np.asarray(v, float)
        try:
            B = self.beta0 * np.asarray(self.func(v[:, None], v[None, :]), float)
        except (TypeError, ValueError) as exc:
            raise KernelError(f"aggregation kernel {self.name!r}: cannot evaluate f(u, v) on arrays ({exc})") from exc
        B = np.broadcast_to(B, (v.size, v.size)).copy()
        if not np.isfinite(B).all():
            j, k = np.argwhere(~np.isfinite(B))[0]
            raise KernelError(f"aggregation kernel {self.name!r}: beta(v={v[j]:.6g}, v={v[k]:.6g}) = "
                              f"{B[j, k]!r}; expected a finite rate")
        if (B < 0).any():
            j, k = np.argwhere(B < 0)[0]
            raise KernelError(f"aggregation kernel {self.name!r}: beta(v={v[j]:.6g}, v={v[k]:.6g}) = "
                              f"{B[j, k]:.6g} < 0; expected a rate >= 0")
        # symmetric to rounding (a user function written as f(u, v) != f(v, u) is a bug)
        asym = np.abs(B - B.T) > 1e-12 * np.maximum(np.abs(B), np.abs(B.T))
        if asym.any():
            j, k = np.argwhere(asym)[0]
            raise KernelError(f"aggregation kernel {self.name!r}: beta(v={v[j]:.6g}, v={v[k]:.6g}) = "
                              f"{B[j, k]:.6g} but beta(v={v[k]:.6g}, v={v[j]:.6g}) = {B[k, j]:.6g}; "
                              "expected a symmetric kernel")
        return 0.5 * (B + B.T)


def constant_kernel(beta0: float) -> Kernel:
    """The constant kernel, beta = beta0 [1/s]."""
    return Kernel("constant", beta0, lambda u, v: np.ones(np.broadcast(u, v).shape))


def sum_kernel(beta0: float) -> Kernel:
    """Golovin's sum kernel beta = beta0 (u + v)."""
    return Kernel("sum", beta0, lambda u, v: u + v)


def product_kernel(beta0: float) -> Kernel:
    """The product kernel, beta = beta0 u v."""
    return Kernel("product", beta0, lambda u, v: u * v)


def shear_kernel(beta0: float) -> Kernel:
    """Orthokinetic (shear) kernel beta = beta0 (u^(1/3) + v^(1/3))^3."""
    return Kernel("shear", beta0, lambda u, v: (np.cbrt(u) + np.cbrt(v)) ** 3)


def user_kernel(func: Callable, beta0: float = 1.0, name: str = "user") -> Kernel:
    """A user function f(u, v) of two volumes (in v_ref units), vectorised; beta = beta0 f."""
    if not callable(func):
        raise KernelError(f"aggregation kernel {name!r}: expected a callable f(u, v), got {type(func).__name__}")
    return Kernel(name, beta0, func)


#: Kernels by name (TOML ``kernel = "constant"`` etc.).
KERNELS = {"constant": constant_kernel, "sum": sum_kernel, "product": product_kernel, "shear": shear_kernel}
