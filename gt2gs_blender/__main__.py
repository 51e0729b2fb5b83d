"""``python -m gt2gs_blender``: the command line (see app/cli/main.py)."""

import sys

from .app.cli.main import main

sys.exit(main())
