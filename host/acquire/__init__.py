"""Acquisition: talking to the firmware and recording what it does. The connection under
the telemetry link, the link itself (MAVLink), the sessions a sweep drives (the firmware
in the loop, or a board's port), sweeps and single experiments with their amplitude
design and multisine signals, the parameter protocol, and serial logging.
"""
