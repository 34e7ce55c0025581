"""The critical friction coefficient mu^c (SPEC §2): of one cone or pattern, and global.

- critical.py: mu^c of one pattern (`MuC`), the mu^c tasks.
- bracket.py: bisection on feasibility, and the 2D route.
- dinkelbach.py, kkt.py: a 3D pattern's mu^c, and its KKT Newton certificate.
- exact_2d.py: a 2D pattern's mu^c certified in rational arithmetic.
- global_search.py: the least mu at which any pattern is feasible.
- lower_bound.py: a certified lower bound on it (free bodies), which ends that search.
- floor_pattern.py: a pattern whose mu^c meets that bound, by pivots on its certificate.
"""

__all__ = ["critical", "bracket", "dinkelbach", "kkt", "exact_2d", "global_search", "lower_bound",
           "floor_pattern"]
