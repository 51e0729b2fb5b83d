"""Optimising Gaussians, shared by fitting and texture transfer: Adam over scene tensors with frozen rows,
adaptive density control, and the L1 + D-SSIM reconstruction loss."""
