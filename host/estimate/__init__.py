"""Estimation: from records to numbers. Frequency-response points (the FSF and the baseline
estimators), transfer-function fits to them, how well a model matches its points, and
the set of fitted models with a recommendation.
"""
