"""The shipped closed circuit (flowsheets/closed_circuit_ball_mill.toml) in its per-time form.

The example file drives its mill by energy and hold-up (rates per energy, S = S^E P / H, tau =
H / F). Many tests edit the linear form instead: rates per time (A = 0.9 1/min) and a fixed
tau = 3.5 min, which gives the same circuit at the example's feed rate (S tau = S^E P / F there).
"""
from tests import paths

FILE = paths.FLOWSHEETS / "closed_circuit_ball_mill.toml"

#: (text in the example, text of the per-time form)
_EDITS = (
    ('rate = {form = "power", A_E_t_per_kWh = 0.675, alpha = 1.0, x0_um = 1000}',
     'rate = {form = "power", A_per_min = 0.9, alpha = 1.0, x0_um = 1000}'),
    ("holdup_t = 47.5              # solids hold-up: tau = H / F at the solved mill feed (with the recycle)",
     "tau_min = 3.5"),
    ("power_kW = 3800             # drives the breakage: S = S^E P / H", "power_kW = 3800"),
)


def per_time_text() -> str:
    """The example with per-time rates and tau_min = 3.5 (a linear circuit)."""
    text = FILE.read_text()
    for new, old in _EDITS:
        assert new in text, new
        text = text.replace(new, old)
    return text


def per_time_file(folder):
    """The per-time form written to ``folder`` (a pytest tmp_path); its path."""
    path = folder / "closed_circuit_ball_mill.toml"
    path.write_text(per_time_text())
    return path
