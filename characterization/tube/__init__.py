"""The socket-force tube (paper Sec. IV-B): playback of the recorded steps, the tube fit
and the model-error bound."""
