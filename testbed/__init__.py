"""testbed: a network-simulated teleoperation testbed for underwater ROVs.

Subpackages follow the layering in the README (protocol and ecs at the bottom; scenario,
runner and cli at the top). Importing this package imports nothing heavy.
"""

__version__ = "0.1.0"
