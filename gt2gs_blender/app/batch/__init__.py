"""Many transfers at once: a manifest of jobs (``manifest``), each run into its own folder (``job``), on a Dask
cluster (``cluster``: the only module that imports dask), summed up in a table and a contact sheet (``summary``,
``sheet``). ``python -m gt2gs_blender batch MANIFEST`` and ``cluster.run_batch`` are its two faces."""
