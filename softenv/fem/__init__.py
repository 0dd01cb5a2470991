"""Finite-element tongue (the ``fem`` extra, FElupe): :mod:`softenv.fem.mesh` (the ball's hexahedra,
base cap and surface; numpy only) and :mod:`softenv.fem.tongue` (the nearly incompressible
neo-Hookean model, its load ramps and Newton solve). Only data generation imports this package."""
