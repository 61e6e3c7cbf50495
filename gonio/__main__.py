"""``python -m gonio`` runs the command line."""
import sys

from gonio.cli import main

sys.exit(main())
