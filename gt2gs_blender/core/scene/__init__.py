"""Gaussian scenes and their files: ``GaussianScene`` (torch) and PLY read/write (numpy only, so Blender
can import and export splats without torch). New splat formats live here."""
