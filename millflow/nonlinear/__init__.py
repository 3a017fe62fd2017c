"""Non-linear grinding kinetics (Principle I).

Aggregation by fixed pivots, population-dependent and slowing-down breakage rates, the
batch solve, exact solutions.

- :mod:`.kernels`: aggregation kernels (constant, sum, product, shear, user);
- :mod:`.aggregation`: fixed-pivot aggregation on any size grid, with overflow;
- :mod:`.kinetics`: the right-hand side R(M) and its Jacobian; slowing-down;
- :mod:`.batch`: the batch ODE solve with error estimate;
- :mod:`.exact`: exact solutions for validation (Scott, Golovin, a combined steady state).
"""
from millflow.nonlinear.aggregation import Aggregation, AggregationOperator, pivot_volumes
from millflow.nonlinear.batch import NonlinearBatchResult, batch_nonlinear
from millflow.nonlinear.kernels import (KERNELS, Kernel, KernelError, constant_kernel, product_kernel,
                                        shear_kernel, sum_kernel, user_kernel)
from millflow.nonlinear.kinetics import FinesSlowing, Kinetics, PopulationRate, kinetics, slowing_down, theta_of

__all__ = ["Aggregation", "AggregationOperator", "pivot_volumes", "NonlinearBatchResult", "batch_nonlinear",
           "KERNELS", "Kernel", "KernelError", "constant_kernel", "product_kernel", "shear_kernel", "sum_kernel",
           "user_kernel", "FinesSlowing", "Kinetics", "PopulationRate", "kinetics", "slowing_down", "theta_of"]
