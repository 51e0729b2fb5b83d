"""Cameras: the pinhole ``Camera`` type, loaders for every pose file the tools accept (cameras.json,
LLFF, COLMAP), generated views around a scene, and depth-based warping between views."""
