"""Finite-element tongue (the ``fem`` extra, FElupe).

Numpy only (what a scene reads): :mod:`softenv.fem.params` (the FE tongue's parameters) and
:mod:`softenv.fem.scene_data` (an FE scene's data file: its request, checks, the shipped file and
generation on demand). FElupe (data generation only): :mod:`softenv.fem.mesh` (the ball's
hexahedra, base cap, inverse map and interpolation; numpy), :mod:`softenv.fem.tongue` (the nearly
incompressible neo-Hookean model, its load ramps and Newton solve), :mod:`softenv.fem.verification`
(closed forms) and :mod:`softenv.fem.data` (FE data sets: ramps in parallel, cached one by one)."""
