"""Make survey.toml: a synthetic survey of circuit.toml (the truth, sampled with the stated errors).

The survey a plant metallurgist would take: the fresh feed weightometer, % solids and a
root-2 sieve analysis of every stream, the sump's water flowmeter. One sample holds a
gross error (the underflow's % solids written 8 points low), as real surveys do.
Run from this folder: ``python make_survey.py`` (seeded: the same file every time).
"""
from pathlib import Path

import numpy as np

from millflow.flowsheet import load, solve
from millflow.survey.reader import ErrorModel, class_fractions
from millflow.survey.synthetic import grid_sieves, synthetic_survey

HERE = Path(__file__).resolve().parent
ERRORS = ErrorModel(solids_rel=0.02, water_rel=0.05, solids_content_sd=0.01, psd_sd=0.01, psd_floor=0.001)


def main():
    sol = solve(load(HERE / "circuit.toml"))
    sieves = grid_sieves(sol.flowsheet.grid, 2, bottom=40e-6)[1:]  # 5657 um down to 44 um
    survey, _ = synthetic_survey(sol, sieves, np.random.default_rng(2024), errors=ERRORS, additions=["sump"])
    lines = ['# A survey of circuit.toml: made by make_survey.py (synthetic, seeded); edit freely.',
             'title = "Closed-circuit ball mill survey"', 'flowsheet = "circuit.toml"', "",
             "[errors]            # the error model, stated once",
             f"solids_rel_sd_pct = {100 * ERRORS.solids_rel:g}      # relative SD of solids flows",
             f"water_rel_sd_pct = {100 * ERRORS.water_rel:g}       # relative SD of water flows",
             f"solids_content_sd_pct = {100 * ERRORS.solids_content_sd:g}  # absolute SD of % solids",
             f"psd_sd_pct = {100 * ERRORS.psd_sd:g}             # SD of a class's mass % at 50 %, as 2 sqrt(p(1-p))",
             f"psd_floor_pct = {100 * ERRORS.psd_floor:g}         # plus this floor", ""]
    sizes = ", ".join(f"{x * 1e6:.0f}" for x in sieves)
    for name, m in survey.streams.items():
        lines.append(f"[streams.{name}]")
        if m.solids is not None:
            lines.append(f"solids_tph = {m.solids * 3.6:.1f}")
        if m.solids_content is not None:
            c = 100 * m.solids_content - (8.0 if name == "underflow" else 0.0)  # the planted gross error
            lines.append(f"solids_content_pct = {c:.1f}")
        lines.append("")
        if m.psd is not None:
            # a sieve never holds negative mass: the noise of nearly empty classes is cut at 0 and
            # the analysis normalised to its total, as a laboratory reports it
            f = np.maximum(class_fractions(m.psd.passing), 0.0)
            passing = 1.0 - np.cumsum(f / f.sum())[:-1]
            lines += [f"[streams.{name}.psd]", f"size_um = [{sizes}]",
                      f"passing_pct = [{', '.join(f'{100 * max(p, 0.0):.2f}' for p in passing)}]", ""]
    for unit, (v, _) in survey.water_additions.items():
        if v is not None:
            lines += [f"[water_additions.{unit}]", f"water_tph = {v * 3.6:.1f}", ""]
    lines += ["[fit]               # circuit parameters fitted to the reconciled survey (flowsheet keys)",
              "starts = 2", "", "[fit.parameters]",
              '"materials.ore.rate.A_E_t_per_kWh" = {min = 0.3, max = 2.0}',
              '"materials.ore.rate.alpha" = {min = 0.3, max = 2.0}',
              '"units.cyclones.d50c_um" = {min = 80, max = 300}',
              '"units.cyclones.alpha" = {min = 1.0, max = 6.0}',
              '"units.cyclones.bypass" = {min = 0.05, max = 0.6}',
              '"units.cyclones.water_to_coarse" = {min = 0.05, max = 0.6}', ""]
    (HERE / "survey.toml").write_text("\n".join(lines), encoding="utf-8")


if __name__ == "__main__":
    main()
