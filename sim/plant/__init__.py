"""The plants the firmware flies in simulation: the 6-DoF vehicle (its parameters in
``vehicle.toml``), the per-axis transfer-function plant and Dryden turbulence.
"""
