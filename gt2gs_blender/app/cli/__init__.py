"""The command line, ``python -m gt2gs_blender``: one module per command, ``main`` in ``main.py``."""
