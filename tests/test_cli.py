"""The gonio command line: version, help, model listing and slice plots, clean errors."""
from __future__ import annotations

import subprocess
import sys

import pytest

import gonio
from gonio.cli import main
from gonio.cli.models import format_model_table, parse_model_spec


def test_version_and_help(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.strip() == f"gonio {gonio.__version__}"
    assert main([]) == 0
    assert "demo" in capsys.readouterr().out


def test_console_script_runs_as_a_module():
    done = subprocess.run([sys.executable, "-m", "gonio", "--version"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.startswith("gonio ")


def test_models_lists_every_model_with_units_and_bounds(capsys):
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    for name in gonio.models.available():
        assert f"{name}  -  " in out
    assert "sigma      [deg]" in out and "range [0, 90]" in out
    assert format_model_table() == out


def test_model_spec_parsing_and_errors():
    assert parse_model_spec("oren-nayar:sigma=30,rho=0.9") == ("oren-nayar", {"sigma": 30.0, "rho": 0.9})
    with pytest.raises(ValueError, match="unknown model"):
        parse_model_spec("oren-naiar")
    with pytest.raises(ValueError, match="expected key=value"):
        parse_model_spec("lambert:rho")
    with pytest.raises(ValueError, match="rho = 2"):
        parse_model_spec("lambert:rho=2")


def test_models_plot_writes_a_png_of_the_fig10_geometry(tmp_path, capsys):
    out = tmp_path / "slices.png"
    code = main(["models", "plot", "oren-nayar:sigma=30,rho=0.9", "lambert:rho=0.9",
                 "--theta-i", "75", "--plane", "in", "perp", "45", "--out", str(out)])
    assert code == 0 and out.stat().st_size > 10_000
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_plot_arguments_give_one_line_errors(tmp_path, capsys):
    assert main(["models", "plot", "lambert", "--plane", "sideways", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gonio: error: plane 'sideways'") and "Traceback" not in err


def test_figures_reproduces_oren_nayar_figs_10_to_14(tmp_path, capsys):
    """gonio figures draws Figs 10-14 of Oren & Nayar (1995) from the registered models."""
    assert main(["figures", "--out", str(tmp_path)]) == 0
    names = sorted(p.name for p in tmp_path.glob("*.png"))
    assert [n[:5] for n in names] == ["fig10", "fig11", "fig12", "fig13", "fig14"]
    assert all((tmp_path / n).stat().st_size > 20_000 for n in names)
    assert "5 figures written" in capsys.readouterr().out
