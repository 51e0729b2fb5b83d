"""Feature networks: VGG specifications, weight resolution (with a reported fallback), the feature
extractor, and LPIPS for the consistency metrics."""
