"""The gonio command line: version, help, model listing and slice plots, clean errors."""
from __future__ import annotations

import errno
import os
import stat
import subprocess
import sys

import pytest

import gonio
from gonio.cli import CLIError, main
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


def test_the_program_exits_with_the_commands_status_and_its_whole_output(tmp_path):
    # gonio.cli.run (the console script, python -m gonio) freezes the objects left before
    # exiting: the exit status and every line of output are still the command's.
    listed = subprocess.run([sys.executable, "-m", "gonio", "models"], capture_output=True, text=True, timeout=120)
    assert listed.returncode == 0
    assert all(f"{name}  -  " in listed.stdout for name in gonio.models.available())
    missing = subprocess.run([sys.executable, "-m", "gonio", "fit", str(tmp_path / "none.csv"), "--model", "lambert"],
                             capture_output=True, text=True, timeout=120)
    assert missing.returncode == 2 and missing.stderr.startswith("gonio: error:")
    from importlib.metadata import entry_points

    assert [script.value for script in entry_points(group="console_scripts", name="gonio")] == ["gonio.cli:run"]


def test_a_reader_that_leaves_early_is_not_an_error():
    """``gonio models | head -1``: the reader closes the pipe before gonio has written; gonio
    stops quietly with 141 (128 + SIGPIPE, as shell tools do), not 'gonio: error: Broken pipe'."""
    reader, writer = os.pipe()
    os.close(reader)  # gone before the first line is written
    try:
        done = subprocess.run([sys.executable, "-m", "gonio", "models"], stdout=writer, stderr=subprocess.PIPE,
                              text=True, timeout=120)
    finally:
        os.close(writer)
    assert done.returncode == 141
    assert done.stderr == ""


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


# ---------------------------------------------------------------------- output folders
CSV = "theta_i,phi_i,theta_r,phi_r,value,sigma\n30,0,10,0,0.30,0.01\n30,0,20,0,0.29,0.01\n30,0,40,180,0.28,0.01\n"


def _fit(data, out, *extra) -> int:
    return main(["fit", str(data), "--model", "lambert", "--no-mcmc", "--quiet", "--out", str(out), *extra])


def test_fit_refuses_a_used_folder_and_overwrite_replaces_only_its_own_files(tmp_path, capsys):
    data = tmp_path / "data.csv"
    data.write_text(CSV)
    out = tmp_path / "result"
    assert _fit(data, out, "--report") == 0
    written = {p.name for p in out.iterdir()}
    assert {"result.json", "summary.txt", "report.html", "fit-data.png"} <= written
    capsys.readouterr()
    assert _fit(data, out) == 2  # a second run without --overwrite
    assert "already holds files" in capsys.readouterr().err
    (out / "notes.txt").write_text("the user's notes")
    before = (out / "result.json").stat().st_mtime_ns
    assert _fit(data, out, "--overwrite") == 0  # no --report this time
    remaining = {p.name for p in out.iterdir()}
    assert remaining == {"result.json", "summary.txt", "notes.txt"}  # the earlier report is stale: removed
    assert (out / "notes.txt").read_text() == "the user's notes"
    assert (out / "result.json").stat().st_mtime_ns >= before


def test_overwrite_without_mcmc_removes_the_earlier_chain_and_posterior(tmp_path, capsys):
    """A least-squares result must not sit beside the chain and posterior.nc of an earlier
    MCMC fit, which a reader would take for its own."""
    data = tmp_path / "data.csv"
    data.write_text(CSV)
    out = tmp_path / "result"
    assert main(["fit", str(data), "--model", "lambert", "--quiet", "--out", str(out)]) == 0  # with MCMC
    assert {"chain.npz", "posterior.nc"} <= {p.name for p in out.iterdir()}
    assert _fit(data, out, "--overwrite") == 0
    assert {p.name for p in out.iterdir()} == {"result.json", "summary.txt"}


