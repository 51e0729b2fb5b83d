"""The bpy-free engine. Never imports bpy or a front end; the library API is ``core.api``.

OpenMP threads (torch's and the C++ rasterizer's) sleep instead of spinning while they wait,
unless the caller chose otherwise: with any other busy process on the machine (Blender's UI, a
second job), spinning threads made renders 5-8x slower (measured on 2 cores), while sleeping costs
little when the machine is idle. This only takes effect when set before torch is first imported.
"""

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
