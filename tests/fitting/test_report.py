"""The fit report and the gonio fit / gonio report commands."""
from __future__ import annotations

import io
import re
import warnings

import numpy as np
import pytest
from matplotlib.colors import to_rgba_array

from gonio.cli import main
from gonio.fitting import ConvergenceWarning, Dataset, FitResult, fit
from gonio.report.fit_figures import MAX_TRACE_POINTS, MAX_TRACE_WALKERS, data_figure, geometry_figure, residual_figure, trace_figure
from gonio.report.fit_report import FIGURES, write_report

from .synthetic import in_plane_geometry, synthetic_dataset


def _with_out_of_plane(data: Dataset) -> Dataset:
    extra = 8
    theta_r = np.linspace(5.0, 75.0, extra)
    return Dataset(
        np.r_[data.theta_i, np.full(extra, 45.0)], np.r_[data.phi_i, np.zeros(extra)],
        np.r_[data.theta_r, theta_r], np.r_[data.phi_r, np.full(extra, 90.0)],
        np.r_[data.value, np.full(extra, 0.2)], np.r_[data.sigma, np.full(extra, 0.01)], label="mixed",
    )


def _off_plane_geometry(theta_i: float, phi_i: float, offset: float):
    """(theta_i, phi_i, theta_r, phi_r) [deg] of a sweep from the normal at phi_r = phi_i + offset."""
    theta_r = np.arange(0.0, 86.0, 5.0)
    return np.broadcast_arrays(theta_i, phi_i, theta_r, phi_i + offset)


def _demo_like_dataset() -> Dataset:
    """Oren & Nayar Fig 16 in-plane sweeps (theta_i = 30, 45, 60 deg) plus two Fig 19 off-plane sweeps."""
    parts = [in_plane_geometry(), _off_plane_geometry(60.0, -45.0, 45.0), _off_plane_geometry(75.0, -60.0, 60.0)]
    geometry = [np.concatenate(angles) for angles in zip(*parts)]
    return synthetic_dataset("lambert", {"rho": 0.5}, 0.005, geometry=geometry)


def _axes_with_data(fig) -> list:
    return [ax for ax in fig.axes if ax.lines or ax.collections]


def test_data_figure_draws_each_incidence_once_in_its_plane():
    data = _demo_like_dataset()
    fig = data_figure(fit(data, "lambert", mcmc=False))
    sources, _ = data.incidences()
    assert len(sources) == 5
    assert len(_axes_with_data(fig)) == len(fig.axes) == len(sources)  # no empty "no ... data" panels
    # no "no ... data" notes; the only texts name the azimuth of a one-azimuth sweep
    assert all(text.get_text().startswith("phi_r - phi_i = ") for ax in fig.axes for text in ax.texts)
    titles = [ax.get_title() for ax in fig.axes]
    for theta_i, phi_i in sources:
        assert sum(f"theta_i = {theta_i:g} deg, phi_i = {phi_i:g} deg" in title for title in titles) == 1
    x_labels = {ax.get_title(): ax.get_xlabel() for ax in fig.axes}
    assert all("signed viewing angle" in x_labels[f"theta_i = {t:g} deg, phi_i = 0 deg"] for t in (30, 45, 60))
    assert x_labels["theta_i = 60 deg, phi_i = -45 deg"] == "viewing angle theta_r [deg]"
    assert x_labels["theta_i = 75 deg, phi_i = -60 deg"] == "viewing angle theta_r [deg]"
    for ax in fig.axes:  # an off-plane panel names its azimuths: a legend, or one text for one azimuth
        if ax.get_xlabel() == "viewing angle theta_r [deg]":
            assert (ax.get_legend() is None) == (len(ax.texts) == 1)


def test_data_figure_puts_both_planes_of_one_incidence_side_by_side():
    data = _with_out_of_plane(synthetic_dataset("lambert", {"rho": 0.5}, 0.005))
    fig = data_figure(fit(data, "lambert", mcmc=False))
    assert len(_axes_with_data(fig)) == len(fig.axes) == 4  # 30 and 60 deg in plane; 45 deg in both planes
    both = [ax for ax in fig.axes if ax.get_title().startswith("theta_i = 45 deg")]
    assert [ax.get_title() for ax in both] == ["theta_i = 45 deg, in plane", "theta_i = 45 deg, out of plane"]
    in_plane, off_plane = (ax.get_subplotspec() for ax in both)
    assert in_plane.rowspan == off_plane.rowspan and off_plane.colspan.start == in_plane.colspan.stop


def test_report_is_one_self_contained_html_file(tmp_path):
    data = _with_out_of_plane(synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.005, seed=1))
    result = fit(data, "minnaert", n_walkers=8, tau_multiple=10.0, rhat_limit=1.05)
    result.save(tmp_path)
    html_path = write_report(tmp_path)
    text = html_path.read_text()
    for filename, title, *_ in FIGURES:
        assert (tmp_path / filename).stat().st_size > 10_000  # a real picture, not an empty canvas
        assert f"<h2>{title}</h2>" in text
    sources = re.findall(r"src=['\"]([^'\"]*)['\"]", text)
    assert len(sources) == len(FIGURES)
    assert all(s.startswith("data:image/png;base64,") for s in sources)
    assert "href=" not in text  # no external references of any kind
    assert "Diagnostics" in text and "reduced chi-square" in text


