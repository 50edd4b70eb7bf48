"""heliquad's lower layer: the shared base both sides import (``base``), and what stands in
for the rig when there is no hardware: the plants (``plant``), the MPU6050 (``sensor``),
the test rig around the firmware (``rig``) and the emulated Teensy 3.5 chip (``chip``).
Nothing here imports the host tool (docs/architecture.md)."""

__all__ = []
