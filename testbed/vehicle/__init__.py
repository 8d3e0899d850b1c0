"""vehicle: physics, thrusters, allocation, control and sensors of the simulated ROV.

Its architecture is the ECS paper's (README, "Architecture"; docs/vehicle.md).

Modules (import them directly; this package imports nothing, so ``import testbed.vehicle``
stays cheap and never loads pybullet):

* ``hydrodynamics``: Fossen's 6-DOF model (``HydroModel``, ``load_model``) and its equation of
  motion, written once and compiled by numba (``fossen_acceleration``); ``water_current``: the
  current (``WaterCurrent``, ``CurrentProcess``).
* ``physics``: the plant (``Physics``), the only module in the project that imports pybullet;
  it hands pybullet to ``hull_body``, ``arm_body``, ``arm_coupling``, ``pool_scene``
  (``PoolScene``) and ``scenery_render``; ``pybullet_frames`` converts NED ↔ pybullet's z-up
  frames, ``body_state`` holds its ``BodyState``, ``open_loop`` runs it open loop
  (``simulate_open_loop``).
* ``thrusters``, ``allocation``, ``control``, ``sensors`` and the assembled vehicle
  (``vehicle``, built from its configuration by ``assembly``); the per-frame arithmetic of the
  plant, the thrust chain, the closed loops and the navigation filter is compiled by numba in
  ``plant_kernels``, ``thrust_kernels``, ``control_kernels`` and ``filter_kernels``.

Rotations (quaternions, Euler angles, rotation matrices) are ``testbed.common.geometry``.
"""
