"""Sweeps and Monte Carlo over co-simulations, on Dask."""
