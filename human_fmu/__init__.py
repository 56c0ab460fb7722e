"""The human side (plant + human-side controller) packaged as an FMI 2.0 co-simulation FMU.

The FMU's C code is generated from the same CasADi definitions as :mod:`hp_model`.
Depends only on :mod:`hp_model`.
"""
