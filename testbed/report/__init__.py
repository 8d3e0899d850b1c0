"""Plots of one run and of sweeps, and the closed forms they draw (matplotlib only here)."""
