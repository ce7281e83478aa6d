"""`lpvest reproduce all`: the FMU cache, the agreement records, the report."""

from __future__ import annotations

import hmac
import json
import pickle
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from lpvest.cli import main
from lpvest.core._errors import LpvestError
from lpvest.experiments import Experiment, ExperimentResult
from lpvest.experiments._fmus import (
    CATALOG,
    Agreement,
    ExperimentFmus,
    FmuRun,
)
from lpvest.experiments._reproduce import reproduce_all
from lpvest.fmi._cache import fingerprint
from tests.tolerances import roundoff

# -- agreement records ------------------------------------------------------------------------------


def test_agreement_is_relative_to_the_scale():
    a = Agreement.of("y", [1.0, 2.0 + 1e-12], [1.0, 2.0])
    assert not a.bit_for_bit and a.ok and a.scale == 2.0
    assert Agreement.of("y", [0.0, 1e-6], [0.0, 0.0]).ok is False  # scale below 1 counts as 1
    assert Agreement.of("y", [100.0 + 5e-11], [100.0]).ok is True  # 5e-11 <= 1e-12 * 100
    assert Agreement.of("y", [100.0 + 2e-10], [100.0]).ok is False
    assert Agreement.of("y", [3.0], [3.0]).line() == "y: max |FMU - library| = 0 (bit for bit)"
    nan = Agreement.of("y", [np.nan], [1.0])
    assert nan.max_abs_difference == float("inf") and not nan.ok
    with pytest.raises(LpvestError, match=r"y: FMU result has shape \(2,\), library result \(3,\)"):
        Agreement.of("y", [1.0, 2.0], [1.0, 2.0, 3.0])


def test_fmu_run_headline():
    good = FmuRun("d", ("A",), (Agreement.of("p", [1.0], [1.0]), Agreement.of("y", [2.0 + 4e-16], [2.0])))
    assert good.ok and not good.bit_for_bit
    assert good.headline() == ("FMU co-simulation vs library: max |difference| = 4.44e-16 "
                               "(within 1e-12 of scale) over 2 quantities")
    bad = FmuRun("d", ("A",), (Agreement.of("y", [2.1], [2.0]),))
    assert not bad.ok and "EXCEEDS" in bad.headline()


# -- the FMU cache ----------------------------------------------------------------------------------


def test_cache_builds_once_then_reuses_and_detects_staleness(tmp_path):
    messages: list[str] = []
    cache = ExperimentFmus(tmp_path, progress=messages.append)
    path = cache["CoxTothEx1Scheduler"]
    assert path == tmp_path / "CoxTothEx1Scheduler.fmu" and cache.built == ["CoxTothEx1Scheduler"]
    assert messages == [f"building CoxTothEx1Scheduler into {tmp_path}"]
    assert cache["CoxTothEx1Scheduler"] == path and cache.built == ["CoxTothEx1Scheduler"]  # once per instance
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["fmus"]["CoxTothEx1Scheduler"]["fingerprint"] == fingerprint(cache.plan("CoxTothEx1Scheduler"))

    again = ExperimentFmus(tmp_path)  # another process, same folder: reused
    again["CoxTothEx1Scheduler"]
    assert again.reused == ["CoxTothEx1Scheduler"] and again.built == []
    assert "reused 1 up-to-date" in again.summary()

    path.write_bytes(path.read_bytes()[:-10])  # a damaged file is rebuilt
    damaged = ExperimentFmus(tmp_path)
    damaged["CoxTothEx1Scheduler"]
    assert damaged.built == ["CoxTothEx1Scheduler"]

    manifest = json.loads((tmp_path / "manifest.json").read_text())
    manifest["fmus"]["CoxTothEx1Scheduler"]["fingerprint"] = "0" * 64  # built from other code
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    stale = ExperimentFmus(tmp_path)
    stale["CoxTothEx1Scheduler"]
    assert stale.built == ["CoxTothEx1Scheduler"]


