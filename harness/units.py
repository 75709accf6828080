"""Unit conversions shared by every stage."""

GF_TO_N = 9.80665e-3  # one gram-force in newtons
