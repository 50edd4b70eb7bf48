"""The shared base of heliquad, below both the simulator and the host tool: the errors every
layer reports as one line, the generated MAVLink dialect, the fast MAVLink framing, the
reading of a user's files, and where the Teensy image is. It imports nothing else of
heliquad's.
"""
