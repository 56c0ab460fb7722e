"""Data-driven characterization of the human (paper Sec. II and IV).

Owns: motion-capture readers and processing, the synthetic subject, Bezier regression,
PHZD gait optimization, playback socket-force estimation and the force tube.
Depends only on :mod:`hp_model`.

Motion capture (issue 3):

- :mod:`.mocap_take` (in-memory take, :class:`MocapError`), :mod:`.motive_csv`,
  :mod:`.c3d_io` (readers and writers), :mod:`.sagittal` (projection, quaternion pitch),
  :mod:`.mocap_mapping` (limb mapping and options, TOML);
- :mod:`.limb_angles` (pitch sources, gap filling, low-pass), :mod:`.joint_centres`
  (the paper's least squares), :mod:`.step_segmentation` (delta_p_hip turns, tau, double
  support), :mod:`.mocap_pipeline` (a take -> joint trajectories and steps);
- :mod:`.steps_artifact` (the versioned steps file), :mod:`.mocap_report` (QA report and
  figures), :mod:`.mocap_files` (file-level entry point);
- :mod:`.synthetic_gait`, :mod:`.synthetic_subject` (ground-truth subject).
"""
