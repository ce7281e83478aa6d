"""The lpvest command line."""

import argparse
import os
import subprocess
import sys
from pathlib import Path

import pytest

from lpvest.cli import main
from lpvest.core._errors import shorten
from lpvest.design import HinfDesign


def test_systems_lists_the_examples(capsys):
    assert main(["systems"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split()[0] for line in lines] == [
        "cox-toth-ex1", "cox-toth-truncation", "peixoto-ex1", "peixoto-ex2", "sridhar-ltv"
    ]


@pytest.mark.parametrize("name", ["cox-toth-ex1", "cox-toth-truncation", "peixoto-ex1", "peixoto-ex2", "sridhar-ltv"])
def test_systems_show(name, capsys):
    assert main(["systems", "show", name]) == 0
    out = capsys.readouterr().out
    assert out.startswith(name + ": ")
    assert "model " in out


def test_systems_show_peixoto_details(capsys):
    main(["systems", "show", "peixoto-ex2", "--param", "rho=3"])
    out = capsys.readouterr().out
    assert "parameters: rho = 3 in [1, 21]" in out
    assert "-0.15" in out  # -0.05 * rho
    assert "alpha_1 = (1 - theta)/2" in out


def test_systems_show_users_file(tmp_path, capsys):
    from tests.test_modelfile import GOOD

    path = tmp_path / "mine.toml"
    path.write_text(GOOD)
    assert main(["systems", "show", str(path)]) == 0
    out = capsys.readouterr().out
    assert "affine LPV with general noise" in out and "n_x=2 n_u=0 n_y=1" in out


def test_malformed_file_gives_one_line_and_no_traceback(tmp_path):
    path = tmp_path / "broken.toml"
    from tests.test_modelfile import GOOD

    path.write_text(GOOD.replace("C = [[1.0, 0.0]]", "C = [[1.0, 0.0], [3.0]]"))
    proc = subprocess.run(
        [sys.executable, "-m", "lpvest.cli", "systems", "show", str(path)],
        capture_output=True, text=True, check=False,
    )
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.count("\n") == 1
    assert proc.stderr.startswith(f"lpvest: error: {path}: models.m.C: rows have different lengths")
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    ("name", "extra"),
    [("peixoto-ex1", ["--schedule", "sin(0.25*k)"]), ("cox-toth-ex1", ["--schedule", "0.5 + 0.3*sin(k)"]),
     ("cox-toth-ex1", ["--model", "io"]), ("sridhar-ltv", []), ("peixoto-ex2", ["--param", "rho=10"])],
)
def test_simulate_writes_csv_and_plot(tmp_path, capsys, name, extra):
    assert main(["simulate", name, "--steps", "40", "--out", str(tmp_path), *extra]) == 0
    out = capsys.readouterr().out
    assert "simulated" in out
    csvs = list(tmp_path.glob("*.csv"))
    pngs = list(tmp_path.glob("*.png"))
    assert len(csvs) == 1 and len(pngs) == 1
    header = csvs[0].read_text().splitlines()[0]
    assert "y" in header.split(",")
    assert len(csvs[0].read_text().splitlines()) == 41


def test_simulate_reports_bad_schedule(capsys):
    # (21b) is not defined where p_{t+1} = 0
    assert main(["simulate", "cox-toth-ex1", "--schedule", "0*k", "--out", "/tmp/lpvest-x"]) == 2
    assert "the gain K is not finite" in capsys.readouterr().err


def test_output_piped_into_head_ends_quietly():
    proc = subprocess.run(
        f"{sys.executable} -m lpvest.cli systems show peixoto-ex1 | head -1",
        shell=True, capture_output=True, text=True, check=False,
    )
    assert proc.stdout.startswith("peixoto-ex1: ")
    assert "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr


# -- every expected failure is one line and status 2 (issue 12) -----------------------------------


