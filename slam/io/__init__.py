"""Input and output: the dataset registry, loaders into one :class:`~slam.io.log.Log`, file formats.

Loaders never estimate anything; they read, validate and hand over arrays.
"""
