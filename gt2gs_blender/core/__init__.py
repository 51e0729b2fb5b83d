"""The bpy-free engine: scene I/O, cameras, rasterizer, texture transfer. Never imports bpy."""
