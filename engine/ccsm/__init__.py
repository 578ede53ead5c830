"""The paper's method (Qian et al. 2021): target, correspondence resampling, the continuous changing surface,
slicing at t, similarity, the scale -> t regression, the crossing repair and the build of a whole set.

Nothing here reads files, cuts tiles or touches the store (an import-linter contract checks it).
"""
