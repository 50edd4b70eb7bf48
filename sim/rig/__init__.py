"""The simulated test rig around the firmware: its configuration and the pilot's RC, the
lockstep driver of the firmware process, injected faults, and the free-running board
that stands in for a Teensy on a serial port.
"""
