"""The ``hpcosim`` command line, closed-loop scenarios, co-simulation master, recorder,
replay, refit, experiments, reports and sweeps.  The only package allowed to import all
the others.
"""
