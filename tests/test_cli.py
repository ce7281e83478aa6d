"""The lpvest command line."""

import subprocess
import sys

import pytest

from lpvest.cli import main


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
    assert "parameters: rho = 3" in out
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
