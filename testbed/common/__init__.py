"""The shared library of both nodes (the ECS paper's ``common``).

What the operator and the vehicle must agree on lives here: the component types they replicate
(with stable ids and owners) and the link codecs that carry them — the full change-set codec for
wideband links and the compact teleop codec for narrow ones. Imports: ``ecs``, ``protocol``,
``config``, numpy; never ``vehicle`` or ``operator``.
"""
