"""``python -m gt2gs_blender``: the command line (see core/cli.py)."""
import sys

from .core.cli import main

sys.exit(main())
