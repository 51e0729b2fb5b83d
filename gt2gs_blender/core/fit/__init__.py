"""3DGS fitting to posed photographs (random or COLMAP initialisation, the LLFF reconstruction protocol)."""