def test_fingerprint_follows_what_the_fmu_is_made_of(tmp_path):
    from dataclasses import replace

    cache = ExperimentFmus(tmp_path)
    plan = cache.plan("PeixotoEx1HinfPDEps150")
    assert plan.estimator.design == "lpvest.experiments._fmus:hinf_pd_eps150"
    base = fingerprint(plan)
    assert fingerprint(cache.plan("PeixotoEx1HinfPDEps150")) == base
    assert fingerprint(cache.plan("PeixotoEx1HinfPD")) != base  # another design function
    edited = tmp_path / "peixoto_ex1.toml"
    shutil.copy(plan.system_path, edited)
    edited.write_text(edited.read_text().replace("Bw = [[2.0], [0.1]]", "Bw = [[2.0], [0.2]]"))
    assert fingerprint(replace(plan, system_path=edited)) != base  # another model


def test_variant_model_file_for_example2(tmp_path):
    from lpvest import load_system

    plan = ExperimentFmus(tmp_path).plan("PeixotoEx2Rho11HinfPD")
    assert plan.system_path == tmp_path / "models" / "peixoto_ex2_rho11.toml"
    system = load_system(plan.system_path)
    assert system.name == "peixoto-ex2-rho11" and system.parameters == {"rho": 11.0}
    assert plan.model_parameters == ()  # the design is for rho = 11: not an FMU parameter
    assert {"PeixotoEx2Rho11HinfPD", "PeixotoEx2Rho21HinfPD", "PeixotoEx1HinfRobustEps150"} <= set(CATALOG)


def test_a_resolved_cache_serves_its_fmus_only_and_pickles(tmp_path):
    import pickle

    from lpvest.fmi._cache import FmuCacheError

    cache = ExperimentFmus(tmp_path)
    view = pickle.loads(pickle.dumps(cache.resolved(["CoxTothEx1Scheduler"])))  # what a worker gets
    assert cache.built == ["CoxTothEx1Scheduler"]  # built here, before
    assert type(view) is ExperimentFmus and view["CoxTothEx1Scheduler"] == tmp_path / "CoxTothEx1Scheduler.fmu"
    with pytest.raises(FmuCacheError, match=r"CoxTothEx1Plant was not resolved for this process \(resolved: "
                                            r"CoxTothEx1Scheduler\): declare it with the experiment"):
        view["CoxTothEx1Plant"]
    assert not (tmp_path / "CoxTothEx1Plant.fmu").exists()


def test_workers_must_be_a_count(tmp_path, capsys):
    from lpvest.core._errors import ArgumentError
    from lpvest.experiments._reproduce import reproduce

    with pytest.raises(ArgumentError, match=r"workers must be an integer >= 0 \(0: in this process\); found -1"):
        reproduce(["peixoto-fig1"], tmp_path, workers=-1)
    with pytest.raises(SystemExit) as exit_info:  # argparse's usage error: status 2
        main(["reproduce", "all", "--out", str(tmp_path), "--workers", "two"])
    assert exit_info.value.code == 2
    assert "argument --workers: expected 0 (run in this process) or a number of worker processes, found 'two'" in \
        capsys.readouterr().err


def test_unknown_fmu(tmp_path):
    with pytest.raises(LpvestError, match="no experiment FMU 'PeixotoEx3Plant'"):
        ExperimentFmus(tmp_path)["PeixotoEx3Plant"]


# -- the command line -------------------------------------------------------------------------------


def test_disagreement_gives_exit_status_1(monkeypatch, tmp_path, capsys):
    import lpvest.experiments as experiments

    def run(out_dir, *, fmus, progress=None):
        fmu = FmuRun("fake", ("X",), (Agreement.of("y", [1.0], [1.5]),))
        return ExperimentResult("fake", "table", {"n": 1}, (), (), fmu)

    monkeypatch.setattr(experiments, "registry", lambda: {"fake": Experiment("fake", "a fake", run)})
    assert main(["reproduce", "fake", "--out", str(tmp_path), "--fmus", str(tmp_path / "c")]) == 1
    captured = capsys.readouterr()
    assert "EXCEEDS 1e-12" in captured.out
    assert "FMU results disagree with the library in: fake" in captured.err
    assert main(["reproduce", "nothing", "--out", str(tmp_path)]) == 2
    assert "no experiment 'nothing'" in capsys.readouterr().err


