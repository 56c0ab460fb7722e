"""The ``hpcosim`` command line and everything that runs the closed loop; the only package
allowed to import all the others.  Subpackages, imports pointing one way
(cli -> {sweep, cosim, experiments} -> loop):

- :mod:`.cli`: the ``hpcosim`` verbs (typer), one module per verb group;
- :mod:`.loop`: the one closed loop (plants, links, recorder, ``run_loop``);
- :mod:`.experiments`: scenarios, the paper's Sec. V experiments, diagnosis, report, the
  walker's animation;
- :mod:`.cosim`: the co-simulation master and its MCAP recordings (replay, refit);
- :mod:`.sweep`: robustness sweeps on Dask;
- :mod:`.modes`: the co-simulation and sweep modes.
"""
