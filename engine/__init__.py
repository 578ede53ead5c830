"""ccsm engine: continuous contour generalization with the continuous changing surface model (CCSM).

Pure algorithm code: no web framework, no environment variables. See ``engine.types`` for the meaning of ``t``.
"""
