"""Runs that chain the stages: a session's identification (from a sweep's log to points,
models, validation, plots and report).
"""
