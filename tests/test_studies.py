"""The experiments' studies (lpvest/experiments/_studies.py): each held by its experiment, so the
experiments' registry is the studies'; found by name; a sweep file's ``experiment = NAME`` prepared
by the study from the experiments floor; a task's metrics and signals cut to the sweep's selection.
(The studies' numbers through a sweep are checked against the serial experiments in test_sweep.py.)"""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import lpvest.experiments._studies as studies_module
from lpvest._version import __version__
from lpvest.core._errors import InternalError, ModelFileError
from lpvest.experiments import Experiment, ExperimentResult, experiment_studies, registry
from lpvest.experiments._peixoto import example2_task
from lpvest.experiments._studies import SelectedTask, select_task, study
from lpvest.parallel import Prepared, Task, TaskResult
from lpvest.sweep import experiment_studies as sweep_experiment_studies, sweep_spec
from lpvest.sweep._studies import prepare


def test_the_studies_are_those_the_registered_experiments_hold():
    studies = experiment_studies()
    assert studies == {name: exp.study for name, exp in registry().items() if exp.study is not None}
    assert list(studies) == ["cox-toth-truncation", "peixoto-example2", "sridhar-noisy"]  # registry order
    assert [st.name for st in studies.values()] == list(studies)
    assert sweep_experiment_studies is experiment_studies  # lpvest.sweep keeps re-exporting it


def test_an_experiment_holding_a_study_of_another_name_is_an_internal_error(monkeypatch):
    held = experiment_studies()["peixoto-example2"]
    wrong = Experiment("peixoto-fig1", "Figs. 1-2", lambda out_dir: ExperimentResult("peixoto-fig1", "", {}),
                       study=held)
    monkeypatch.setattr(studies_module, "registry", lambda: {"peixoto-fig1": wrong})
    experiment_studies.cache_clear()
    try:
        with pytest.raises(InternalError, match=r"^experiment 'peixoto-fig1' holds the study 'peixoto-example2'$"):
            experiment_studies()
    finally:
        experiment_studies.cache_clear()  # the next call reads the real registry again


def test_an_unknown_study_is_a_model_file_error_naming_the_known_ones():
    with pytest.raises(ModelFileError, match=r"^s\.toml: experiment: no experiment 'peixoto-fig1' to sweep "
                                             r"\(experiments: cox-toth-truncation, peixoto-example2, sridhar-noisy\)$"):
        study("peixoto-fig1", where="s.toml: experiment")


def _task(shared: float, task: Task) -> TaskResult:
    return TaskResult({"a": 1.0, "b": 2.0, "c": shared + task.index}, {"x": np.zeros(2), "y": np.ones(3)})


def test_a_selected_task_returns_the_sweeps_metrics_in_its_order_and_its_kept_signals_only():
    spec = sweep_spec({"experiment": "cox-toth-truncation", "metrics": ["relative_difference", "mean_trace"]})
    selected = select_task(_task, spec, ("a", "b", "c"))
    assert selected == SelectedTask(_task, ("relative_difference", "mean_trace"), ())
    cut = select_task(_task, sweep_spec({"experiment": "sridhar-noisy", "keep": ["y"]}), ("c", "a"))
    assert cut.metrics == ("c", "a")  # no selection: every metric of the study
    r = pickle.loads(pickle.dumps(cut))(2.5, Task(4))  # travels to a Dask worker by reference
    assert list(r.metrics.items()) == [("c", 6.5), ("a", 1.0)]
    assert list(r.signals) == ["y"] and np.array_equal(r.signals["y"], np.ones(3))


def test_a_sweep_of_an_experiment_is_prepared_by_the_experiments_study():
    spec = sweep_spec({"experiment": "peixoto-example2", "parameters": {"rho": [3.0]}, "metrics": ["gamma"]})
    prepared = prepare(spec)
    assert isinstance(prepared, Prepared)
    assert prepared.fn == SelectedTask(example2_task, ("gamma",), ())
    assert (prepared.shared, prepared.metrics, dict(prepared.signals), prepared.time) == (None, ("gamma",), {}, None)
    assert prepared.identity == {"experiment": "peixoto-example2", "lpvest": __version__}
