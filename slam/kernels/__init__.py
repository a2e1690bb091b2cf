"""numba kernels: the hot loops of the toolkit, and nothing else.

Kernels take arrays and scalars, return arrays, never do I/O, never draw random numbers (noise is
drawn by the Python layer with one seeded generator and passed in), and hold no global state
(the one module-level object, :mod:`slam.kernels.threads`' pool of threads that runs serial
kernels side by side, holds nothing a result depends on).
"""
