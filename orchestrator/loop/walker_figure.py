"""The walker as a stick figure, drawn alike by the GIF animation
(:mod:`orchestrator.experiments.animation`) and Foxglove's scene
(:mod:`orchestrator.loop.foxglove`): per part, its colour and the chains of the model's
named frames (``model.numeric()["frames"]``) its lines join; the socket-force arrow's scale."""

from __future__ import annotations

FORCE_SCALE = 1500.0  # N per metre of arrow
HUMAN = ("#1f5fa8", (("hip", "l_knee", "l_ankle", "l_heel", "l_toe", "l_ankle"),
                     ("hip", "r_knee")))
IWALK = ("#7f7f7f", (("r_knee", "socket"),))
PROSTHESIS = ("#e07b00", (("socket", "p_knee", "p_ankle", "p_heel", "p_toe", "p_ankle"),))
