"""The Blender edge: conversions between bpy data and ``core`` types, and registration helpers.

``splats`` turns ``SplatArrays`` (core's numpy scene) into a point-cloud object and back; ``transform`` is the
(bpy-free, numpy-only) maths for baking an object transform into Gaussians. Operators and panels
use these; ``core`` never imports from here.
"""