def _run(*argv, cwd=None):
    return subprocess.run([sys.executable, "-m", "lpvest.cli", *argv], capture_output=True, text=True,
                          check=False, cwd=cwd)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["simulate", "cox-toth-ex1", "--schedule", "0.5", "--schedule", "0.2", "--out", "OUT"],
         "lpvest: error: schedule: 2 formulas given; expected 1 (one per scheduling component: p)"),
        (["simulate", "peixoto-ex1", "--seed", "-1"],
         "lpvest simulate: error: argument --seed: expected a non-negative integer, found -1 "
         "(see lpvest simulate --help)"),
        (["simulate", "peixoto-ex1", "--steps", "1"],
         "lpvest simulate: error: argument --steps: expected 2 to 1,000,000 samples, found 1 "
         "(see lpvest simulate --help)"),
        (["simulate", "peixoto-ex1", "--out", "/dev/null"],
         "lpvest: error: --out /dev/null: cannot create the output folder (/dev/null is a file, not a folder)"),
        (["simulate", "cox-toth-ex1", "--schedule", "1/k", "--out", "OUT"],
         "lpvest: error: schedule: formula '1/k' is inf at k = 0"),
        (["simulate", "peixoto-ex1", "--schedule", "9**9**9", "--out", "OUT"],
         "lpvest: error: formula '9**9**9' overflows (its value exceeds the floating-point range, about 1.8e308)"),
        (["validate", "README.md"], "lpvest: error: README.md: not an FMU (not a zip archive)"),
        (["validate", "nothing.fmu"], "lpvest: error: nothing.fmu: no such file"),
        (["systems", "show"], "lpvest: error: systems: expected one example name or model file, e.g. "
                              "`lpvest systems show peixoto-ex1` (or nothing, to list the examples)"),
        (["systems", "peixoto-ex9"],
         "lpvest: error: no example system 'peixoto-ex9' (examples: cox-toth-ex1, cox-toth-truncation, peixoto-ex1, "
         "peixoto-ex2, sridhar-ltv; or give a .toml file)"),
        (["systems", "show", "peixoto-ex2", "--param", "rho"], "lpvest: error: --param 'rho': expected NAME=VALUE"),
        (["systems", "show", "peixoto-ex2", "--param", "rho=nan"],
         "lpvest: error: ROOT/models/peixoto_ex2.toml: parameters.rho (override): expected a finite number, "
         "found a number (nan)"),
        (["reproduce", "nothing"], "lpvest: error: no experiment 'nothing' (known: "),
        (["reproduce", "cox-toth-example1", "nothing"], "lpvest: error: no experiment 'nothing' (known: "),
        (["reproduce", "cox-toth-example1", "all"],
         "lpvest: error: 'all' stands alone (lpvest reproduce all), not among experiment names"),
        (["bogus"], "lpvest: error: argument COMMAND: invalid choice: 'bogus' (choose from "),
        # issue 21: refused before any slow work, one line naming the culprit
        (["design", "peixoto-ex1", "--out", "README.md/d.json"],
         "lpvest: error: --out README.md: cannot create the output folder (README.md is a file, not a folder)"),
        (["build", "--model", "peixoto-ex1", "--out", "README.md/fmus"],
         "lpvest: error: --out README.md/fmus: cannot create the output folder (README.md is a file, not a folder)"),
        (["design", "peixoto-ex1", "--out", "models"], "lpvest: error: --out models: is a folder; expected a file"),
        (["design", "peixoto-ex1", "--solver", "BOGUS", "--out", "OUT/d.json"],
         "lpvest: error: solver 'BOGUS': expected AUTO or an installed cvxpy solver of semidefinite programs ("),
        (["build", "--model", "peixoto-ex1", "--solver", "BOGUS", "--out", "OUT"],
         "lpvest: error: solver 'BOGUS': expected AUTO or an installed cvxpy solver of semidefinite programs ("),
        (["build", "--model", "peixoto-ex1", "--solver", "OSQP", "--out", "OUT"],  # installed, but no SDPs
         "lpvest: error: solver 'OSQP': expected AUTO or an installed cvxpy solver of semidefinite programs ("),
        (["design", "peixoto-ex1", "--epsilon", "nan", "--out", "OUT/d.json"],
         "lpvest design: error: argument --epsilon: expected a number (inf and -inf allowed), found nan"),
        # a negative number in scientific notation is a value, not an option: the solver is the error
        (["design", "peixoto-ex1", "--epsilon", "-1e300", "--solver", "BOGUS", "--out", "OUT/d.json"],
         "lpvest: error: solver 'BOGUS'"),
        (["sweep", "examples/sweep_kalman.toml", "--workers", "-1"],
         "lpvest sweep: error: argument --workers: expected 0 (run in this process) or a number of worker "
         "processes, found '-1'"),
        (["--bogus-flag"], "lpvest: error: unrecognized option '--bogus-flag' before the command"),
        (["systems", "show", "models"], "lpvest: error: models: is a folder, not a model file"),
        (["build", "--kinds", "Bogus", "--out", "OUT"],
         "lpvest: error: --kinds: no role 'Bogus' (roles: Plant, Scheduler, Source, Kalman, TruncatedKalman, "),
        # regress: its folders checked before any FMU is built
        (["regress", "--dir", "OUT/none", "--fmus", "OUT/cache"], "lpvest: error: no reference folder "),
        (["regress", "--dir", "tests", "--fmus", "OUT/cache"],
         "lpvest: error: tests: no reference file cox-toth-example1.csv (6 of 6 missing; write them with "
         "lpvest regress --update)"),
        (["regress", "--update", "--dir", "README.md/refs"],
         "lpvest: error: --dir README.md/refs: cannot create the output folder (README.md is a file, not a folder)"),
        (["regress", "--fmus", "README.md"],
         "lpvest: error: --fmus README.md: cannot create the output folder (README.md is a file, not a folder)"),
    ],
)
def test_expected_failures_are_one_line_with_status_2(tmp_path, argv, message):
    root = str(Path(__file__).resolve().parent.parent)
    argv = [a.replace("OUT", str(tmp_path / "out")) for a in argv]
    proc = _run(*argv, cwd=root)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert proc.stderr.startswith(message.replace("ROOT", root)), proc.stderr
    assert "Traceback" not in proc.stderr


