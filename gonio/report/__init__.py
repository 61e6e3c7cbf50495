"""Figures and reports (the only part of gonio that imports matplotlib)."""
