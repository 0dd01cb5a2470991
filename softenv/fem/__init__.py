"""Finite-element tongue (the ``fem`` extra, FElupe): :mod:`softenv.fem.mesh` (the ball's hexahedra,
base cap, inverse map and interpolation; numpy only), :mod:`softenv.fem.tongue` (the nearly
incompressible neo-Hookean model, its load ramps and Newton solve), :mod:`softenv.fem.verification`
(closed forms) and :mod:`softenv.fem.data` (FE data sets: ramps in parallel, cached one by one).
Only data generation imports this package."""
