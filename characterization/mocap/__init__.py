"""Motion capture (paper Sec. II): readers, mapping, checks, limb pitches, joint centres,
step segmentation, the steps artifact, the QA report and the synthetic subject."""
