"""The AMPRO3-style CAN bus of hpcosim, in two parts that a newcomer can change apart:

- :mod:`bus_schemas.transport`: the CAN protocol (DBC), its codec, zenoh key expressions and
  sessions, the python-can interface that carries CAN frames over zenoh, bus configs and
  liveliness (what the controller process loads; no ``hp_model``);
- :mod:`bus_schemas.recording`: the MCAP channel schemas, the ``Recorder`` and the readers.

See ``README.md`` here. Nothing is imported eagerly: ``import bus_schemas`` stays cheap.
"""
