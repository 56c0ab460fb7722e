"""Prosthesis controllers (robust CLF-QP exact and relaxed, PD, robust-passive, swing),
the controller node process and its CAN port. Depends only on :mod:`hp_model` and
:mod:`bus_schemas`.
"""