def test_design_replaces_an_earlier_design_but_no_other_file(tmp_path, capsys):
    """`lpvest design --out FILE` wrote its JSON over any file, README.md included: a file
    that is not a design is now refused before the solve, left as it was; a design is
    replaced (the same command run again)."""
    notes = tmp_path / "notes.md"
    notes.write_text("my notes\n")
    proc = _run("design", "peixoto-ex1", "--epsilon", "1", "--out", "notes.md", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr == ("lpvest: error: --out notes.md: exists and is not an lpvest design (JSON) (only one is "
                           "replaced); remove it or choose another name\n")
    assert notes.read_text() == "my notes\n"
    for text in ("{not json", '["lpvest.hinf-design"]', '{"format": "another"}'):  # JSON or not, not a design
        notes.write_text(text)
        assert main(["design", "peixoto-ex1", "--epsilon", "1", "--out", str(notes)]) == 2
        assert notes.read_text() == text
    capsys.readouterr()
    earlier = tmp_path / "pd.json"
    earlier.write_text('{"format": "lpvest.hinf-design", "version": 1}')  # an earlier design (its format's name)
    assert main(["design", "peixoto-ex1", "--epsilon", "1", "--out", str(earlier), "--quiet"]) == 0
    assert f"wrote {earlier}" in capsys.readouterr().out
    assert HinfDesign.from_json(earlier).gamma > 0


def test_debug_shows_the_traceback():
    proc = _run("simulate", "peixoto-ex1", "--out", "/dev/null", "--debug")
    assert proc.returncode == 2
    assert "Traceback (most recent call last)" in proc.stderr and "OutputError" in proc.stderr
    assert proc.stderr.endswith("lpvest: error: --out /dev/null: cannot create the output folder "
                                "(/dev/null is a file, not a folder)\n")


def test_systems_name_is_systems_show_name(capsys):
    assert main(["systems", "peixoto-ex1"]) == 0
    short = capsys.readouterr().out
    assert main(["systems", "show", "peixoto-ex1"]) == 0
    assert capsys.readouterr().out == short and short.startswith("peixoto-ex1: ")


def test_schedule_does_not_swallow_the_file_name(tmp_path, capsys):
    # `--schedule FORMULA` takes one formula: the example name after it is the target
    assert main(["simulate", "--schedule", "0.5", "peixoto-ex1", "--steps", "5", "--out", str(tmp_path)]) == 0
    assert "simulated peixoto-ex1 / plant: 5 samples" in capsys.readouterr().out


def test_every_subcommand_has_a_description_and_examples():
    from lpvest.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) >= {"systems", "simulate", "reproduce", "regress", "build", "cosim", "validate"}
    for name, p in sub.choices.items():
        text = p.format_help()
        assert p.description and len(p.description) > 40, name
        assert "examples:\n  lpvest " + name in text, name
        assert "--debug" in text, name


