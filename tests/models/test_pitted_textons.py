"""Textons, radiance histograms and textures (Koenderink et al. 1999, section 4.2, Figs 13-14)."""
from __future__ import annotations

import numpy as np
import pytest

import gonio
from gonio.cli import main
from gonio.models.pitted.interreflection import diffuse_radiance
from gonio.models.pitted.textons import (
    FIGURE_13_GEOMETRIES, place_pits, radiance_histogram, render_texton, render_texture,
)


def test_fig14_shadow_mode_sits_at_the_diffuse_radiance_of_eq12():
    # section 4.2: (alpha, beta, eps) = (30, 30, 180) is strongly bimodal; the cast-shadow
    # mode is a narrow peak at the diffuse radiance (eq 12 times cos alpha) because the
    # diffuse irradiance is the same over the whole cavity
    rho, psi = 0.8, 90.0
    texton = render_texton(30.0, 30.0, 180.0, rho=rho, psi=psi, pixels=160)
    values = texton.pit_radiances
    shadow = float(diffuse_radiance(rho, psi)) * np.cos(np.radians(30.0))
    assert texton.diffuse_radiance == pytest.approx(shadow, rel=1e-14)
    assert values.min() == pytest.approx(shadow, rel=1e-12)  # nothing darker than the shadow
    in_shadow = np.isclose(values, shadow, rtol=1e-12)
    assert 0.2 < in_shadow.mean() < 0.8  # bimodal: a large share in the narrow mode, not all
    density, edges = radiance_histogram(values, bins=64)
    peak = int(np.argmax(density))
    assert edges[peak] <= shadow <= edges[peak + 1]  # the tallest bin holds eq 12


def test_only_the_shadow_is_seen_in_oblique_forward_view():
    # Fig 13, (60, 60, 180): the texton degenerates to a uniform grey blob at eq 12, not black
    texton = render_texton(60.0, 60.0, 180.0, rho=1.0, psi=90.0, pixels=64)
    np.testing.assert_allclose(texton.pit_radiances, texton.diffuse_radiance, rtol=1e-12)
    assert texton.diffuse_radiance > 0.0


def test_normal_incidence_texton_is_light_in_the_centre():
    # Fig 13 (0, 0): light centre ((rho/pi)(1 + H_diff), lighter than the plane for rho = 1)
    # and no pixel darker than the diffuse radiance
    texton = render_texton(0.0, 0.0, 0.0, rho=1.0, psi=90.0, pixels=65)
    centre = texton.radiance[32, 32]
    assert centre == pytest.approx(1.5 / np.pi, rel=1e-12)
    assert centre > texton.plane_radiance
    assert texton.pit_radiances.min() >= texton.diffuse_radiance


@pytest.mark.parametrize("geometry,psi", [((30.0, 30.0, 180.0), 90.0), ((45.0, 20.0, 60.0), 40.0)])
def test_texton_mean_radiance_is_the_brdf_times_cos_alpha(geometry, psi):
    # pixels sample the orifice uniformly in projected area (section 4.1), so the pit's
    # mean pixel radiance is the pit BRDF times cos(alpha); at 300 px across the rim
    # discretisation error measured ~6e-5, tolerance 5e-4
    alpha, beta, eps = geometry
    texton = render_texton(alpha, beta, eps, rho=0.7, psi=psi, pixels=300, margin=1.0)
    brdf = float(gonio.brdf("pitted", alpha, 0.0, beta, eps, rho=0.7, psi=psi, coverage=1.0))
    assert texton.pit_radiances.mean() == pytest.approx(brdf * np.cos(np.radians(alpha)), rel=5e-4)


def test_texture_mean_tends_to_the_brdf_of_its_coverage():
    # a tiled texture is a pitted surface: its mean radiance is (BRDF at the placed coverage)
    # x cos(alpha); 512 px and ~60 pits: measured -0.2 % (pixelised rims), tolerance 1 %
    alpha, beta, eps, rho = 30.0, 30.0, 180.0, 0.9
    texture = render_texture(alpha, beta, eps, rho=rho, psi=90.0, coverage=0.5, pixels=512, seed=2)
    brdf = float(gonio.brdf("pitted", alpha, 0.0, beta, eps, rho=rho, psi=90.0, coverage=texture.coverage))
    assert texture.radiance.mean() == pytest.approx(brdf * np.cos(np.radians(alpha)), rel=0.01)
    assert 0.4 < texture.coverage <= 0.55


def test_placed_pits_do_not_overlap_and_reach_modest_coverage():
    centres, diameters = place_pits(0.4, size=1.0, mean_diameter=0.06, spread=0.4, seed=5)
    delta = centres[:, None, :] - centres[None, :, :]
    delta -= np.round(delta)
    distance = np.hypot(delta[..., 0], delta[..., 1]) + np.eye(len(centres)) * 10
    assert np.all(distance >= 0.5 * (diameters[:, None] + diameters[None, :]) - 1e-12)
    assert np.sum(np.pi * diameters**2 / 4) == pytest.approx(0.4, abs=0.03)


def test_figure_13_layout_has_the_thirteen_listed_triples():
    cells = [g for row in FIGURE_13_GEOMETRIES for g in row if g is not None]
    assert len(cells) == 13
    assert (30.0, 30.0, 180.0) in cells and (60.0, 60.0, 0.0) in cells


def test_bad_input_names_the_parameter():
    with pytest.raises(ValueError, match="psi = 0"):
        render_texton(0.0, 0.0, 0.0, psi=0.0)
    with pytest.raises(ValueError, match="coverage = 1.5"):
        render_texture(0.0, 0.0, 0.0, coverage=1.5)
    with pytest.raises(ValueError, match="theta_r = 90"):
        render_texton(0.0, 90.0, 0.0)


def test_cli_textons_writes_the_figures(tmp_path, capsys):
    # `gonio textons --out DIR` reproduces the Fig 13-14 layout as PNG files
    assert main(["textons", "--out", str(tmp_path), "--pixels", "24"]) == 0
    for name in ("textons.png", "histograms.png", "texture.png"):
        assert (tmp_path / name).stat().st_size > 1000
    assert main(["textons", "--out", str(tmp_path), "--psi", "120"]) == 2
    assert "psi = 120" in capsys.readouterr().err
