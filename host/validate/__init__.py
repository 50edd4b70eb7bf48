"""Validation of an identified model: the firmware's cascade around it in closed loop, the
simulator's truth a simulated sweep should have found, and a model's replay of the
measured records.
"""
