"""numba kernels: the hot loops of the toolkit, and nothing else.

Kernels take arrays and scalars, return arrays, never do I/O, never draw random numbers (noise is
drawn by the Python layer with one seeded generator and passed in), and hold no global state.
"""
