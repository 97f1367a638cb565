"""Measuring code shared by ``benchmarks/*.py`` and ``couplekit bench``: the arrays a simulation actually
allocated (:mod:`.memory`), the bytes each stage moves and the bandwidth projection (:mod:`.traffic`), paper
000's Table 1 row by row (:mod:`.table1`), the price of each effect (:mod:`.effects`) and the runner behind
``couplekit bench`` (:mod:`.runner`)."""
