"""The ``heliquad`` command line: the console script's entry, the parser and the one place
errors become exit codes, and the options several commands share.
"""
