"""benchmarks/calibration.py's options: the true samples of the model-choice study
(``--truths``) and the sample's mesoscale slope in every fit (``--texture-slope``,
docs/calibration.md section 3)."""
from __future__ import annotations

import argparse

import pytest

from tests.conftest import benchmark_script


@pytest.fixture(scope="module")
def calibration():
    return benchmark_script("calibration")


def test_truths_are_chosen_by_key_and_an_unknown_key_is_a_usage_error(calibration, capsys):
    parser = argparse.ArgumentParser()
    assert calibration._chosen_truths(parser, None) == calibration.SELECTION_TRUTHS
    assert [t.key for t in calibration._chosen_truths(parser, "on+ts, lambert")] == ["on+ts", "lambert"]
    with pytest.raises(SystemExit):
        calibration._chosen_truths(parser, "on+ts,glossy")
    assert "unknown key(s) glossy" in capsys.readouterr().err


def test_the_texture_slope_joins_the_rig_errors_on_the_lab_rig_only(calibration, monkeypatch, capsys):
    monkeypatch.setitem(calibration.REALISM, "spec", "lab")
    monkeypatch.setitem(calibration.REALISM, "texture_slope", True)
    assert calibration.rig_errors() == {"alignment": "all,texture_slope", "stray_light": True}
    monkeypatch.setitem(calibration.REALISM, "texture_slope", False)
    assert calibration.rig_errors() == {"alignment": "all", "stray_light": True}
    with pytest.raises(SystemExit):
        calibration.main(["--texture-slope"])
    assert "--texture-slope needs --realism lab" in capsys.readouterr().err
