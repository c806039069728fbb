"""Physics kernels: pure functions of SI floats, compiled with numba where hot.

- :mod:`skidmc.physics.mechanics`: the plastic impact and sliding of the hemispherical billet
  (report Eqs. 1-10).
- :mod:`skidmc.physics.thermal`: the implicit two-media heat-conduction kernel with Arrhenius
  decomposition and melting of HMX (Eqs. 11-16).
- :mod:`skidmc.physics.fast`: the reduced (fast-tier) model's compiled kernels.

This layer imports nothing from the rest of skidmc but :mod:`skidmc.errors`.
"""

__all__: list[str] = []
