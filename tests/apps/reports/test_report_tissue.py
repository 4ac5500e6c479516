"""`tensormass report accuracy --benchmark tissue`, quick form: every case within its bound, and the
Prony fit of the LBMC power laws (laws/prony.py) against the thesis' numbers."""
import numpy as np
import pytest

from tensormass.apps.reports.accuracy import run_accuracy
from tensormass.laws import prony


@pytest.mark.heavy           # about 10 s warm: CI's heavy step runs it
def test_tissue_report_quick(tmp_path):
    rows = run_accuracy(tmp_path, benchmarks=["tissue"], quick=True, progress=None)
    by = {r["case"]: r for r in rows}
    mixed = {f"incompressible uniaxial {e}" for e in ("tetra", "tetra10", "hexahedron")} | {
        f"cook tetra mixed nu {nu:g}" for nu in (0.4999, 0.49999, 0.5)} | {"cook tetra displacement nu 0.4999"} | {
        f"organ tetra nu {nu:g}" for nu in (0.4999, 0.49999, 0.5)}
    assert set(by) == {"relaxation", "creep", "hgo along", "hgo across"} | {
        f"lbmc liver rate {r:g}" for r in prony.RATES} | mixed
    assert abs(by["relaxation"]["error_analytic"]) < 0.01 and abs(by["creep"]["error_analytic"]) < 0.01
    for rate in prony.RATES:
        assert abs(by[f"lbmc liver rate {rate:g}"]["error_analytic"]) < 0.01
    assert abs(by["hgo along"]["error_analytic"]) < 0.005 and abs(by["hgo across"]["error_analytic"]) < 0.005
    assert by["relaxation"]["value"] > 1.2          # the force has not relaxed to the elastic one yet at 1 s
    # nu = 0.5: the closed form; Cook and the organ converge tenfold per decade of 0.5 - nu
    for e in ("tetra", "tetra10", "hexahedron"):
        assert abs(by[f"incompressible uniaxial {e}"]["error_analytic"]) < 1e-6
    for body in ("cook tetra mixed", "organ tetra"):
        far, near = (abs(by[f"{body} nu {nu:g}"]["error_analytic"]) for nu in (0.4999, 0.49999))
        assert 8 < far / near < 12 and far < 0.01
    assert by["cook tetra displacement nu 0.4999"]["error_analytic"] < -0.3       # the displacement tetra locks
    assert "## Benchmark `tissue`" in (tmp_path / "report.md").read_text()


@pytest.mark.parametrize("organ", sorted(prony.LBMC))
def test_the_prony_fit_follows_the_power_law(organ):
    """The fit is within 2 % of G(t) over its window, and its constant-rate stress within 0.2 % of the
    power law's at 0.5 to 2 s; liver at 1 s gives the thesis' 13.58 / 119.6 / 603 Pa."""
    K, n = prony.LBMC[organ]
    G_inf, branches = prony.prony_fit(K, n)
    t = np.geomspace(1e-3, 10.0, 300)
    assert np.abs(prony.prony_modulus(t, G_inf, branches) / prony.relaxation_modulus(t, K, n) - 1).max() < 0.02
    times = np.array([0.5, 1.0, 2.0])
    for rate in prony.RATES:
        fit = prony.prony_constant_rate_stress(times, rate, G_inf, branches)
        assert np.abs(fit / prony.constant_rate_stress(times, rate, K, n) - 1).max() < 2e-3
    if organ == "liver":
        at_1s = [float(prony.constant_rate_stress(1.0, r, K, n)) for r in prony.RATES]
        assert at_1s == pytest.approx([13.58, 119.6, 603.0], rel=2e-3)
