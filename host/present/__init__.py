"""Presentation: plots and the HTML report. These draw results computed elsewhere.
"""
