"""``python -m gonio`` runs the command line."""
from gonio.cli import run

run()
