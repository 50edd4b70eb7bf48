"""The ``heliquad`` program as a process: how it takes signals, and child processes run side
by side as one command. Imported by every layer that runs for long, so it imports nothing
of the host tool's own.
"""
