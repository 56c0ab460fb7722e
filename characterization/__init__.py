"""Data-driven characterization of the human (paper Sec. II and IV).

Owns: motion-capture readers and processing, the synthetic subject, Bezier regression,
PHZD gait optimization, playback socket-force estimation and the force tube.
Depends only on :mod:`hp_model`.
"""
