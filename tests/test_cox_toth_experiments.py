"""The Cox & Toth experiments run headless and give the numbers we report."""

import json

import numpy as np
import pytest

from lpvest.cli import main
from lpvest.experiments import registry
from lpvest.experiments.cox_toth import run_example1, run_truncation


def test_registered():
    reg = registry()
    assert "cox-toth-example1" in reg and "cox-toth-truncation" in reg


def test_example1_three_realizations_agree(experiment_fmus):
    res = run_example1(None, fmus=experiment_fmus)
    r = res.results
    # paper: (21a), (21b), (21c) give the same y "to machine precision". max |y| is
    # about 6 here, so 1e-12 allows ~100 ulp of accumulated round-off over 200 steps
    assert 1.0 < r["max_abs_y"] < 100.0
    for key in ("max_diff_21b_21a", "max_diff_21c_21a", "max_diff_21c_21b"):
        assert r[key] < 1e-12, key
    # e is the innovation of (21b) and (21c): inverting them recovers it
    assert r["max_innovation_error_21b"] < 1e-12
    assert r["max_innovation_error_21c"] < 1e-12
    # through FMUs: the Plant FMU realizes (21c); Scheduler, Source and Plant give
    # the library's p, u, y, x bit for bit (the same operations), and its y is
    # (21a)'s and (21b)'s to the same round-off as the library's (21c)
    fmu = res.fmu
    assert fmu.ok and fmu.bit_for_bit and len(fmu.agreements) == 4
    assert fmu.fmus == ("CoxTothEx1Scheduler", "CoxTothEx1Source", "CoxTothEx1Plant")
    assert r["fmu_max_diff_21a"] < 1e-12 and r["fmu_max_diff_21b"] < 1e-12
    assert r["fmu_max_innovation_error_21c"] < 1e-12


@pytest.fixture(scope="module")
def truncation(experiment_fmus):
    return run_truncation(None, fmus=experiment_fmus)


def test_truncation_assumptions_and_bound_8(truncation):
    r = truncation.results
    assert r["assumptions_hold"]
    g, tr = r["assumptions_grid"], r["assumptions_trajectory"]
    assert g["alpha2"] > 0 and g["beta1"] > 0 and g["delta2"] > 0
    assert g["alpha2"] <= tr["alpha2"] and g["beta2"] >= tr["beta2"]  # the grid covers the trajectory
    assert r["min_eig_filtered_covariance"] >= r["bound_8_lower"]


def test_truncation_decay(truncation):
    d = truncation.results["decay"]
    th = d["theorem"]
    # our numbers for this example (deterministic; the margins at the thresholds
    # are a factor 1.4 or more, see the error tables):
    assert th["tau_needed_K_1e-3"] == 11
    assert th["tau_needed_K_1e-6"] == 21
    assert th["max_K_error"][10] > 1e-3 > th["max_K_error"][11]
    assert th["max_K_error"][20] > 1e-6 > th["max_K_error"][21]
    # geometric decay at about 0.55 per step, down to round-off by tau = 60
    assert 0.5 < th["decay_rate_K"] < 0.6
    assert th["max_K_error"][60] < 1e-15
    # monotone: the sup over t for every start; pointwise (Conjecture 1) only for
    # the theorem's start here; the steady-state start violates it (ERRATA)
    for name in d:
        assert d[name]["sup_monotone_K"] and d[name]["sup_monotone_P"], name
    assert th["pointwise_violations_K"] == 0 and th["pointwise_pairs_K"] > 10000
    ss = d["steady-state at p=0"]
    assert ss["pointwise_violations_K"] > 1000
    assert th["min_ordering_eigenvalue"] > -1e-15  # Lemma 2


