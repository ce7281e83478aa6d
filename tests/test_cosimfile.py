"""`lpvest cosim FILE.toml`: the example files run and give the library's numbers;
every mistake in a file is one line naming the file and the field."""

from __future__ import annotations

import dataclasses
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest

from lpvest import load_system
from lpvest.cli import main
from lpvest.core._errors import ModelFileError
from lpvest.cosim._cosimfile import _path_text, load_cosim
from tests.kalman_helpers import kalman_fmu_tolerance
from tests.test_fmu import paper_w, theta
from tests.tolerances import roundoff

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"


def _design(fmu: Path):
    from lpvest.design import HinfDesign

    with zipfile.ZipFile(fmu) as z:
        return HinfDesign.from_json(z.read("resources/design.json").decode())


def test_peixoto_example_file_runs_from_the_command_line_and_matches_the_library(fmus, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["cosim", str(EXAMPLES / "peixoto_ex1_hinf.toml"), "--fmus", str(fmus.out), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "co-simulated peixoto_ex1_hinf.toml: 4 components, 100 steps of 1 (t = 0 .. 100)" in text
    # the order the master found: the filter's inputs are set after the plant's y is read
    assert "set plant: p[1], w[1]; get plant: y[1], z[1], z[2]; set filter: p[1], y[1]" in text
    csv, png = out / "peixoto_ex1_hinf.csv", out / "peixoto_ex1_hinf.png"
    assert f"wrote {csv}" in text and f"wrote {png}" in text
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    header = csv.read_text().splitlines()[0].split(",")
    assert header == ["time", "sched.p[1]", "sched.alpha[1]", "sched.alpha[2]", "src.w[1]", "plant.y[1]",
                      "plant.z[1]", "plant.z[2]", "filter.zhat[1]", "filter.zhat[2]"]
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    # an independent computation with the library: the paper's signals, the
    # plant's batch simulation, the streaming filter on the FMU's design
    plant = load_system("peixoto-ex1").model()
    k = np.arange(101)
    alpha = plant.alpha_batch(theta(k)[:, None])
    ref = plant.simulate(alpha, paper_w(k)[:, None])
    from lpvest.estimators._hinf import hinf_filter_batch

    zhat = hinf_filter_batch(_design(fmus["PeixotoEx1HinfPD"]), ref.y, alpha).zhat
    np.testing.assert_array_equal(data[:, 0], k)
    # CSV with 17 digits: the round trip is exact. The signals: sin / exp of an
    # argument of size <= 25, one rounding each; plant and filter: the same
    # recursions in another rounding order (sums of <= 4 products per step,
    # 101 steps, no growth assumed)
    np.testing.assert_allclose(data[:, 1], theta(k), rtol=0, atol=roundoff(1.0 + 0.25 * k[-1], 1))
    np.testing.assert_allclose(data[:, 4], paper_w(k), rtol=0, atol=roundoff(1.0 + 0.25 * k[-1], 3))
    n = len(k)
    np.testing.assert_allclose(data[:, 5], ref.y[:, 0], rtol=0, atol=roundoff(np.max(np.abs(ref.y)), n, n=4))
    np.testing.assert_allclose(data[:, 6:8], ref.z, rtol=0, atol=roundoff(np.max(np.abs(ref.z)), n, n=4))
    np.testing.assert_allclose(data[:, 8:10], zhat, rtol=0, atol=roundoff(np.max(np.abs(zhat)), 2 * n, n=4))


@pytest.mark.blas_sensitive
def test_kalman_example_file_matches_the_library_filters_on_the_recorded_data(fmus):
    spec = load_cosim(EXAMPLES / "cox_toth_kalman.toml", fmu_dir=fmus.out)
    assert spec.n_steps == 300 and spec.stop_time == 300.0
    spec = dataclasses.replace(spec, record=(*spec.record, "src.u", "plant.y"))
    res = spec.run()
    d = res.data
    model = load_system("cox-toth-truncation").model()
    p, u = d["sched.p[1]"][:, None], d["src.u[1]"][:, None]
    y = np.column_stack([d["plant.y[1]"], d["plant.y[2]"]])
    # sin of an argument of size <= 30 rounded once, sin once
    np.testing.assert_allclose(d["src.u[1]"], np.sin(0.1 * d["time"]), rtol=0, atol=roundoff(1.0 + 30.0, 1))
    assert np.all(np.abs(np.diff(d["sched.p[1]"])) <= 0.2 + roundoff(1.0, 2))  # the random walk's rate bound
    from lpvest.estimators._truncated import TruncatedKalmanFilter
    from lpvest.estimators.kalman import kalman_filter

    kf = kalman_filter(model, p, u, y)
    tol = kalman_fmu_tolerance(model, p, u, y, kf)
    np.testing.assert_allclose(np.column_stack([d["kalman.xhat[1]"], d["kalman.xhat[2]"]]), kf.filtered_means,
                               rtol=0, atol=tol)
    tk = TruncatedKalmanFilter(model, 3, start="theorem")
    xt = np.array([tk.step({"p": p[i], "u": u[i], "y": y[i]})["xhat"] for i in range(len(y))])
    # the FMU runs this same streaming filter: the same rounding bound, without the scan's
    np.testing.assert_allclose(np.column_stack([d["truncated.xhat[1]"], d["truncated.xhat[2]"]]), xt,
                               rtol=0, atol=tol)
    assert [t for t, _ in res.panels()] == ["sched.p", "plant.x[1], kalman.xhat[1], truncated.xhat[1]",
                                            "plant.x[2], kalman.xhat[2], truncated.xhat[2]",
                                            "kalman.P[1,1], truncated.P[1,1]"]


def test_default_record_and_panels_and_fmus_by_path(fmus, tmp_path):
    f = tmp_path / "two.toml"
    f.write_text(f"""
step_size = 0.5
stop_time = 2.0
start_time = 1.0
connections = ["sched.p -> plant.p"]
[components.sched]
fmu = "{fmus['PeixotoEx1Scheduler'].as_posix()}"
[components.plant]
fmu = "PeixotoEx1Plant"
parameters = {{ sample_time = 0.5 }}
""")
    res = load_cosim(f, fmu_dir=fmus.out).run()
    assert res.data.shape == (3,)
    np.testing.assert_array_equal(res.data["time"], [1.0, 1.5, 2.0])
    assert res.names == ["sched.p[1]", "sched.alpha[1]", "sched.alpha[2]", "plant.y[1]", "plant.z[1]",
                         "plant.z[2]", "plant.x[1]", "plant.x[2]"]
    assert [t for t, _ in res.panels()] == ["sched.p", "sched.alpha", "plant.y", "plant.z", "plant.x"]
    assert res.plot(tmp_path / "two.png").stat().st_size > 0


BASE = """
step_size = 1.0
steps = 10
connections = ["sched.p -> plant.p", "src.w -> plant.w"]

[components.sched]
fmu = "PeixotoEx1Scheduler"

[components.src]
fmu = "PeixotoEx1Source"

[components.plant]
fmu = "PeixotoEx1Plant"
"""


def _edit(text: str, old: str, new: str) -> str:
    assert old in text
    return text.replace(old, new, 1)


# (how to change BASE, field: message)
ERRORS = [
    (lambda t: t + "[", "not valid TOML: "),
    (lambda t: "speed = 2\n" + t, "speed: unknown key (expected one of: components, connections, description, "
     "fmu_dir, plots, record, start_time, step_size, steps, stop_time, title)"),
    (lambda t: "stepz = 2\n" + t, "stepz: unknown key, did you mean 'steps'? (expected one of: components, "
     "connections, description, fmu_dir, plots, record, start_time, step_size, steps, stop_time, title)"),
    (lambda t: _edit(t, "step_size = 1.0", "step_size = -1.0"),
     "step_size: expected a positive number, found a number (-1.0)"),
    (lambda t: _edit(t, "step_size = 1.0", 'step_size = "1"'),
     "step_size: expected a positive number, found a string ('1')"),
    (lambda t: _edit(t, "step_size = 1.0\n", ""), "step_size: missing (expected a positive number)"),
    (lambda t: _edit(t, "steps = 10", "steps = 10\nstop_time = 10.0"),
     "steps: give either steps or stop_time (exactly one)"),
    (lambda t: _edit(t, "steps = 10", "steps = 2.5"), "steps: expected a positive integer, found a number (2.5)"),
    (lambda t: _edit(t, "steps = 10", "stop_time = 10.25"),
     "stop_time: expected start_time + a positive whole number of steps of 1, found 10.25 (10.25 steps)"),
    (lambda t: t.split("[components.sched]")[0],
     "components: missing (expected a table [components.NAME] per component)"),
    (lambda t: t.split("[components.sched]")[0] + "components = {}\n",
     "components: expected at least one [components.NAME] table"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Scheduler"', 'fmu = "PeixotoEx1Scheduler"\ngain = 2'),
     "components.sched.gain: unknown key (expected one of: feedthrough, fmu, parameters)"),
    (lambda t: _edit(t, "[components.src]", '[components."2src"]'),
     "components.2src: is not a valid component name (expected a letter, then letters, digits, _)"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Scheduler"', "fmu = 3"),
     "components.sched.fmu: expected a built FMU's name or a path to an .fmu file, found a number (3)"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Scheduler"', 'parameters = { omega = [0.3] }'),
     "components.sched.fmu: missing (expected a built FMU's name or a path to an .fmu file)"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Scheduler"', 'fmu = "PeixotoEx9Scheduler"'),
     "components.sched.fmu: no FMU PeixotoEx9Scheduler.fmu in {fmu_dir} (build the FMUs into that folder "
     "with `lpvest build --out FOLDER`, or point --fmus or fmu_dir at theirs)"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Scheduler"', 'fmu = "nowhere/Sched.fmu"'),
     "components.sched.fmu: expected an FMU file, found no file {missing}"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Plant"', 'fmu = "PeixotoEx1Plant"\nparameters = 3'),
     "components.plant.parameters: expected a table of start values, found a number (3)"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Plant"', 'fmu = "PeixotoEx1Plant"\nparameters = { x0 = { a = 1 } }'),
     "components.plant.parameters.x0: expected a number, string, boolean or a list of them, found a table"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Plant"', 'fmu = "PeixotoEx1Plant"\nfeedthrough = "no"'),
     "components.plant.feedthrough: expected true or false, found a string ('no')"),
    (lambda t: _edit(t, '"src.w -> plant.w"', '"src.w plant.w"'),
     "connections[2]: expected 'comp.output -> comp.input', found 'src.w plant.w'"),
    (lambda t: _edit(t, '"src.w -> plant.w"', '"source.w -> plant.w"'),
     "connections[2]: no component 'source' in 'source.w' (components: sched, src, plant)"),
    (lambda t: _edit(t, '"src.w -> plant.w"', "3"), "connections[2]: expected a string, found a number (3)"),
    (lambda t: _edit(t, "steps = 10", 'steps = 10\nrecord = ["plant"]'),
     "record[1]: expected 'component.variable', found 'plant'"),
    (lambda t: _edit(t, "steps = 10", "steps = 10\nplots = [[]]"),
     "plots[1]: expected a non-empty list of variable names, found a list"),
    # found by the master, named by field
    (lambda t: _edit(t, '"src.w -> plant.w"', '"src.v -> plant.w"'),
     "connections[2]: connection source 'src.v': src has no variable 'v' (outputs: w)"),
    (lambda t: _edit(t, '"src.w -> plant.w"', '"plant.y -> src.w"'),
     "connections[2]: connection target src.w[1] is not an input (output)"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Plant"', 'fmu = "PeixotoEx1Plant"\nparameters = { gain = 2.0 }'),
     "components.plant.parameters.gain: no variable 'gain' to set (settable: p, sample_time, w, x0)"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Plant"', 'fmu = "PeixotoEx1Plant"\nparameters = { "\\r" = 2.0 }'),
     # one line, whatever the key
     "components.plant.parameters.'\\r': no variable '\\r' to set (settable: p, sample_time, w, x0)"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Plant"', 'fmu = "PeixotoEx1Plant"\nparameters = { x0 = [1.0] }'),
     "components.plant.parameters.x0: x0 has 2 element(s); 1 value(s) given"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Scheduler"',
                     'fmu = "PeixotoEx1Scheduler"\nparameters = { omega = ["fast"] }'),
     "components.sched.parameters.omega: omega[1]: expected a number, found str 'fast'"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Scheduler"', 'fmu = "PeixotoEx1Scheduler"\nparameters = { seed = 1.5 }'),
     "components.sched.parameters.seed: seed: expected an integer, found float 1.5"),
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Plant"', 'fmu = "PeixotoEx1Plant"\nparameters = { "y[1]" = 1.0 }'),
     "components.plant.parameters.'y[1]': y[1] is an output; it cannot be set"),  # the key as TOML quotes it
    (lambda t: _edit(t, "steps = 10", 'steps = 10\nrecord = ["plant.y"]\nplots = [["plant.x"]]'),
     "plots[1]: 'plant.x' is not recorded (see record)"),
    # found while running: the component's own message
    (lambda t: _edit(t, 'fmu = "PeixotoEx1Scheduler"',
                     'fmu = "PeixotoEx1Scheduler"\nparameters = { amplitude = [2.0] }'),
     "components.sched: reading outputs during initialization at t = 0 returned error ([ERROR] "
     "[PeixotoEx1Scheduler] fmi2GetReal (computing the outputs): SignalError: amplitude[1] = 2 with offset[1] = 0 "
     "takes p[1] (theta) to [-2, 2], outside its declared range [-1, 1])"),
]