def test_report_of_a_least_squares_only_fit(tmp_path):
    data = synthetic_dataset("lambert", dict(rho=0.5), 0.005)
    write_report(fit(data, "lambert", mcmc=False), tmp_path)
    text = (tmp_path / "report.html").read_text()
    assert "least squares only, no MCMC" in text
    assert (tmp_path / "fit-corner.png").exists() and "<h2>Posterior</h2>" in text


def test_cli_fit_then_report(tmp_path, capsys):
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.005, seed=2)
    csv = data.to_csv(tmp_path / "plaster.csv")
    code = main(["fit", str(csv), "--model", "minnaert", "--walkers", "8", "--max-steps", "400", "--quiet"])
    assert code == 3  # documented exit status: chain not converged
    out, err = capsys.readouterr()
    assert "[[Variables]]" in out
    folder = tmp_path / "plaster.fit-minnaert"
    assert (folder / "result.json").exists()
    # 400 steps cannot reach 50 tau: the CLI must say so loudly.
    assert "did NOT converge" in err
    assert main(["report", str(folder)]) == 0
    assert (folder / "report.html").exists()


def test_cli_errors_are_one_line_messages(tmp_path, capsys):
    data = synthetic_dataset("lambert", dict(rho=0.5), 0.005)
    csv = data.to_csv(tmp_path / "d.csv")
    assert main(["fit", str(csv), "--model", "lambert", "--fix", "rho=2", "--no-mcmc"]) == 2
    assert "parameter rho = 2" in capsys.readouterr().err
    assert main(["fit", str(csv), "--model", "lambert", "--fix", "rho"]) == 2
    assert "expected NAME=VALUE" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "missing")]) == 2
    assert "no result.json" in capsys.readouterr().err


def test_cli_compares_models(tmp_path, capsys):
    data = synthetic_dataset("lambert", dict(rho=0.5), 0.003, seed=8)
    csv = data.to_csv(tmp_path / "d.csv")
    assert main(["fit", str(csv), "--model", "lambert", "--model", "minnaert"]) == 0
    assert "chosen: lambert" in capsys.readouterr().out


def test_cli_fit_reads_a_recording_folder(tmp_path, capsys, monkeypatch):
    # The acquisition layer reduces a recording to datasets; 'gonio fit FOLDER' fits the
    # normalised radiance when asked (the reduction itself is tested with acquisition).
    import gonio.acquisition as acquisition

    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7, scale=40.0), 0.01, quantity="radiance", relative=True)
    reduced = acquisition.Reduced(
        theta_i=data.theta_i, phi_i=data.phi_i, theta_r=data.theta_r, phi_r=data.phi_r,
        view=data.signed_view, radiance=data.value, radiance_sigma=data.sigma, repeats=np.ones(data.n, int),
        reference_irradiance=None, reference_irradiance_sigma=None, label="recorded",
    )
    folder = tmp_path / "recording"
    folder.mkdir()
    import gonio.analysis
    import gonio.reduction

    monkeypatch.setattr(gonio.reduction, "reduce_recording", lambda path, **options: reduced)
    monkeypatch.setattr(gonio.analysis, "recording_notes", lambda folder, quantity: [])
    assert main(["fit", str(folder), "--model", "minnaert", "--no-mcmc", "--quiet"]) == 0
    result = FitResult.load(tmp_path / "recording.fit-minnaert")
    assert result.dataset.quantity == "normalised_radiance" and result.dataset.label == "recorded"
    assert result.least_squares.values["k"] == pytest.approx(0.7, abs=0.02)


# ------------------------------------------------ figure cost independent of the incidences
def _random_incidences(n: int, seed: int = 3) -> Dataset:
    """``n`` Minnaert measurements, each at an incidence of its own (the worst case for
    drawing per incidence: image-based data such as CUReT)."""
    rng = np.random.default_rng(seed)
    geometry = (rng.uniform(0, 80, n), rng.uniform(-180, 180, n), rng.uniform(0, 80, n), rng.uniform(-180, 180, n))
    return synthetic_dataset("minnaert", {"rho": 0.6, "k": 0.7}, 0.005, geometry=geometry)


