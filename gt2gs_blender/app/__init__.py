"""Front ends shared by the command line and the Blender worker: jobs, the CLI, the worker and its
protocol, dependency installation. Imports ``core``; ``core`` never imports this."""
