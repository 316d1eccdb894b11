"""popbal: the population-balance / Stokes settling model sharing the droplet laws of :mod:`settler.physics`.

Under construction (issue: popbal).
"""
