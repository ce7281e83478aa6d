"""The Sridhar et al. experiments (Section V), headless and on the command line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lpvest.cli import main
from lpvest.experiments import registry
from lpvest.experiments._sridhar import (
    PAPER_A1_NOISELESS,
    PAPER_A1_NOISY,
    noisy_output,
    run_noiseless,
    run_noisy,
    run_sliding,
)
from tests.tolerances import roundoff


def test_registered():
    names = set(registry())
    assert {"sridhar-noiseless", "sridhar-noisy", "sridhar-sliding"} <= names


def test_paper_numbers_are_the_printed_ones():
    assert PAPER_A1_NOISELESS == 0.9617  # paper Section V-A
    assert PAPER_A1_NOISY == 0.8321  # paper Section V-B


def test_noise_has_the_stated_snr(rng):
    y = np.sin(np.linspace(0, 30, 200_000))
    noisy, sigma = noisy_output(y, 30.0, rng)
    # 30 dB: power ratio 1000; the same mean of y.size squares, summed in any
    # order (gamma_n relative to the sum of the positive terms), then sqrt
    assert sigma == pytest.approx(np.sqrt(np.mean(y**2) / 1000.0), rel=roundoff(1.0, 2, n=y.size))
    snr = 10 * np.log10(np.mean(y**2) / np.mean((noisy - y) ** 2))
    assert snr == pytest.approx(30.0, abs=0.05)  # 200k samples: sample variance within ~0.3 %


def _plant_checks(fmu):
    # the plant FMU and the streaming LTVPlant do the same operations: bit for bit
    names = [a.what for a in fmu.agreements]
    assert names[:3] == [f"{q} (SridharLtvPlant FMU vs streaming LTVPlant)" for q in ("y", "x", "u applied")]
    assert fmu.ok and fmu.bit_for_bit
    assert fmu.fmus == ("SridharLtvPlant", "SridharLtvBSplineObserver") and fmu.steps == 20000


def test_noiseless_headless(experiment_fmus):
    res = run_noiseless(None, fmus=experiment_fmus)
    r = res.results
    assert res.figures == ()
    # paper Section V-A prints a1 = 0.9617; exact data determine a1 = 1 (issue 5: within 1e-6)
    assert abs(r["a1"] - 1.0) < 1e-6
    assert r["paper_a1"] == PAPER_A1_NOISELESS
    assert r["a0_max_rel_error"] <= 1e-6
    assert r["y_max_error"] < 1e-10
    assert r["dy_max_error"] < 1e-9
    assert r["samples"] == 20001 and r["n_basis"] == 86 and r["inner_window"] == [5.0, 15.0]
    assert "0.9617" in res.table
    _plant_checks(res.fmu)
    # one batch integration instead of the FMU's per-step restarts: the data
    # differ by the integrator's local errors (DOP853, rtol 1e-12: ~1e-12 of
    # scale), the fit amplifies them by its condition number; a method bound
    # (measured ~1e-11), not rounding, which moves a1 by ~eps cond ~ 4e-12
    assert r["a1_difference_fmu_vs_batch"] < 1e-9


def test_noisy_headless(experiment_fmus):
    res = run_noisy(None, fmus=experiment_fmus)
    r = res.results
    # paper Section V-B prints a1 = 0.8321 (one realization); issue 5: over
    # 20 seeds the mean is within 0.02 of 1 and the mean max relative error of
    # a0 on [1.5, 7.5] at most 0.06
    assert r["seeds"] == 20 and len(r["per_seed"]) == 20
    assert abs(r["a1"] - 1.0) < 0.02
    assert r["a1_std"] < 0.02
    assert r["a0_max_rel_error"] <= 0.06
    assert r["y_max_error"] < 2e-4  # noise sigma ~5e-4: y_E filters it
    assert r["dy_max_error"] < 2e-3
    assert r["gcv"]["a0_max_rel_error"] <= 0.06 and abs(r["gcv"]["a1"] - 1.0) < 0.02
    assert r["snr_db"] == 30.0 and r["window"] == [0.0, 9.0] and r["n_basis"] == 16
    assert "0.8321" in res.table
    _plant_checks(res.fmu)
    assert r["samples"] == 9001  # the plant FMU's first 9 s
    assert r["a1_difference_fmu_vs_batch"] < 1e-9  # method bound, as in the noiseless case


def test_sliding_headless(experiment_fmus):
    res = run_sliding(None, fmus=experiment_fmus)
    r = res.results
    # the observer FMU against BSplineObserver on the streaming plant's samples
    _plant_checks(res.fmu)
    assert len(res.fmu.agreements) == 3 + 7
    assert r["delay_s"] == 2.0 and r["first_valid_time"] == 4.0
    assert r["t_est_error"] < roundoff(10.0, 2)  # t_k - delay against t_j: two roundings of times <= 10 s
    assert r["a1_max_error"] < 1e-6
    assert r["a0_max_rel_error"] < 1e-6
    # method bounds (quadrature and fit conditioning, as in tests/test_bspline.py)
    assert r["y_max_error"] < 1e-10 and r["dy_max_error"] < 1e-9


def test_cli_writes_results_and_figures(tmp_path, capsys, experiment_fmus):
    assert main(["reproduce", "sridhar-noiseless", "--out", str(tmp_path),
                 "--fmus", str(experiment_fmus.directory)]) == 0
    out = capsys.readouterr().out
    assert "0.9617" in out
    folder = tmp_path / "sridhar-noiseless"
    data = json.loads((folder / "results.json").read_text())
    assert {"a1", "a0_max_rel_error", "y_max_error", "dy_max_error"} <= set(data)
    for name in ("fig1_a0.png", "fig2_y.png", "fig3_dy.png"):
        assert (folder / name).stat().st_size > 10_000


@pytest.mark.parametrize("run, files", [
    (run_noisy, ("fig4_a0.png", "fig5_y.png", "fig6_dy.png")),
    (run_sliding, ("sliding.png",)),
])
def test_figures(run, files, tmp_path, experiment_fmus):
    res = run(tmp_path, fmus=experiment_fmus)
    assert sorted(p.name for p in res.figures) == sorted(files)
    for name in files:
        assert (tmp_path / name).stat().st_size > 10_000
