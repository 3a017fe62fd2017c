"""Breakage per unit of specific energy (Herbst and Fuerstenau): S_i = S_i^E P / H.

A specific rate measured in one mill, S_i [1/s], depends on how hard that mill works. Herbst
and Fuerstenau (1980, Int. J. Miner. Process. 7, 1-31, doi:10.1016/0301-7516(80)90034-4) found
it proportional to the net power drawn per unit mass of charge held: S_i = S_i^E P / H, with P
the mill power [W], H the solids hold-up [kg] and S_i^E [kg/J] a property of the material
alone (the energy-specific rate, usually quoted in t/kWh). In a continuous mill of mean
residence time tau = H / F (F the solids flow through the mill), S_i tau = S_i^E P / F = S_i^E
E: the product depends on the specific energy E = P / F [J/kg] and the shape of the residence
time distribution only, not on power, hold-up or feed rate separately.
:class:`EnergySpecificRate` carries S^E; a mill turns it into a time rate with its own power
and hold-up (:func:`time_rates`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, ClassVar

import numpy as np

from millflow.errors import InputError

__all__ = ["EnergySpecificRate", "time_rates", "from_lab"]

#: 1 t/kWh in SI [kg/J].
T_PER_KWH = 1000.0 / 3.6e6


@dataclass(frozen=True)
class EnergySpecificRate:
    """S_i^E(x) [kg/J]: breakage rate per unit of specific energy.

    Parameters
    ----------
    specific : callable
        x [m] -> S^E [kg/J] (any rate model, e.g. :class:`millflow.breakage.PowerLawRate`
        whose A is given in kg/J instead of 1/s).
    source : str
        Where S^E came from (shown in results).
    """

    specific: Callable
    source: str = "given per energy"
    basis: ClassVar[str] = "energy"

    def __call__(self, x) -> np.ndarray:
        return np.asarray(self.specific(np.asarray(x, float)), float)

    def time_rates(self, x, power: float, holdup: float) -> np.ndarray:
        """S_i [1/s] = S_i^E P / H in a mill drawing ``power`` [W] with solids hold-up ``holdup`` [kg]."""
        return time_rates(self(x), power, holdup)


def time_rates(s_energy, power: float, holdup: float) -> np.ndarray:
    """S_i = S_i^E P / H [1/s] from S^E [kg/J], net power P [W] and solids hold-up H [kg].

    >>> float(time_rates([1 / 3600.0], 3.6e6, 1000.0)[0])   # 1 t/kWh at 3600 kW per t held
    1.0
    """
    if not (np.isfinite(power) and power > 0):
        raise InputError(f"power = {power!r} W: a mill whose rates are per energy needs a power > 0")
    if not (np.isfinite(holdup) and holdup > 0):
        raise InputError(f"hold-up = {holdup!r} kg: a mill whose rates are per energy needs a hold-up > 0")
    return np.asarray(s_energy, float) * (float(power) / float(holdup))


@dataclass(frozen=True)
class _Scaled:
    rate: Callable
    factor: float

    def __call__(self, x):
        return self.factor * np.asarray(self.rate(x), float)


def from_lab(rate: Callable, power: float, holdup: float) -> EnergySpecificRate:
    """S^E = S_lab H_lab / P_lab: a time rate fitted in a lab mill (power [W], hold-up [kg]) carried per energy."""
    if not (power > 0 and holdup > 0):
        raise InputError(f"lab power {power!r} W and hold-up {holdup!r} kg: expected both > 0")
    return EnergySpecificRate(_Scaled(rate, float(holdup) / float(power)),
                              source=f"lab rate x H/P (P = {power / 1e3:.6g} kW, H = {holdup:.6g} kg)")