@pytest.mark.parametrize(("change", "message"), ERRORS, ids=[m.split(":")[0] for _, m in ERRORS])
def test_every_mistake_is_one_line_naming_file_and_field(fmus, tmp_path, change, message):
    f = tmp_path / "run.toml"
    f.write_text(change(BASE))
    # paths in a message are shortened beyond a length (cosim.files._path_text): expected as shown,
    # so that the test does not depend on how long pytest's temporary folder is
    expected = f"{f}: " + message.format(fmu_dir=_path_text(fmus.out, 80),
                                         missing=_path_text(tmp_path / "nowhere" / "Sched.fmu"))
    with pytest.raises(ModelFileError) as info:
        load_cosim(f, fmu_dir=fmus.out).run()
    if message.startswith("not valid TOML"):
        assert str(info.value).startswith(expected)
    else:
        assert str(info.value) == expected
    assert "\n" not in str(info.value)


def test_command_line_error_is_one_line_with_status_2(fmus, tmp_path, capsys):
    f = tmp_path / "run.toml"
    f.write_text(_edit(BASE, "step_size = 1.0", "step_size = 0"))
    assert main(["cosim", str(f), "--fmus", str(fmus.out), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err == f"lpvest: error: {f}: step_size: expected a positive number, found a number (0)\n"


def test_fmu_dir_of_the_file_is_relative_to_the_file(fmus, tmp_path):
    sub = tmp_path / "cases"
    sub.mkdir()
    f = sub / "run.toml"
    rel = Path("..") / "fmus"
    (tmp_path / "fmus").symlink_to(fmus.out, target_is_directory=True)
    f.write_text(f'fmu_dir = "{rel.as_posix()}"\n' + BASE)
    spec = load_cosim(f)
    assert spec.fmu_dir == sub / rel
    assert re.fullmatch(r"PeixotoEx1Plant\.fmu", spec.components[2].fmu.name)
    assert spec.run().data.shape == (11,)


def test_the_readme_scripting_example_runs(fmus, capsys):
    text = (ROOT / "README.md").read_text()
    block = text.split("## Co-simulation", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    assert len(block.strip().splitlines()) <= 15
    exec(compile(block.replace('"fmu-build/', f'"{fmus.out.as_posix()}/'), "README.md", "exec"), {})
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("['get sched: ") and "'set filter: p[1], y[1]'" in out[0]
    assert float(out[1]) == pytest.approx(1.07, abs=0.005)


@pytest.mark.parametrize(
    ("value", "message"),
    [("inf", "expected an integer, found float inf"), ("nan", "expected an integer, found float nan"),
     ("1e308", "1e+308 is outside the range of an FMI Integer [-2147483648, 2147483647]"),
     ("4294967296", "4294967296 is outside the range of an FMI Integer [-2147483648, 2147483647]")],
)
def test_integer_parameters_out_of_range(fmus, tmp_path, value, message):
    # issue 12: seed = inf gave OverflowError, nan ValueError; found by tests/test_properties.py:
    # tau = 3e308 printed a 309-digit integer
    f = tmp_path / "run.toml"
    f.write_text(_edit(BASE, 'fmu = "PeixotoEx1Scheduler"',
                       f'fmu = "PeixotoEx1Scheduler"\nparameters = {{ seed = {value} }}'))
    with pytest.raises(ModelFileError, match=re.escape(f"{f}: components.sched.parameters.seed: seed: {message}")):
        load_cosim(f, fmu_dir=fmus.out).check()


def test_a_stop_time_of_too_many_steps(fmus, tmp_path):
    # found by tests/test_properties.py: the step count was printed with all its 300 digits
    f = tmp_path / "run.toml"
    f.write_text(_edit(BASE, "steps = 10", "stop_time = 1e300"))
    with pytest.raises(ModelFileError, match=re.escape(f"{f}: stop_time: 1e+300 steps: at most 100,000,000 (the "
                                                       "results are kept in memory)")):
        load_cosim(f, fmu_dir=fmus.out)


@pytest.mark.parametrize(
    ("raw", "message"),
    [(b"\xff\xfes\x00t\x00", r"not a TOML text file: byte 1 \(b'\\xff'\) is not UTF-8 \(the file is UTF-16"),
     (b"step_size = " + b"[" * 500 + b"1" + b"]" * 500, r"not valid TOML: arrays or tables nested too deeply$")],
    ids=["utf-16", "nested 500 deep"],
)
def test_a_cosimulation_file_that_is_not_toml_text(tmp_path, raw, message):
    # issue 12: UnicodeDecodeError and RecursionError escaped, as for model files
    f = tmp_path / "run.toml"
    f.write_bytes(raw)
    with pytest.raises(ModelFileError, match=f"^{re.escape(str(f))}: {message}"):
        load_cosim(f)
