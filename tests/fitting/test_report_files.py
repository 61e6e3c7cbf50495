"""The report's files: the page embeds exactly the figures it was given and is written
after them; ``gonio fit --report`` writes the same files as ``gonio report`` on the saved
folder, and with ``--overwrite`` a report that fails leaves no report of the earlier fit."""
from __future__ import annotations

import base64
import pickle

import pytest

from gonio.cli import main
from gonio.fitting import fit
from gonio.fitting.results import FitResult
from gonio.report import fit_report
from gonio.report.fit_html import FIGURE_NAMES, FIGURES, REPORT_FILES, write_html

from .synthetic import synthetic_dataset


@pytest.fixture(scope="module")
def saved_fit(tmp_path_factory):
    """A small Minnaert fit with MCMC, saved (result.json, chain.npz, posterior.nc)."""
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.005, seed=1)
    folder = tmp_path_factory.mktemp("fit")
    fit(data, "minnaert", n_walkers=8, tau_multiple=10.0, rhat_limit=1.05, seed=0).save(folder)
    return folder


def _contents(folder, names=REPORT_FILES) -> dict[str, bytes]:
    return {name: (folder / name).read_bytes() for name in names}


def test_figure_names_are_unique():
    assert len(set(FIGURE_NAMES)) == len(FIGURES) == 5


def test_the_page_embeds_exactly_the_figures_given_and_needs_all_five(saved_fit, tmp_path):
    result = FitResult.load(saved_fit)
    pngs = {name: f"not really {name}".encode() for name in FIGURE_NAMES}
    (tmp_path / "fit-corner.png").write_bytes(b"an earlier fit's corner plot")
    with pytest.raises(ValueError, match="no PNG for fit-corner.png"):
        write_html(result, tmp_path, {k: v for k, v in pngs.items() if k != "fit-corner.png"})
    assert not (tmp_path / "report.html").exists()
    text = write_html(result, tmp_path, pngs).read_text()
    embedded = [base64.b64decode(s) for s in text.split("data:image/png;base64,")[1:] for s in [s.split("'")[0]]]
    assert embedded == [pngs[name] for name in FIGURE_NAMES]


def test_a_result_in_memory_and_its_saved_folder_give_the_same_report(saved_fit, tmp_path):
    fit_report.write_report(saved_fit, tmp_path / "folder")
    fit_report.write_report(FitResult.load(saved_fit), tmp_path / "memory")
    assert _contents(tmp_path / "memory") == _contents(tmp_path / "folder")


def test_a_pickled_result_leaves_its_cached_problem_behind():
    data = synthetic_dataset("lambert", dict(rho=0.5), 0.005)
    result = fit(data, "lambert", mcmc=False)
    result.problem()
    clone = pickle.loads(pickle.dumps(result))
    assert "_problem" in result.__dict__ and "_problem" not in clone.__dict__
    assert clone.problem().free == result.problem().free


# ----------------------------------------------------------------------------- the command
@pytest.fixture
def small_csv(tmp_path):
    data = synthetic_dataset("lambert", dict(rho=0.5), 0.005)
    return data.to_csv(tmp_path / "d.csv")


FIT = ["--model", "lambert", "--walkers", "8", "--max-steps", "300", "--rhat-limit", "1.2", "--quiet", "--report"]


def test_overwrite_removes_the_earlier_report_before_drawing(small_csv, tmp_path, monkeypatch, capsys):
    out = tmp_path / "fit"
    main(["fit", str(small_csv), *FIT, "--out", str(out)])
    assert (out / "report.html").exists()
    earlier = (out / "result.json").read_bytes()

    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(fit_report, "write_report", disk_full)
    assert main(["fit", str(small_csv), *FIT, "--out", str(out), "--overwrite", "--seed", "1"]) == 2
    assert "No space left on device" in capsys.readouterr().err
    assert (out / "result.json").read_bytes() != earlier  # the new result
    assert not any((out / name).exists() for name in REPORT_FILES)  # and no report of the earlier fit


def test_fit_report_equals_the_report_command(small_csv, tmp_path):
    main(["fit", str(small_csv), *FIT, "--out", str(tmp_path / "fit")])
    assert main(["report", str(tmp_path / "fit"), "--out", str(tmp_path / "again")]) == 0
    assert _contents(tmp_path / "fit") == _contents(tmp_path / "again")
