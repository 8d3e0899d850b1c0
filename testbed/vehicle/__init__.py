"""vehicle: physics, thrusters, allocation, control and sensors of the simulated ROV (see DESIGN.md)."""
