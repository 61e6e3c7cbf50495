"""Package rules (DESIGN.md, "Layers"): importing drivers defines code only and never
imports gonio; the client drivers do not import gonio either."""
from __future__ import annotations

import subprocess
import sys


def _modules_after(statement: str) -> set[str]:
    code = f"import sys; {statement}; print(' '.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return set(out.stdout.split())


def test_import_drivers_is_cheap():
    loaded = _modules_after("import drivers")
    assert not {m for m in loaded if m.split(".")[0] in ("gonio", "numpy", "serial")}


def test_client_drivers_never_import_gonio():
    loaded = _modules_after("from drivers import Rig; import drivers.ptc")
    assert "drivers.rig" in loaded
    assert not {m for m in loaded if m.split(".")[0] == "gonio"}