@pytest.fixture(scope="module")
def sampled_fits():
    """MCMC fits of 12 and 60 measurements at as many incidences (short chains)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # a short chain is enough to draw
        return {n: fit(_random_incidences(n), "minnaert", n_walkers=8, max_steps=300, tau_multiple=5.0,
                       rhat_limit=1.2) for n in (12, 60)}


def _artists(fig) -> int:
    return sum(len(ax.lines) + len(ax.collections) + len(ax.patches) for ax in fig.axes)


def test_geometry_and_residual_figures_draw_a_fixed_number_of_artists(sampled_fits):
    # One scatter of views and one of sources, one or two of residuals, whatever the
    # number of incidences (one artist per incidence made a 10,000-point report take minutes).
    for make in (geometry_figure, residual_figure):
        assert _artists(make(sampled_fits[12])) == _artists(make(sampled_fits[60]))
    views, stars = geometry_figure(sampled_fits[60]).axes[0].collections
    assert len(views.get_offsets()) == 60 and len(stars.get_offsets()) == 60


def test_few_incidences_get_a_colour_and_legend_entry_each_many_a_colour_bar():
    few = fit(_demo_like_dataset(), "lambert", mcmc=False)
    fig = geometry_figure(few)
    labels = fig.axes[0].get_legend_handles_labels()[1] + [t.get_text() for t in fig.axes[0].get_legend().texts]
    assert sum(label.startswith("views, theta_i = ") for label in set(labels)) == 5
    views = fig.axes[0].collections[0]
    # each view in its incidence's colour of the cycle (C0..C4), ordered by incidence
    _, index = few.dataset.incidences()
    order = np.argsort(index, kind="stable")
    np.testing.assert_allclose(views.get_edgecolors(), to_rgba_array([f"C{k}" for k in index[order]]))
    assert len(views.get_facecolors()) == 0  # hollow rings: coincident views of every incidence show
    assert len(set(views.get_sizes())) == 5  # one ring size per incidence
    assert len(fig.axes) == 1
    # residuals: one panel per incidence, then measured against model; no colour bar
    axes = residual_figure(few).axes
    assert len(axes) == 6 and "Measured against model" in axes[-1].get_title()
    assert [ax.get_title().startswith("theta_i = ") for ax in axes[:5]] == [True] * 5
    many = fit(_random_incidences(40), "minnaert", mcmc=False)
    fig = geometry_figure(many)
    assert len(fig.axes) == 2 and "theta_i" in fig.axes[1].get_ylabel()  # the colour bar
    fig = residual_figure(many)
    assert len(fig.axes) == 3 and "theta_i" in fig.axes[1].get_ylabel()  # residuals, colour bar, measured


def test_data_figure_bands_come_from_one_draw_set_equal_to_per_series_bands(sampled_fits, monkeypatch):
    from gonio.report import fit_figures

    result = sampled_fits[12]
    calls = []
    original = FitResult.posterior_predictive

    def counting(self, *args, **kwargs):
        calls.append(np.broadcast(*args[:4]).shape)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(FitResult, "posterior_predictive", counting)
    fig = data_figure(result, n_draws=50)
    assert len(calls) == 1  # every band of every panel from one set of posterior draws
    # The reference path: each series' band on its own, with the same draws (same seed).
    panels = [panel for group in fit_figures._data_panels(result) for panel in group]
    series = [one for panel in panels for one in fit_figures._off_plane_series(result.dataset, panel)[0]]
    assert len(series) == len(fig.axes) == fit_figures.MAX_INCIDENCE_PANELS  # 12 incidences, 8 drawn
    for ax, one in zip(fig.axes, series):
        alone = original(result, *one.geometry, n_draws=50)
        np.testing.assert_allclose(ax.lines[0].get_ydata(), alone[2], rtol=1e-12, atol=0)  # the median line
        np.testing.assert_allclose(ax.lines[0].get_xdata(), one.x, rtol=0, atol=0)


def test_trace_figure_draws_one_collection_per_panel_and_survives_minus_infinity(sampled_fits):
    result = sampled_fits[12]
    m = result.mcmc
    m.log_prob[5, 0] = -np.inf  # a walker proposed outside the support at one step
    fig = trace_figure(result)
    for ax in fig.axes:
        (lines,) = ax.collections
        assert len(lines.get_segments()) == min(m.n_walkers, MAX_TRACE_WALKERS)
        assert max(len(s) for s in lines.get_segments()) <= MAX_TRACE_POINTS
        assert np.all(np.isfinite(ax.get_ylim()))
    fig.savefig(io.BytesIO(), format="png")


def test_a_large_ensemble_is_traced_by_a_subset_that_keeps_a_stuck_walker():
    from gonio.report.fit_figures import _shown_walkers, _trace_limits

    rng = np.random.default_rng(0)
    log_prob = rng.normal(-10.0, 1.0, size=(500, 256))
    log_prob[:, 201] -= 40.0  # one walker stuck in a poor region for the whole chain
    shown = _shown_walkers(log_prob, burn_in=50)
    assert len(shown) == MAX_TRACE_WALKERS and 201 in shown
    assert shown[0] == 0 and shown[-1] == 255 and np.all(np.diff(shown) > 0)
    assert np.array_equal(_shown_walkers(log_prob[:, :20], burn_in=50), np.arange(20))
    # The vertical range follows the chain after burn-in, not a far start ...
    values = rng.normal(0.9, 1e-3, size=(500, 32))
    values[:10] = 0.1  # walkers start far out during burn-in
    low, high = _trace_limits(values, np.arange(500) >= 50)
    assert 0.89 < low < 0.9 < high < 0.91
    # ... but keeps a walker that stays apart for the whole chain in view.
    values[:, 7] = 0.8
    low, _ = _trace_limits(values, np.arange(500) >= 50)
    assert low < 0.8