def test_a_wrong_model_is_refused_before_anything_is_printed():
    proc = _run("systems", "show", "peixoto-ex1", "--model", "nomodel", cwd=Path(__file__).resolve().parent.parent)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.endswith("no model 'nomodel' (models: plant)\n")


def test_help_shows_a_percent_sign_once():
    proc = _run("simulate", "--help")
    assert "spanning 90 % of the box" in proc.stdout and "%%" not in proc.stdout


def test_a_design_file_for_another_plant_is_refused_before_any_fmu_is_built(tmp_path):
    root = Path(__file__).resolve().parent.parent
    out = tmp_path / "out"
    proc = _run("build", "--model", "examples/own_plant.toml", "--design",
                "models/designs/peixoto-ex1.HinfPD.json", "--out", str(out), cwd=root)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert proc.stderr.startswith("lpvest: error: models/designs/peixoto-ex1.HinfPD.json: designed for a plant"), \
        proc.stderr
    assert not list(out.glob("*.fmu"))  # refused first: not after the plant, scheduler, source, filters


# -- issue 21: four more messages that left a new user guessing (each: before -> after) ----------------
@pytest.mark.parametrize(
    ("argv", "message"),
    [
        # before: "lpvest: error: unrecognized arguments: --stpes 10 (see lpvest --help)", the wrong command's help
        (["simulate", "peixoto-ex1", "--stpes", "10"],
         "lpvest simulate: error: unrecognized option '--stpes' (did you mean --steps?) (see lpvest simulate --help)"),
        (["design", "peixoto-ex1", "--out", "OUT/d.json", "--epsilno", "3"],
         "lpvest design: error: unrecognized option '--epsilno' (did you mean --epsilon?) (see lpvest design --help)"),
        (["simulate", "peixoto-ex1", "--bogus=3"],  # nothing near: no guess
         "lpvest simulate: error: unrecognized option '--bogus' (see lpvest simulate --help)"),
        (["simulate", "peixoto-ex1", "peixoto-ex2"],
         "lpvest simulate: error: unexpected argument 'peixoto-ex2' (lpvest simulate takes no more) "
         "(see lpvest simulate --help)"),
        # before: "lpvest: error: .: cannot be read: Is a directory"
        (["build", "--model", "peixoto-ex1", "--design", "HinfPD=", "--out", "OUT"],
         "lpvest: error: --design 'HinfPD=': expected [ROLE=]FILE.json, found no file name after HinfPD="),
        # before: "building PeixotoEx1Scheduler into README.md" then "lpvest: error: File exists: README.md"
        (["reproduce", "peixoto-fig1", "--fmus", "README.md", "--out", "OUT"],
         "lpvest: error: --fmus README.md: cannot create the output folder (README.md is a file, not a folder)"),
        # before: "lpvest: error: systems: expected one example name or model file, e.g. `lpvest systems show
        # peixoto-ex1` (or nothing, to list the examples)": the user had given one, after a misspelt "show"
        (["systems", "shwo", "peixoto-ex1"],
         "lpvest: error: systems: 'shwo' is not a word of `lpvest systems` (did you mean "
         "`lpvest systems show peixoto-ex1`?)"),
        (["systems", "peixoto-ex1", "peixoto-ex2"],
         "lpvest: error: systems: expected one example name or model file, found 2: peixoto-ex1 peixoto-ex2 "
         "(one system at a time)"),
    ],
)
def test_a_mistaken_command_line_is_named_in_the_commands_own_terms(tmp_path, argv, message):
    root = str(Path(__file__).resolve().parent.parent)
    proc = _run(*[a.replace("OUT", str(tmp_path / "out")) for a in argv], cwd=root)
    assert (proc.returncode, proc.stdout, proc.stderr) == (2, "", message + "\n")
    assert not (tmp_path / "out").exists()  # refused before anything was made


@pytest.mark.parametrize("folder", [False, True])
def test_a_sweep_file_naming_a_missing_cosim_file_says_which_file_and_where(tmp_path, folder):
    """Before: "lpvest: error: nosuch.toml: cannot be read: No such file or directory",
    neither the sweep file that names it nor where it was looked for."""
    spec = tmp_path / "specs" / "s.toml"
    spec.parent.mkdir()
    spec.write_text('title = "t"\ncosim = "nosuch.toml"\n')
    if folder:
        (spec.parent / "nosuch.toml").mkdir()
    proc = _run("sweep", "specs/s.toml", "--workers", "0", "--out", "out", cwd=tmp_path)
    expected = ("specs/nosuch.toml is a folder, not a co-simulation file" if folder
                else "no co-simulation file specs/nosuch.toml (a path relative to this sweep file)")
    assert (proc.returncode, proc.stdout, proc.stderr) == (2, "", f"lpvest: error: specs/s.toml: cosim: {expected}\n")


