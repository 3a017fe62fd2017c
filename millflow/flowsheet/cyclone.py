"""A hydrocyclone cluster predicted from its geometry and its feed (:mod:`millflow.cyclones`).

Unlike the fixed-curve :class:`~millflow.flowsheet.units.Classifier`, its cut size,
sharpness and water split depend on the slurry it receives: the volumetric flow per
cyclone Q/n (n cyclones in the cluster) and the solids volume fraction phi =
(S/rho_s)/Q. The solver therefore tears it like a hold-up mill, on its solids and water
throughput, and, for Plitt's model, on C = sum_i w_i c_corr,i (the corrected recovery of
its feed PSD w), from which the water split R_f follows in closed form
(:func:`millflow.cyclones.plitt_water_split`). The actual curve is
c = R_f + (1 - R_f) c_corr: the water split is the bypass (fines follow the water).
Its unit report gives d50c, sharpness, pressure drop, flow per cyclone, volume split and
R_f; the water balance takes R_f from it (:mod:`millflow.flowsheet.water`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from millflow.breakage.averaged import curve_on_grid
from millflow.classifiers import plitt, whiten
from millflow.errors import InputError, SolverError

__all__ = ["PredictedCyclone", "CYCLONE_MODELS", "report_operation"]

#: Cyclone models by the name used in flowsheet files.
CYCLONE_MODELS = ("plitt", "nageswararao")
#: Each model's corrected partition curve c_corr(x, d50c, sharpness).
_CORRECTED = {"plitt": plitt, "nageswararao": whiten}


@dataclass(frozen=True)
class PredictedCyclone:
    """Hydrocyclone cluster by model (``plitt`` or ``nageswararao``), geometry and count.

    Parameters
    ----------
    geometry : :class:`millflow.cyclones.CycloneGeometry` (one cyclone, SI).
    cyclones : number of cyclones in the cluster (the flow divides equally).
    slurry : :class:`~millflow.flowsheet.water.Slurry` (densities).
    calibration : PlittCalibration or NageswararaoConstants.
    viscosity : liquid viscosity [Pa s].
    """

    name: str
    model: str
    geometry: object
    cyclones: int
    slurry: object
    calibration: object = None
    viscosity: float = 1.0e-3
    kind: str = field(default="hydrocyclone", init=False)
    type: ClassVar[str] = "classifier"
    max_inlets: ClassVar[int | None] = None

    def __post_init__(self):
        if self.model not in CYCLONE_MODELS:
            raise InputError(f"units.{self.name}.model = {self.model!r}: expected one of {', '.join(CYCLONE_MODELS)}")
        if self.slurry is None:
            raise InputError(f"units.{self.name}: a hydrocyclone predicted by {self.model} needs the solids density; "
                             "add [slurry] solids_density_t_m3 = ...")

    @property
    def ports(self) -> tuple[str, ...]:
        return ("underflow", "overflow")

    @property
    def curve(self) -> str:
        return self.model

    nonlinear: ClassVar[bool] = True
    needs_water: ClassVar[bool] = True

    @property
    def needs_recovery(self) -> bool:
        """Plitt's water split needs C, the corrected recovery of the feed PSD (torn)."""
        return self.model == "plitt"

    def feed(self, solids: float, water: float):
        from millflow.cyclones import CycloneFeed

        if not (solids > 0 and water > 0):
            raise SolverError(f"units.{self.name}: receives {solids * 3.6:.6g} t/h of solids and {water * 3.6:.6g} "
                              f"t/h of water; a hydrocyclone predicted by {self.model} needs both (add water "
                              "upstream, e.g. add_water_tph at the sump)")
        Q = self.slurry.volume_flow(solids, water)
        phi = solids / self.slurry.solids_density / Q
        return CycloneFeed(phi, self.slurry.solids_density, self.slurry.water_density, self.viscosity), Q

    def predict(self, solids: float, water: float, recovery: float | None = None):
        """(CyclonePrediction-like dict, corrected curve function) at the given feed [kg/s]."""
        from millflow import cyclones as cy

        feed, Q = self.feed(solids, water)
        q = Q / self.cyclones
        where = f"units.{self.name}"
        try:
            if self.model == "plitt":
                pred = cy.plitt_cyclone(self.geometry, feed, flow_m3_s=q,
                                        calibration=self.calibration or cy.PlittCalibration(),
                                        corrected_recovery=0.5 if recovery is None else float(recovery))
            else:
                pred = cy.nageswararao_cyclone(self.geometry, feed, flow_m3_s=q,
                                               constants=self.calibration or cy.NageswararaoConstants())
        except (InputError, OverflowError, ZeroDivisionError, ValueError) as exc:
            why = str(exc) if isinstance(exc, InputError) else "the model's power laws overflow at this operating point"
            raise SolverError(f"{where}: at {Q * 3600:.6g} m3/h of slurry ({100 * feed.solids_volume_fraction:.3g} % "
                              f"solids by volume, {self.cyclones} cyclones): {why}") from None
        d50c, m = pred.d50c_m, pred.sharpness
        return {"d50c_m": d50c, "sharpness": m, "pressure_Pa": pred.pressure_Pa, "flow_per_cyclone_m3_s": q,
                "volume_split": pred.volume_split, "water_split": pred.water_split,
                "solids_volume_fraction": feed.solids_volume_fraction}, \
            lambda x: _CORRECTED[self.model](x, d50c, m)

    def blocks(self, grid, throughput=None, water=None, recovery=None):
        t0 = time.perf_counter()
        if throughput is None or water is None:
            raise SolverError(f"units.{self.name}: a predicted hydrocyclone needs its feed flows (torn by the solver)")
        pred, corrected = self.predict(float(throughput), float(water), recovery)
        rf = pred["water_split"]
        c = rf + (1.0 - rf) * curve_on_grid(corrected, grid)
        info = {"method": f"{self.model} model ({self.cyclones} cyclones): d50c {pred['d50c_m'] * 1e6:.4g} um, "
                          f"pressure {pred['pressure_Pa'] / 1e3:.4g} kPa, R_f {rf:.4g}",
                "error_estimate": 0.0, "runtime_s": time.perf_counter() - t0, **pred}
        return {"underflow": c, "overflow": 1.0 - c}, info

    def corrected_recovery(self, grid, inflow, info) -> float:
        """C = sum_i w_i c_corr,i of the inlet PSD w under the curve in ``info``."""
        total = float(np.sum(inflow))
        if not total > 0:
            return 0.5
        cc = curve_on_grid(lambda x: _CORRECTED[self.model](x, info["d50c_m"], info["sharpness"]), grid)
        return float(np.dot(np.asarray(inflow, float) / total, cc))