def test_quiet_reproduce_asks_its_experiments_for_no_progress_bars(monkeypatch, tmp_path, capsys):
    import lpvest.experiments as experiments

    asked = []

    def run(out_dir, *, fmus, progress=None):
        asked.append(progress)
        return ExperimentResult("fake", "table", {"n": 1}, (), (), None)

    monkeypatch.setattr(experiments, "registry", lambda: {"fake": Experiment("fake", "a fake", run)})
    assert main(["reproduce", "fake", "--out", str(tmp_path / "a"), "--workers", "0", "--quiet"]) == 0
    # another folder: in the same one the rerun would keep the finished experiment, not run it
    assert main(["reproduce", "fake", "--out", str(tmp_path / "b"), "--workers", "0"]) == 0
    assert asked == [False, None]  # None: the experiment's own rule, bars on a terminal only
    assert capsys.readouterr().err == ""


def test_reproduce_runs_the_experiments_named_in_their_order_each_once(monkeypatch, tmp_path, capsys):
    import lpvest.experiments as experiments

    ran = []

    def runner(name):
        def run(out_dir, *, fmus, progress=None):
            ran.append(name)
            return ExperimentResult(name, "table", {"n": 1}, (), (), None)
        return run

    monkeypatch.setattr(experiments, "registry", lambda: {n: Experiment(n, f"fake {n}", runner(n))
                                                          for n in ("a", "b", "c")})
    assert main(["reproduce", "c", "a", "c", "--out", str(tmp_path), "--workers", "0", "--quiet"]) == 0
    assert ran == ["c", "a"]
    assert sorted(p.name for p in tmp_path.iterdir() if (p / "results.json").is_file()) == ["a", "c"]
    assert not (tmp_path / "report.md").exists()  # all only
    assert "2 experiment(s) in " in capsys.readouterr().out


def _without_times(value):
    """results.json or report.md without what depends on the machine's speed and the run's
    folder: timing keys, durations ("18.7 s"), the date, the FMU cache's built/reused counts."""
    if isinstance(value, dict):
        return {k: _without_times(v) for k, v in value.items() if k not in ("compile_time", "solve_time", "wall_time")}
    if isinstance(value, list):
        return [_without_times(v) for v in value]
    if isinstance(value, str):
        value = re.sub(r"\d+(\.\d+)? s\b", "<t> s", value)
        value = re.sub(r"\d{4}-\d{2}-\d{2} \d{2}:\d{2}", "<date>", value)
        value = re.sub(r"wall time <t> s; FMU cache [^;]*;", "<cache>;", value)
        return re.sub(r"--out \S+`", "--out <out>`", value)
    return value