def test_regress_refuses_a_missing_reference_before_building_anything(tmp_path):
    """A reference folder without the references asked for: one line, status 2,
    and the FMU cache untouched (no FMU built, no co-simulation run)."""
    (tmp_path / "refs").mkdir()
    (tmp_path / "refs" / "cox-toth-example1.csv").write_text("stored\n")
    # relative paths: the message is exact whatever the length of the temporary folder's path
    proc = _run("regress", "cox-toth-example1", "peixoto-table1", "--dir", "refs", "--fmus", "cache", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stdout == "", proc.stderr
    assert proc.stderr == ("lpvest: error: refs: no reference file peixoto-table1.csv "
                           "(1 of 2 missing; write them with lpvest regress --update)\n")
    assert list((tmp_path / "cache").iterdir()) == []


@pytest.mark.parametrize("quiet", [False, True])
def test_regress_quiet_silences_the_fmu_build_lines(tmp_path, monkeypatch, capsys, quiet):
    """`lpvest regress --quiet`: the FMU cache reports nothing (the results and
    errors still do); without it, each build line goes to stderr."""
    from lpvest.experiments import _references

    seen = {}

    def fake_regress(names, *, update, directory, fmus):
        seen.update(names=names, progress=fmus.progress)
        if fmus.progress is not None:
            fmus.progress("building CoxTothEx1Plant")
        return 0

    monkeypatch.setattr(_references, "regress", fake_regress)
    argv = ["regress", "cox-toth-example1", "--fmus", str(tmp_path / "cache")] + (["--quiet"] if quiet else [])
    assert main(argv) == 0
    assert seen["names"] == ["cox-toth-example1"]
    assert (seen["progress"] is None) is quiet
    assert capsys.readouterr().err == ("" if quiet else "building CoxTothEx1Plant\n")


def _without_file_permission_override():
    """For a child process run as root: drop the capabilities that let root write
    where the folder's mode forbids it (CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH), so
    that a read-only folder refuses it as it refuses any user."""
    import ctypes

    if os.geteuid() != 0:
        return
    libc = ctypes.CDLL(None, use_errno=True)
    for cap in (1, 2):
        if libc.prctl(24, cap, 0, 0, 0) != 0:  # PR_CAPBSET_DROP
            raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="folder modes and capabilities as on Linux")
@pytest.mark.parametrize("argv", [
    ["design", "peixoto-ex1", "--epsilon", "1", "--out", "OUT/d.json"],
    ["build", "--model", "peixoto-ex1", "--out", "OUT"],
    ["simulate", "peixoto-ex1", "--out", "OUT"],
    ["reproduce", "peixoto-fig1", "--out", "OUT"],
    ["regress", "--update", "--dir", "OUT"],
], ids=["design", "build", "simulate", "reproduce", "regress"])
@pytest.mark.parametrize("where", ["the-folder", "a-folder-in-it"])
def test_a_folder_without_write_permission_is_refused_before_any_work(tmp_path, argv, where):
    """Issue 21: an unwritable output place is said at once, in one line, by every
    command that writes (root included: the child runs without root's override)."""
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    out = locked if where == "the-folder" else locked / "sub"
    try:
        proc = subprocess.run([sys.executable, "-m", "lpvest.cli", *[a.replace("OUT", str(out)) for a in argv]],
                              capture_output=True, text=True, check=False, timeout=120,
                              preexec_fn=_without_file_permission_override)
    finally:
        locked.chmod(0o755)
    assert proc.returncode == 2, proc.stderr
    what = "cannot write in" if where == "the-folder" else "cannot create"
    option = "--dir" if argv[0] == "regress" else "--out"
    folder = locked if where == "the-folder" else out
    assert proc.stderr == (f"lpvest: error: {option} {shorten(str(folder), 60)}: {what} the output folder "
                           "(permission denied)\n"), proc.stderr
    assert list(locked.iterdir()) == []  # nothing was written
