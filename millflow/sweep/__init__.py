"""Sweeps of a flowsheet over its inputs, on the local cores or a Dask cluster.

A sweep varies keys of a flowsheet file (dotted paths into its TOML tables, e.g.
``units.ball_mill.tau_min``) over a grid (``START:STOP:N`` each, every combination) or
a Latin hypercube (``samples``), solves every case and returns one xarray Dataset:

- grid: one dimension per varied key; Latin hypercube: a ``case`` dimension with the
  keys as coordinates;
- per case: P80 and P50 of every product stream [um], the circulating load of every
  recycle [-], the circuit's specific energy [kWh/t], the mass-balance error and the
  solve time; a case that fails is NaN there with its one-line ``reason`` (never
  dropped, never aborting the sweep).

Cases are solved in chunks (one task per chunk keeps the per-case overhead small) by
``dask.distributed``: a ``LocalCluster`` on this machine, or the scheduler at
``scheduler=ADDRESS``; the scheduler does the placement, retries of lost workers and
progress. ``scheduler="serial"`` solves in this process (no Dask needed).
"""
from millflow.sweep.cases import Axis, grid_cases, latin_hypercube_cases, parse_vary
from millflow.sweep.run import CaseSolver, run_sweep, solve_case

__all__ = ["Axis", "parse_vary", "grid_cases", "latin_hypercube_cases", "run_sweep", "solve_case", "CaseSolver"]
