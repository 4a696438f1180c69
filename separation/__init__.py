"""Direct/global separation with high-frequency illumination (Nayar et al. 2006)."""
