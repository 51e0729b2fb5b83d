"""Tests that need the bpy module (Blender 5.0.1 as a Python module); skipped without it."""