def test_truncation_prediction_error(truncation):
    v = truncation.results["prediction_error"]
    exact = v["exact"]["mean_trace"]
    order = ["truncated tau=0", "truncated tau=1", "truncated tau=2", "truncated tau=5"]
    vals = [v[n]["mean_trace"] for n in order]
    assert vals == sorted(vals, reverse=True) and vals[-1] >= exact
    assert v["truncated tau=20"]["excess_over_exact"] < 1e-9
    assert 1e-3 < v["truncated tau=0"]["excess_over_exact"] < 0.05
    assert v["frozen K_inf(p_t)"]["excess_over_exact"] > 0
    assert v["constant K_inf(0)"]["excess_over_exact"] > v["frozen K_inf(p_t)"]["excess_over_exact"]
    # Monte Carlo (2000 trajectories, common random numbers) agrees with the exact
    # moments: the relative standard error of each mean is about 0.3 %; 1.5 % is 5 of them
    for name, row in v.items():
        assert abs(row["monte_carlo_relative_difference"]) < 0.015, name
    assert "tau(K<1e-3)" in truncation.table


def test_truncation_through_fmus(truncation):
    fmu = truncation.fmu
    # the plant, the Kalman FMU and six TruncatedKalman FMUs against the library:
    # model.simulate and the streaming filters (other operations: round-off), the
    # gains against the truncation analysis; max |y| ~ 8, so 1e-12 is ~50 ulp
    assert fmu.ok and len(fmu.agreements) == 4 + 3 + 2 * 6
    assert fmu.max_abs_difference < 1e-13
    assert all(a.bit_for_bit for a in fmu.agreements[:2])  # p and u
    # max_t ||K_t - K^(tau)_t|| from the FMUs' gain outputs is the analysis' number
    th = truncation.results["decay"]["theorem"]
    for tau, value in truncation.results["fmu_max_K_error"].items():
        assert value == pytest.approx(th["max_K_error"][int(tau)], rel=1e-9, abs=1e-15), tau


def test_the_plant_fmu_draws_what_simulate_draws(experiment_fmus):
    """The Plant FMU (noise on, seed 3) draws x_0 ~ N(x0, P0) and then the noise,
    as AffineLPV.simulate(rng=3) does: the same seed, the same realization."""
    from lpvest import load_system
    from lpvest.experiments.cox_toth import truncation_cosim
    from lpvest.experiments.fmus import column

    model = load_system("cox-toth-truncation").model()
    assert np.any(model.P0)  # else x_0 would not be drawn
    res = truncation_cosim(30, seed=3, taus=()).run(experiment_fmus)
    k = np.arange(30)
    data = model.simulate(np.sin(0.25 * k)[:, None], np.sin(0.1 * k)[:, None], rng=3)
    np.testing.assert_allclose(column(res, "plant.y"), data.y, rtol=0, atol=1e-13)
    np.testing.assert_array_equal(column(res, "plant.x")[0], data.x[0])
    assert not np.array_equal(data.x[0], model.x0)


def test_cli_writes_results_and_figures(tmp_path, capsys, experiment_fmus):
    assert main(["reproduce", "cox-toth-example1", "--out", str(tmp_path),
                 "--fmus", str(experiment_fmus.directory)]) == 0
    out = capsys.readouterr().out
    assert "max |y(21b) - y(21a)|" in out
    assert "FMU co-simulation vs library: max |difference| = 0 (bit for bit) over 4 quantities" in out
    folder = tmp_path / "cox-toth-example1"
    res = json.loads((folder / "results.json").read_text())
    assert res["max_diff_21b_21a"] < 1e-12
    assert res["fmu_cosimulation"]["ok"] and res["fmu_cosimulation"]["bit_for_bit"]
    assert (folder / "example1.png").stat().st_size > 10000


def test_truncation_figures(tmp_path, experiment_fmus):
    r = run_truncation(tmp_path, runs=50, fmus=experiment_fmus)
    names = sorted(f.name for f in r.figures)
    assert names == ["truncation_decay.png", "truncation_over_time.png"]
    assert all(f.stat().st_size > 10000 for f in r.figures)
    assert np.isfinite(r.results["prediction_error"]["exact"]["mean_trace"])
