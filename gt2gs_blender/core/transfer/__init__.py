"""The GT²-GS method: settings and presets, the texture bank, colour transfer, the GT² loss, AFCM,
stylise/correct phases, views, the pipeline (``pipeline.transfer``), its caches, skips and metrics."""