@pytest.mark.slow
def test_reproduce_all_reduced_writes_everything(tmp_path, experiment_fmus, capfd):
    """`lpvest reproduce all --quick`: every experiment, through FMUs, and the report,
    on two Dask workers and in this process: the same numbers, bit for bit, and the
    same report. (The full configuration is measured, not tested: see the README.)"""
    lines: list[str] = []
    serial = reproduce_all(tmp_path / "serial", fmus=experiment_fmus, reduced=True, workers=0)
    capfd.readouterr()
    runs = reproduce_all(tmp_path, fmus=experiment_fmus, reduced=True, echo=lines.append, workers=2)
    for a, b in zip(serial, runs, strict=True):
        assert _without_times(json.loads(a.results_path.read_text())) == \
            _without_times(json.loads(b.results_path.read_text())), a.name
    assert _without_times((tmp_path / "serial" / "report.md").read_text()) == \
        _without_times((tmp_path / "report.md").read_text())
    # progress: one line per finished task (4 experiments, one task for the three Sridhar
    # experiments, Example 2's stability limits, FMU co-simulation and 3 values of rho),
    # nothing from the workers' progress bars
    done = [line for line in lines if re.match(r"\[[ \d]\d/10\] ", line)]
    assert [line[:7] for line in done] == [f"[{i:>2}/10]" for i in range(1, 11)]
    assert sum("] peixoto-example2: rho = " in line for line in done) == 3
    assert sum("] peixoto-example2: stability limits (" in line for line in done) == 1
    assert sum("] peixoto-example2: FMU co-simulation (" in line for line in done) == 1
    assert sum("] sridhar-noiseless + sridhar-noisy + sridhar-sliding (" in line for line in done) == 1
    out, err = capfd.readouterr()
    assert "\r" not in out + err + "".join(lines)
    names = [r.name for r in runs]
    assert names == ["cox-toth-example1", "cox-toth-truncation", "peixoto-table1", "peixoto-fig1",
                     "peixoto-example2", "sridhar-noiseless", "sridhar-noisy", "sridhar-sliding"]
    for r in runs:
        assert r.ok and r.result.fmu is not None and r.result.paper, r.name
        data = json.loads(r.results_path.read_text())
        assert data["fmu_cosimulation"]["ok"]
        # FMU against library: the same stable recursions (the FMUs carry
        # lpvest), at most rounded in another order: per step sums of <= 6
        # products of the quantity's size, over 200 steps (the Cox-Toth
        # filters, the only quantities that are not bit for bit)
        for a in data["fmu_cosimulation"]["agreements"]:
            assert a["max_abs_difference"] <= roundoff(max(1.0, a["scale"]), 200, n=6), (r.name, a["what"])
        assert all(f.is_file() for f in r.result.figures) and r.result.figures, r.name
    assert runs[4].options == {"rhos": (1.0, 11.0, 21.0)}
    report = (tmp_path / "report.md").read_text()
    assert lines[-1] == f"wrote {tmp_path / 'report.md'}"
    # the summary table: one row per experiment with its FMU agreement
    rows = [line for line in report.splitlines() if re.match(r"\| \[[a-z0-9-]+\]\(#", line)]
    assert [re.match(r"\| \[([a-z0-9-]+)\]", row).group(1) for row in rows] == names
    assert all("bit for bit" in row or "e-1" in row for row in rows)
    # the paper-versus-ours tables carry the papers' numbers
    for text in ("| Theorem 1 (PD), epsilon = 150: gamma | 1.21 | 1.2138 |", "| 8.18 |", "| 0.9617 |", "| 21.4 |",
                 "0.8321 (one realization)", "machine precision"):
        assert text in report, text
    # every figure is linked with a path relative to the report, and exists
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report)
    assert len(links) == sum(len(r.result.figures) for r in runs) >= 14
    assert all((tmp_path / link).is_file() for link in links)
    assert report.count("**Through FMUs.**") == 8 and "reduced configuration" in report


