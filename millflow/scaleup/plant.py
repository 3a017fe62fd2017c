"""A mill given by dimensions and operation, and the circuit it works in.

:class:`MillDesign` turns dimensions and operation into net power (a model of
:mod:`millflow.scaleup.power`, or a given power) and hold-up; :class:`Circuit` describes
the mill with its transport (any rtd model, tau = H / F set by the mill's flow) and an
optional closing classifier whose coarse stream returns to the mill feed. The circuit is
solved as a flowsheet (:mod:`millflow.scaleup.study`); scale-up holds no solver of its own.

Hold-up (powder or dry solids): H = rho_s (1 - eps) U eps J V  [kg],
V = pi D^2 L / 4 inside liners, J the ball-bed fraction of V, eps = 0.4 the porosity of
the ball bed and of the powder bed, U the fraction of the ball-bed voids filled by
powder (Austin, Klimpel & Luckie 1984, ch. 10 definitions). Wet mills hold slurry
whose volume depends on discharge design: give ``holdup_kg`` directly there.

Closed circuit, steady state: linear in the flows for a fixed mill flow F_m (tau = H / F_m),
so the fresh feed rate that a mill flow carries is F = F_m / sum(m_hat), m_hat the mill
feed per unit fresh feed: one scalar equation in F_m (:mod:`millflow.scaleup.study`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from millflow.errors import InputError
from millflow.scaleup import power as _power
from rtd import names as _rtd_names
from rtd.base import RTDError

__all__ = ["MillDesign", "Circuit", "TRANSPORTS"]

#: transport names: the one table in :mod:`rtd.names` (canonical names, with the short
#: names of ``millflow fit-rtd --model`` as aliases) -> required and optional shape
#: parameters besides tau (kept here as a read-only view for existing callers)
TRANSPORTS = {name: entry.required + entry.optional for name, entry in _rtd_names.TRANSPORTS.items()}


@dataclass(frozen=True)
class MillDesign:
    """A tumbling ball mill by dimensions and operation (SI; ball size in mm as in the
    sources of the power models).

    power_kW / holdup_kg, when given, replace the computed values (measured ones are better).
    """

    diameter_m: float
    length_m: float
    ball_filling: float
    critical_speed_fraction: float
    ball_size_mm: float
    powder_filling: float = 1.0
    solid_density_kg_m3: float = 2700.0
    ball_density_kg_m3: float = 7800.0
    bed_porosity: float = 0.4
    power_model: str = "austin"
    power_kW: float | None = None
    holdup_kg: float | None = None
    drive_efficiency: float | None = None
    name: str = "mill"

    def __post_init__(self):
        w = self.name
        for key in ("diameter_m", "length_m", "ball_size_mm", "solid_density_kg_m3", "ball_density_kg_m3"):
            _power._positive(getattr(self, key), f"{w}.{key}")
        _power.check_operation(self.critical_speed_fraction, self.ball_filling, self.powder_filling, w)
        if not (0 < float(self.bed_porosity) < 1):
            raise InputError(f"{w}.bed_porosity = {float(self.bed_porosity)!r}: expected 0 < eps < 1")
        if self.ball_size_mm * 1e-3 >= self.diameter_m:
            raise InputError(f"{w}.ball_size_mm = {float(self.ball_size_mm)!r}: larger than the mill diameter")
        if self.power_model not in _power.POWER_MODELS:
            raise InputError(f"{w}.power_model = {self.power_model!r}: expected one of {list(_power.POWER_MODELS)}")
        for key in ("power_kW", "holdup_kg"):
            if getattr(self, key) is not None:
                _power._positive(getattr(self, key), f"{w}.{key}")
        if self.drive_efficiency is not None:
            _power.gross_power(1.0, self.drive_efficiency)

    @property
    def volume_m3(self) -> float:
        return math.pi * self.diameter_m ** 2 * self.length_m / 4

    def power(self) -> dict:
        """net_kW (computed by ``power_model`` unless power_kW is given), gross_kW (if a
        drive efficiency is given), kw_per_t_balls, ball_mass_t, model."""
        kw = dict(diameter_m=self.diameter_m, length_m=self.length_m, ball_filling=self.ball_filling,
                  critical_speed_fraction=self.critical_speed_fraction, ball_size_mm=self.ball_size_mm,
                  ball_density_kg_m3=self.ball_density_kg_m3, ball_density_t_m3=self.ball_density_kg_m3 / 1000,
                  bed_porosity=self.bed_porosity)
        out = dict(_power.mill_power(self.power_model, **kw))
        out["model"] = self.power_model
        if self.power_kW is not None:
            out.update(net_kW=float(self.power_kW), kw_per_t_balls=float(self.power_kW) / out["ball_mass_t"],
                       model="given")
        out["gross_kW"] = (None if self.drive_efficiency is None
                           else _power.gross_power(out["net_kW"], self.drive_efficiency))
        return out

    def holdup(self) -> float:
        """Solids hold-up H [kg] (given, or rho_s (1 - eps) U eps J V)."""
        if self.holdup_kg is not None:
            return float(self.holdup_kg)
        eps = float(self.bed_porosity)
        H = self.solid_density_kg_m3 * (1 - eps) * self.powder_filling * eps * self.ball_filling * self.volume_m3
        if H <= 0:
            raise InputError(f"{self.name}: hold-up is 0 (powder_filling = 0); give holdup_kg")
        return H

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def make_transport(name: str, tau: float, params: dict):
    """The rtd model ``name`` (canonical or alias) with mean residence time ``tau`` [s]."""
    return _rtd_names.build(name, float(tau), **params)


@dataclass(frozen=True)
class Circuit:
    """A mill (transport ``transport`` with shape parameters ``transport_params``; tau
    from the hold-up and the mill flow) with an optional closing classifier: ``classifier``
    None (open circuit) or a dict with ``curve`` (a name of :mod:`millflow.classifiers`)
    and its parameters in SI (sizes [m])."""

    mill: MillDesign
    transport: str = "tanks_in_series"
    transport_params: dict = field(default_factory=lambda: {"n": 3})
    classifier: dict | None = None

    def __post_init__(self):
        try:
            name = _rtd_names.canonical_name(self.transport)
        except RTDError as exc:
            raise InputError(f"transport = {self.transport!r}: {exc}") from None
        object.__setattr__(self, "transport", name)
        got = dict(self.transport_params)
        try:
            make_transport(name, 1.0, got)
        except RTDError as exc:  # rtd's own validation names the parameter
            raise InputError(f"transport {name!r} with {got}: {exc}") from None
        if self.classifier is not None and "curve" not in self.classifier:
            raise InputError(f"classifier = {self.classifier!r}: expected a table with 'curve' and its parameters")

    def partition(self, x) -> np.ndarray | None:
        """Fraction of each class to the coarse (recycle) stream, or None (open circuit)."""
        if self.classifier is None:
            return None
        from millflow.classifiers import efficiency
        params = {k: v for k, v in self.classifier.items() if k != "curve"}
        return efficiency(self.classifier["curve"], x, **params)

    # ------------------------------------------------- deprecated solves
    def _study(self, S, b, feed, c):
        """A one-off plant flowsheet of this circuit with S, b and the partition c as given
        (discrete: no grid of sizes needed), for the deprecated solve methods."""
        import warnings

        from millflow.breakage import TabulatedBreakage, TabulatedRate
        from millflow.grid import SizeGrid
        from millflow.scaleup.study import PlantStudy

        warnings.warn("Circuit.at_mill_flow and Circuit.at_throughput are deprecated: a plant study is a flowsheet "
                      "(millflow.scaleup.study.PlantStudy, through ScaleUp)", DeprecationWarning, stacklevel=3)
        S = np.asarray(S, float)
        grid = SizeGrid.geometric(1.0, 2.0, S.size).with_scheme("upper_edge")  # labels only: S, b, c as given
        clf = None
        if c is not None:
            part = np.asarray(c, float)
            clf = {"curve": lambda x, part=part: part}
        import dataclasses

        circ = dataclasses.replace(self, classifier=clf)
        study = PlantStudy(grid, np.asarray(feed, float), circ, self.mill.holdup(), 1.0)
        fs = study.flowsheet(TabulatedRate(np.asarray(S, float)), TabulatedBreakage(b=np.asarray(b, float)))
        return study, fs

    def at_mill_flow(self, S, b, feed, F_m, c=None):
        """Deprecated: the circuit at mill flow F_m [kg/s] (:meth:`millflow.scaleup.study.
        PlantStudy.at_mill_flow` on the plant flowsheet)."""
        study, fs = self._study(S, b, feed, c)
        return study.at_mill_flow(fs, F_m)

    def at_throughput(self, S, b, feed, F, c=None, guess_load=None):
        """Deprecated: the circuit at fresh feed F [kg/s] (:meth:`millflow.scaleup.study.
        PlantStudy.at_throughput` on the plant flowsheet)."""
        study, fs = self._study(S, b, feed, c)
        return study.at_throughput(fs, F)
