"""The files the host tool reads and writes (docs/file-formats.md): their formats, schemas
and atomic writes, the telemetry log, gains files, and the published facts of the paper's
vehicle the tools compare against. The floor of the host tool: it imports only the
shared base (heliquad.sim.base).
"""