def test_fit_result_files_are_written_atomically_with_normal_permissions(tmp_path, monkeypatch):
    from gonio import files
    from gonio.fitting import Dataset, fit

    data = tmp_path / "data.csv"
    data.write_text(CSV)
    result = fit(Dataset.from_csv(data), "lambert", mcmc=False)
    previous = os.umask(0o027)
    try:
        path = result.save(tmp_path / "out")
    finally:
        os.umask(previous)
    for name in result.saved_files():
        assert stat.S_IMODE((tmp_path / "out" / name).stat().st_mode) == 0o640  # 0o666 & ~0o027
    original = path.read_bytes()

    def disk_full(handle, *args):
        raise OSError(errno.ENOSPC, "No space left on device")

    real_fdopen = os.fdopen

    def failing_fdopen(fd, *args, **kwargs):
        handle = real_fdopen(fd, *args, **kwargs)
        handle.write = disk_full
        return handle

    monkeypatch.setattr(files.os, "fdopen", failing_fdopen)
    with pytest.raises(OSError, match="No space left"):
        result.save(tmp_path / "out")
    monkeypatch.undo()
    assert path.read_bytes() == original  # the earlier result is intact
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(result.saved_files())  # no temporary left


def test_tables_clear_deletes_only_tables_gonio_built(tmp_path, monkeypatch, capsys):
    import numpy as np

    from gonio.models.tabulated import store

    monkeypatch.setenv("GONIO_TABLE_DIR", str(tmp_path))
    built = store.save(tmp_path / "oren-nayar.npz", {"shape": np.array([2]), "rtol": np.array(1e-3)})
    np.savez(tmp_path / "chain.npz", chain=np.zeros(3))  # a user's file with the same extension
    np.savez(tmp_path / "oren-nayar.tmp.npz", x=np.zeros(1))
    (tmp_path / "notes.txt").write_text("keep")
    assert main(["tables", "clear"]) == 0
    out = capsys.readouterr().out
    assert not built.exists() and f"removed {built}" in out
    for name in ("chain.npz", "oren-nayar.tmp.npz", "notes.txt"):
        assert (tmp_path / name).exists() and f"kept {tmp_path / name}" in out


def test_tables_clear_keeps_a_foreign_file_with_a_table_name_and_removes_legacy_tables(tmp_path, monkeypatch, capsys):
    import numpy as np

    from gonio.models.tabulated import store

    monkeypatch.setenv("GONIO_TABLE_DIR", str(tmp_path))
    np.savez(tmp_path / "oren-nayar.npz", samples=np.zeros(3))  # named like a table, written by someone else
    assert store.clear_cache() == [] and (tmp_path / "oren-nayar.npz").exists()
    # a table written before the signature: the exact name and the arrays every table holds
    np.savez(tmp_path / "oren-nayar.npz", shape=np.array([2]), rtol=np.array(1e-3), build_seconds=np.array(1.0))
    assert store.clear_cache() == [tmp_path / "oren-nayar.npz"]
    assert main(["tables", "clear"]) == 0
    assert "no table built by gonio" in capsys.readouterr().out


def test_tcp_ports_outside_the_port_range_are_refused_by_name():
    from gonio.cli.emulator import _port_spec

    assert _port_spec("65533") == {"stage": 65533, "camera": 65534, "lamp": 65535}
    with pytest.raises(CLIError, match="--tcp-ports 65534: TCP ports are 1 to 65535"):
        _port_spec("65534")
    with pytest.raises(CLIError, match="TCP ports are 1 to 65535"):
        _port_spec("stage=0,camera=5001,lamp=5002")


def test_an_empty_sample_is_refused_not_read_as_none(tmp_path, capsys):
    protocol = tmp_path / "p.toml"
    protocol.write_text('[protocol]\nname = "p"\n[sample]\nlabel = "s"\n[[block]]\ntheta_i = 30\nphi_i = 0\n'
                        'view = [0]\n')
    assert main(["run", str(protocol), "--out", str(tmp_path / "rec"), "--sample", " "]) == 2
    assert "--sample ' ': expected a sample spec" in capsys.readouterr().err
    assert not (tmp_path / "rec" / "points.csv").exists()