def report_operation(fs, flows, water, reports) -> None:
    """Per hydrocyclone unit, its operation as numbers in its report, and a warning per quantity
    outside its model's range of use (:func:`millflow.cyclones.out_of_range`), once per solve.

    Adds to ``reports[unit]``: ``cyclones`` (count), ``d50c_m``, ``pressure_Pa`` and
    ``flow_per_cyclone_m3_s`` (predicted cyclones; a fixed curve gives only its d50c), and in a
    wet circuit ``underflow_solids_content`` (mass fraction) and, with densities,
    ``underflow_solids_volume_fraction``; ``out_of_range`` lists the phrases warned, each with
    the basis of the bound (the model's data base, the roping onset, or a judgment:
    :data:`millflow.cyclones.VALIDITY`).
    """
    import warnings

    from millflow.cyclones import VALIDITY, describe_out_of_range, illustrative_constants, out_of_range
    from millflow.errors import ModelRangeWarning

    names = fs.stream_names
    for uname, unit in fs.units.items():
        if getattr(unit, "kind", None) != "hydrocyclone":
            continue
        rep = reports[uname]
        if not isinstance(unit, PredictedCyclone) and "d50c" in getattr(unit, "params", {}):
            rep["d50c_m"] = float(unit.params["d50c"])
        under = next((n for n in fs.outlets(uname) if fs.streams[n].port == "underflow"), None)
        if under is not None and water is not None and float(np.sum(water.flows)) > 0:
            s = float(np.sum(flows[names.index(under)]))
            w = float(water.flows[names.index(under)])
            if s + w > 0:
                rep["underflow_solids_content"] = s / (s + w)
            if fs.slurry is not None and s + w > 0:
                vs = s / fs.slurry.solids_density
                rep["underflow_solids_volume_fraction"] = vs / (vs + w / fs.slurry.water_density)
        if not isinstance(unit, PredictedCyclone):
            continue
        rep["cyclones"] = unit.cyclones
        found = out_of_range(unit.model, unit.geometry, pressure_Pa=rep["pressure_Pa"],
                             feed_solids_volume_fraction=rep["solids_volume_fraction"],
                             underflow_solids_volume_fraction=rep.get("underflow_solids_volume_fraction"))
        rng = VALIDITY[unit.model]
        said = [f"units.{uname}: {phrase} (range of use of {unit.model}'s model, "
                f"{rng.source(q).split(':')[0].split(' (')[0]}; {unit.cyclones} cyclones)"
                for phrase, (q, _, _) in zip(describe_out_of_range(found), found)]
        if illustrative_constants(unit.model, unit.calibration):
            said.append(f"units.{uname}: Nageswararao's model runs on its default constants (K_D0, K_Q0, K_V1, "
                        "K_W1), which are illustrative magnitudes, not fitted values; give the plant's own "
                        "(K_D0 = ..., K_Q0 = ... in the unit table) before trusting d50c, flow or splits")
        rep["out_of_range"] = said
        for msg in said:
            warnings.warn(msg, ModelRangeWarning, stacklevel=3)
