"""The simulated test rig around the firmware: its configuration and the pilot's RC, the
firmware processes and the sim link, the lockstep driver that flies a plant with them,
injected faults, and the free-running board that stands in for a Teensy on a serial port.
"""
