"""fulldem: the coupled CFD-DEM engine (slag on a grid, every matte droplet a soft sphere).

Under construction (issue: fulldem engine). The droplet laws it uses live in :mod:`settler.physics`.
"""