class _Plant:
    """A pickle that creates a file when it is loaded."""

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_a_rerun_keeps_a_finished_experiment_unless_its_results_or_options_changed(monkeypatch, tmp_path):
    """What resumes an interrupted reproduce: the resume record next to results.json."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))  # the key that signs the records
    import lpvest.experiments as experiments
    from lpvest.experiments._reproduce import reproduce

    calls = []

    def run(out_dir, *, fmus, progress=None, runs=10):
        calls.append(runs)
        return ExperimentResult("fake", f"table {runs}", {"runs": runs}, (), (), None)

    fake = Experiment("fake", "a fake", run, reduced={"runs": 2})
    monkeypatch.setattr(experiments, "registry", lambda: {"fake": fake})
    cache = tmp_path / "c"
    (first,) = reproduce(["fake"], tmp_path, fmus=cache, workers=0)
    lines: list[str] = []
    (again,) = reproduce(["fake"], tmp_path, fmus=cache, workers=0, echo=lines.append)
    assert calls == [10]  # kept, not run
    assert lines == [f"fake: finished earlier, kept ({tmp_path / 'fake' / 'results.json'})"]
    assert (again.result, again.seconds, again.options) == (first.result, first.seconds, first.options)
    reproduce(["fake"], tmp_path, fmus=cache, workers=0, reduced=True)  # other options: run
    assert calls == [10, 2]
    results = tmp_path / "fake" / "results.json"
    results.write_text(results.read_text().replace("2", "3"))  # not the file it wrote: run
    reproduce(["fake"], tmp_path, fmus=cache, workers=0, reduced=True)
    assert calls == [10, 2, 2] and json.loads(results.read_text()) == {"runs": 2}
    (tmp_path / "fake" / ".resume.pickle").write_bytes(b"garbage")  # a damaged record: run
    reproduce(["fake"], tmp_path, fmus=cache, workers=0, reduced=True)
    assert calls == [10, 2, 2, 2]
    # a record signed with another key (someone else's folder) is never unpickled: a pickle
    # runs code when loaded; the experiment runs again instead
    record = tmp_path / "fake" / ".resume.pickle"
    signed = record.read_bytes()
    assert oct((tmp_path / "xdg" / "lpvest" / "resume.key").stat().st_mode & 0o777) == "0o600"
    planted = tmp_path / "planted"
    payload = pickle.dumps(_Plant(str(planted)))
    record.write_bytes(hmac.new(b"k" * 32, payload, "sha256").digest() + payload)
    reproduce(["fake"], tmp_path, fmus=cache, workers=0, reduced=True)
    assert calls == [10, 2, 2, 2, 2] and not planted.exists()
    assert len(record.read_bytes()) == len(signed)  # rewritten, signed with this user's key
    reproduce(["fake"], tmp_path, fmus=cache, workers=0, reduced=True)
    assert calls == [10, 2, 2, 2, 2]  # kept again


def test_a_rerun_keeps_a_finished_experiment_whose_folder_was_moved_or_is_named_another_way(monkeypatch,
                                                                                              tmp_path):
    """The resume record names the folder as the first command had it (``--out`` relative, say);
    a rerun that names it otherwise (absolute), or after the folder was moved, keeps the
    experiment, its paths now in the folder named; a figure missing there still runs it again."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    import lpvest.experiments as experiments
    from lpvest.experiments._reproduce import reproduce

    calls = []

    def run(out_dir, *, fmus, progress=None):
        calls.append(out_dir)
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        figure = Path(out_dir) / "fig.png"
        figure.write_bytes(b"png")
        return ExperimentResult("fake", "table", {"runs": 1}, (figure,), (), None)

    monkeypatch.setattr(experiments, "registry", lambda: {"fake": Experiment("fake", "a fake", run)})
    monkeypatch.chdir(tmp_path)
    cache = tmp_path / "c"
    (first,) = reproduce(["fake"], "out", fmus=cache, workers=0)
    assert first.results_path == Path("out/fake/results.json") and len(calls) == 1
    lines: list[str] = []
    (again,) = reproduce(["fake"], tmp_path / "out", fmus=cache, workers=0, echo=lines.append)
    assert len(calls) == 1, "the same folder, named absolutely: kept"
    assert lines == [f"fake: finished earlier, kept ({tmp_path / 'out' / 'fake' / 'results.json'})"]
    assert again.folder == tmp_path / "out" / "fake"
    assert again.result.figures == (tmp_path / "out" / "fake" / "fig.png",)
    (tmp_path / "out").rename(tmp_path / "moved")
    (moved,) = reproduce(["fake"], tmp_path / "moved", fmus=cache, workers=0)
    assert len(calls) == 1, "a moved folder: kept"
    assert moved.results_path == tmp_path / "moved" / "fake" / "results.json"
    assert moved.result.figures == (tmp_path / "moved" / "fake" / "fig.png",)
    assert (moved.result.results, moved.seconds) == (first.result.results, first.seconds)
    (tmp_path / "moved" / "fake" / "fig.png").unlink()  # not what it wrote any more: run again
    reproduce(["fake"], tmp_path / "moved", fmus=cache, workers=0)
    assert len(calls) == 2 and (tmp_path / "moved" / "fake" / "fig.png").is_file()
