"""Identification from a flight log: readers, the estimator, windows from the excitation, results, the config edited."""
