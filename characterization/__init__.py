"""Data-driven characterization of the human (paper Sec. II and IV).

Owns: motion-capture readers and processing, the synthetic subject, Bezier regression,
PHZD gait optimization, playback socket-force estimation and the force tube, in three
subpackages whose imports point one way (tube -> gait -> mocap -> hp_model):

- :mod:`.mocap` (Sec. II): readers (:mod:`.mocap.motive_csv`, :mod:`.mocap.c3d_io`,
  :mod:`.mocap.trc_io`), the in-memory take (:mod:`.mocap.take`), the mapping
  (:mod:`.mocap.mapping`), checks, limb pitches, joint centres, step segmentation,
  :mod:`.mocap.pipeline` (a take -> joint trajectories and steps), the steps artifact, the QA
  report, :mod:`.mocap.inspection` and the synthetic subject;
- :mod:`.gait` (Sec. IV-A): Bezier regression, PHZD gait optimization, verification, figures;
- :mod:`.tube` (Sec. IV-B): playback of the recorded steps, the force-tube fit and the
  model-error bound.

Depends only on :mod:`hp_model`.
"""
