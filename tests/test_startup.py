"""Start-up: what ``import gonio`` and the command line load (behaviour, not wall time).

The heavy libraries (scipy, matplotlib, numba, emcee, arviz and what they pull in) load
where they are used, so ``import gonio`` costs little more than ``import numpy``; the
time itself is measured by benchmarks/bench_startup.py, never asserted here. Each check
runs in a fresh interpreter: this test process has imported most of them already.
"""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

#: Libraries that ``import gonio`` must not load (top-level package names).
HEAVY = ("scipy", "matplotlib", "numba", "emcee", "arviz", "pandas", "xarray")


def _loaded_after(code: str) -> list[str]:
    """The HEAVY packages present in ``sys.modules`` after running ``code`` in a new interpreter."""
    probe = (f"{code}\nimport json, sys\n"
             f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}} & set({list(HEAVY)!r}))))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_probe_sees_a_heavy_import():
    # The probe itself must be able to fail: importing scipy directly is seen.
    assert _loaded_after("import gonio, scipy.special") == ["scipy"]


def test_import_gonio_loads_no_heavy_library():
    assert _loaded_after("import gonio") == []


def test_public_api_works_without_heavy_libraries():
    code = ("import gonio\n"
            "assert gonio.__version__\n"
            "assert 'oren-nayar' in gonio.models.available()\n"
            "assert float(gonio.brdf('oren-nayar', 45, 0, 30, 180, rho=0.9, sigma=30)) > 0\n"
            "from gonio import __version__, geometry, radiometry")
    assert _loaded_after(code) == []


@pytest.mark.parametrize("module", ["gonio.geometry", "gonio.radiometry", "gonio.zernike",
                                    "gonio.models.chandrasekhar", "gonio.models.kvd", "gonio.protocols",
                                    "gonio.surfaces"])
def test_light_modules_load_no_heavy_library(module):
    assert _loaded_after(f"import {module}") == []


def test_command_line_parser_loads_no_heavy_library():
    # `gonio --help` and the parsing of every sub-command's arguments stay light; the
    # sub-commands import what they use when they run.
    assert _loaded_after("from gonio.cli import build_parser\nbuild_parser()") == []


def test_command_line_parser_reads_no_version_and_no_acquisition_code():
    # Every gonio command builds every sub-command's parser: the package metadata (for
    # --version) and the acquisition and protocol modules (for gonio run and plan) are
    # loaded only by what uses them.
    probe = ("from gonio.cli import build_parser\nbuild_parser()\nimport sys\n"
             "print([m for m in ('importlib.metadata', 'gonio.acquisition', 'gonio.protocols') if m in sys.modules])")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=True)
    assert done.stdout.strip() == "[]"


def test_lazily_imported_functions_still_work_in_a_fresh_interpreter():
    # Each function imports its scipy routine on first call (no NameError, right value).
    code = ("from gonio.zernike import zernike_radial_of_cos\n"
            "assert float(zernike_radial_of_cos(2, 0, 1.0)) == -1.0\n"
            "from gonio.models.chandrasekhar import h_function\n"
            "assert 1.0 < float(h_function(0.5, 0.9)) < 3.0\n")
    assert _loaded_after(code) == ["scipy"]


def test_reading_and_reporting_a_fit_loads_no_sampler():
    # `gonio report` reads a saved fit and draws it: neither emcee (which loads
    # scipy.stats) nor scipy.optimize, numba or ArviZ is needed for that.
    loaded = _loaded_after("import gonio.fitting.results, gonio.report.fit_report, gonio.cli.report\n"
                           "import sys\nassert 'scipy.optimize' not in sys.modules, 'scipy.optimize'")
    assert loaded == ["matplotlib"]


def test_a_least_squares_fit_loads_no_scipy_stats():
    # Its goodness-of-fit p-value comes from scipy.special (gonio.fitting.adequacy).
    code = ("import sys, numpy as np\n"
            "from gonio.fitting import Dataset, fit\n"
            "theta = np.arange(0.0, 80.0, 5.0)\n"
            "data = Dataset(30.0, 0.0, theta, 0.0, 0.16 + 0.001 * np.cos(np.radians(theta)), 0.002)\n"
            "assert fit(data, 'lambert', mcmc=False).adequacy.chi2_p > 0\n"
            "assert 'scipy.stats' not in sys.modules, 'scipy.stats'\n")
    assert _loaded_after(code) == ["scipy"]


def test_a_fit_with_mcmc_and_its_files_loads_neither_arviz_nor_xarray():
    # R-hat and ESS come from ArviZ's numpy core and posterior.nc is written with h5netcdf:
    # `gonio fit` does not pay for arviz, xarray, pandas or numba (1 to 3 s of start-up).
    code = ("import tempfile, numpy as np\n"
            "from gonio.fitting import Dataset, fit\n"
            "theta = np.arange(0.0, 80.0, 5.0)\n"
            "data = Dataset(30.0, 0.0, theta, 0.0, 0.16 + 0.001 * np.cos(np.radians(theta)), 0.002)\n"
            "result = fit(data, 'lambert', n_walkers=8, max_steps=300, tau_multiple=5.0, rhat_limit=1.2)\n"
            "result.save(tempfile.mkdtemp())\n")
    assert _loaded_after(code) == ["emcee", "scipy"]


def test_fit_with_report_loads_matplotlib_for_the_report_alone(tmp_path):
    # `gonio fit --report` draws the report in its own process, once the fit is saved;
    # again with --overwrite, which first removes the earlier report by name.
    code = ("import numpy as np\n"
            "from gonio.cli import main\n"
            "from gonio.fitting import Dataset\n"
            "theta = np.arange(0.0, 80.0, 5.0)\n"
            "data = Dataset(30.0, 0.0, theta, 0.0, 0.16 + 0.001 * np.cos(np.radians(theta)), 0.002)\n"
            f"csv = data.to_csv({str(tmp_path / 'd.csv')!r})\n"
            "arguments = ['fit', str(csv), '--model', 'lambert', '--walkers', '8', '--max-steps', '300', '--report',\n"
            "             '--quiet', '--rhat-limit', '1.2']\n"
            "main(arguments)\n"
            "assert main(arguments + ['--overwrite', '--seed', '1']) not in (1, 2)  # replaced, no error\n")
    assert _loaded_after(code) == ["emcee", "matplotlib", "scipy"]
    assert (tmp_path / "d.fit-lambert" / "report.html").stat().st_size > 10_000
